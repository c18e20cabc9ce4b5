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

"""Writing exit events to CSV: one row per piece that left the cone."""

from collections.abc import Mapping
import csv
from pathlib import Path

import numpy as np

from ..errors import ConeFeederError

EVENT_COLUMNS = ('particle', 't', 'angle_deg', 'channel', 'x', 'y', 'z', 'vx', 'vy', 'vz',
                 'mass')


def write_events_csv(path: str | Path, table: Mapping[str, np.ndarray]) -> int:
    """
    Write exits to CSV with a header row; return the number of rows.

    table: columns as returned by RunResult.exit_table(): ids (M,), t (M,) s, angle_deg (M,)
    in [0, 360), channel (M,), position (M, 3) m, velocity (M, 3) m/s, mass (M,) kg.
    Rows are sorted by exit time.
    """
    order = np.argsort(table['t'], kind='stable')
    path = Path(path)
    try:
        with path.open('w', newline='', encoding='utf-8') as stream:
            writer = csv.writer(stream)
            writer.writerow(EVENT_COLUMNS)
            for i in order:
                pos = table['position'][i]
                vel = table['velocity'][i]
                writer.writerow([int(table['ids'][i]), repr(float(table['t'][i])),
                                 repr(float(table['angle_deg'][i])), int(table['channel'][i]),
                                 *(repr(float(v)) for v in pos), *(repr(float(v)) for v in vel),
                                 repr(float(table['mass'][i]))])
    except OSError as exc:
        raise ConeFeederError(f'cannot write events to {path}: {exc.strerror or exc}') from exc
    return int(order.shape[0])
