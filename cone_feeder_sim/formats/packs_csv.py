# Copyright 2026 The cone_feeder_sim Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
Writing the weigher's packs to CSV: one row per pack.

Columns (:data:`PACK_COLUMNS`): ``pack`` (from 1), ``t`` (s, discharge time), ``mass`` (kg,
true), ``measured`` (kg, the load cells' sum), ``heads`` (the heads discharged, 1-based like
the channels, separated by spaces), ``giveaway`` (kg, mass - target); floats as ``repr``
writes them (exact round trip).
"""

from collections.abc import Iterable
import csv
from pathlib import Path

from ..errors import ConeFeederError
from ..weigher.machine import Pack

__all__ = ['PACK_COLUMNS', 'write_packs_csv']

PACK_COLUMNS = ('pack', 't', 'mass', 'measured', 'heads', 'giveaway')


def write_packs_csv(path: str | Path, packs: Iterable[Pack]) -> int:
    """Write the packs to ``path`` (created or truncated); return the rows written."""
    path = Path(path)
    rows = [[pack.index, repr(pack.t), repr(pack.mass), repr(pack.measured),
             ' '.join(str(h) for h in pack.heads), repr(pack.giveaway)] for pack in packs]
    try:
        with path.open('w', newline='', encoding='utf-8') as stream:
            writer = csv.writer(stream)
            writer.writerow(PACK_COLUMNS)
            writer.writerows(rows)
    except OSError as exc:
        raise ConeFeederError(f'cannot write packs to {path}: {exc.strerror or exc}') from exc
    return len(rows)
