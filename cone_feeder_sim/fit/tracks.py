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
Tracks of pieces: where each was seen, when, in the world frame.

A CSV file with the columns ``particle`` (the 0-based index of the piece in the scenario's
``particles``), ``t`` (s), ``x``, ``y`` (m, world frame) and optionally ``z`` (m). Rows may come
in any order; tracks may be sparse (a video at 25-30 frames/s), start late and end early.
"""

import csv
from dataclasses import dataclass
import math
from pathlib import Path

import numpy as np

from ..errors import ScenarioError

__all__ = ['Tracks', 'read_tracks_csv']

#: The columns a tracks file must have (``z`` is optional).
COLUMNS = ('particle', 't', 'x', 'y')


@dataclass(frozen=True, eq=False)
class Tracks:
    """
    Observed positions: particle (M,) int64 index, t (M,) s, xyz (M, 3) m (z NaN if unknown).

    Rows are sorted by time, then particle.
    """

    particle: np.ndarray
    t: np.ndarray
    xyz: np.ndarray

    @property
    def has_z(self) -> bool:
        """Tell whether the tracks give heights."""
        return bool(np.all(np.isfinite(self.xyz[:, 2])))

    def __len__(self) -> int:
        """Return the number of observations."""
        return int(self.t.shape[0])


def read_tracks_csv(path: str | Path) -> Tracks:
    """Read a tracks file; raise ScenarioError naming the file, the row and the column."""
    path = Path(path)
    try:
        with path.open(newline='', encoding='utf-8') as stream:
            reader = csv.DictReader(stream)
            missing = [c for c in COLUMNS if c not in (reader.fieldnames or ())]
            if missing:
                raise ScenarioError(f'{path}: the tracks need the columns '
                                    f'{", ".join(COLUMNS)} (z optional); missing '
                                    f'{", ".join(missing)}')
            has_z = 'z' in (reader.fieldnames or ())
            rows = []
            for number, row in enumerate(reader, start=2):
                try:
                    particle = int(row['particle'])
                    values = [float(row[c]) for c in ('t', 'x', 'y')]
                    z = float(row['z']) if has_z else math.nan
                except (TypeError, ValueError) as exc:
                    raise ScenarioError(f'{path} line {number}: {exc}') from None
                if particle < 0 or not all(math.isfinite(v) for v in values) or (
                        has_z and not math.isfinite(z)):
                    raise ScenarioError(f'{path} line {number}: particle must be >= 0 and '
                                        'every value finite')
                rows.append((values[0], particle, values[1], values[2], z))
    except OSError as exc:
        raise ScenarioError(f'cannot read the tracks {path}: {exc.strerror or exc}') from exc
    if not rows:
        raise ScenarioError(f'{path}: no tracks')
    rows.sort()
    table = np.array(rows)
    return Tracks(particle=table[:, 1].astype(np.int64), t=table[:, 0], xyz=table[:, 2:5])
