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
Or a recording (``.mcap``, a headless run's or ``sim_node``'s): its ``particle_states``
(ids, x, y, z at each message's stamp), so a simulated run with known parameters is a first
test subject; ``every`` keeps every n-th message (a 50-Hz recording thinned to a video's
rate).
"""

import csv
from dataclasses import dataclass
import math
from pathlib import Path

import numpy as np

from ..errors import ConeFeederError, ScenarioError
from ..formats.cdr import default_codec
from ..formats.mcap_reader import open_recording, parse_run_source
from ..formats.pointcloud import cloud_points

__all__ = ['read_table', 'read_tracks', 'read_tracks_csv', 'read_tracks_mcap', 'Tracks']

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

    @property
    def columns(self) -> int:
        """Return how many coordinates a row compares: 3 with heights, else 2 (x, y)."""
        return 3 if self.has_z else 2

    def __len__(self) -> int:
        """Return the number of observations."""
        return int(self.t.shape[0])


def read_table(path: Path, columns: tuple[str, ...], optional: str,
               what: str) -> tuple[tuple[str, ...], list[tuple[int, dict[str, str]]]]:
    """
    Read a CSV file with a header; return its columns and its (line number, row) pairs.

    Raise ScenarioError naming the file when it cannot be read or lacks one of ``columns``;
    ``what`` names its content and ``optional`` its optional columns in that message.
    """
    try:
        with path.open(newline='', encoding='utf-8') as stream:
            reader = csv.DictReader(stream)
            fields = tuple(reader.fieldnames or ())
            missing = [c for c in columns if c not in fields]
            if missing:
                raise ScenarioError(f'{path}: the {what} need the columns '
                                    f'{", ".join(columns)} ({optional} optional); missing '
                                    f'{", ".join(missing)}')
            return fields, list(enumerate(reader, start=2))
    except OSError as exc:
        raise ScenarioError(f'cannot read the {what} {path}: {exc.strerror or exc}') from exc


def read_tracks_csv(path: str | Path) -> Tracks:
    """Read a tracks file; raise ScenarioError naming the file, the row and the column."""
    path = Path(path)
    fields, lines = read_table(path, COLUMNS, 'z', 'tracks')
    has_z = 'z' in fields
    rows = []
    for number, row in lines:
        try:
            particle = int(row['particle'])
            values = [float(row[c]) for c in ('t', 'x', 'y')]
            z = float(row['z']) if has_z else math.nan
        except (TypeError, ValueError) as exc:
            raise ScenarioError(f'{path} line {number}: {exc}') from None
        if particle < 0 or not all(math.isfinite(v) for v in values) or (
                has_z and not math.isfinite(z)):
            raise ScenarioError(f'{path} line {number}: particle must be >= 0 and every value '
                                'finite')
        rows.append((values[0], particle, values[1], values[2], z))
    if not rows:
        raise ScenarioError(f'{path}: no tracks')
    rows.sort()
    table = np.array(rows)
    return Tracks(particle=table[:, 1].astype(np.int64), t=table[:, 0], xyz=table[:, 2:5])


#: The type of the recorded piece states.
STATES_TYPE = 'sensor_msgs/msg/PointCloud2'


def read_tracks_mcap(path: str | Path, every: int = 1) -> Tracks:
    """Read the pieces' states of a recording (every ``every``-th particle_states message)."""
    try:
        recording = open_recording(parse_run_source(str(path)))
        topics = {name for name, topic in recording.topics.items()
                  if name.endswith('particle_states') and topic.type_name == STATES_TYPE}
        if not topics:
            raise ScenarioError(f'{path}: no particle_states topic to take tracks from')
        codec = default_codec()
        parts = []
        for k, message in enumerate(recording.messages(topics=topics)):
            if k % every:
                continue
            points = cloud_points(codec.decode(STATES_TYPE, message.data, strict=False))
            parts.append(np.column_stack([
                np.full(points.shape[0], message.log_time_ns * 1e-9),
                points['id'].astype(np.float64), points['x'], points['y'], points['z']]))
    except ScenarioError:
        raise
    except ConeFeederError as exc:
        raise ScenarioError(f'cannot read the tracks {path}: {exc}') from exc
    if not parts:
        raise ScenarioError(f'{path}: no tracks')
    table = np.concatenate(parts)
    table = table[np.lexsort((table[:, 1], table[:, 0]))]
    return Tracks(particle=table[:, 1].astype(np.int64), t=table[:, 0], xyz=table[:, 2:5])


def read_tracks(path: str | Path, every: int = 1) -> Tracks:
    """Read tracks from a CSV file or, for ``.mcap``, from a recording."""
    if str(path).endswith('.mcap'):
        return read_tracks_mcap(path, every)
    return read_tracks_csv(path)
