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
Writing exit events to CSV: one row per piece that left the cone, appended as they happen.

The file has a header row (:data:`EVENT_COLUMNS`) and one row per exit: ``particle`` (the
particle id; the headless runner's ids are the 0-based indices in the scenario), ``t`` (s),
``angle_deg`` ([0, 360)), ``channel`` (1-based), ``x``, ``y``, ``z`` (m), ``vx``, ``vy``,
``vz`` (m/s), ``mass`` (kg); floats as ``repr`` writes them (exact round trip). Rows are in
exit-time order when the exits are given interval by interval.
"""

from collections.abc import Iterable
import csv
import io
from pathlib import Path
from types import TracebackType
from typing import Any, Self, TextIO

import numpy as np

from ..errors import ConeFeederError
from ..physics.simulation import ExitEvents

EVENT_COLUMNS = ('particle', 't', 'angle_deg', 'channel', 'x', 'y', 'z', 'vx', 'vy', 'vz',
                 'mass')


class EventsCsvWriter:
    """
    An events CSV written as the run goes: the header at open, rows appended by :meth:`write`.

    Every write ends with a flush, so the rows of the finished intervals are in the file
    whatever ends the process afterwards. ``with EventsCsvWriter(path) as events:`` closes it.
    """

    def __init__(self, path: str | Path) -> None:
        """Create (or truncate) the file and write the header row."""
        self.path = Path(path)
        self.rows = 0
        try:
            self._stream: TextIO = self.path.open('w', newline='', encoding='utf-8')
        except OSError as exc:
            raise self._error(exc) from exc
        self._append([EVENT_COLUMNS])

    def __enter__(self) -> Self:
        """Return the writer (closed at the end of the with block)."""
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        """Close the file."""
        self.close()

    @property
    def closed(self) -> bool:
        """Tell whether the file is closed."""
        return self._stream.closed

    def write(self, exits: ExitEvents) -> int:
        """Append one row per exit, in exit-time order, and flush; return the rows written."""
        order = np.argsort(exits.t, kind='stable')
        self._append([int(exits.ids[i]), repr(float(exits.t[i])),
                      repr(float(exits.angle_deg[i])), int(exits.channel[i]),
                      *(repr(float(v)) for v in exits.position[i]),
                      *(repr(float(v)) for v in exits.velocity[i]),
                      repr(float(exits.mass[i]))] for i in order)
        self.rows += int(order.shape[0])
        return int(order.shape[0])

    def close(self) -> None:
        """Close the file; idempotent."""
        if self._stream.closed:
            return
        try:
            self._stream.close()
        except OSError as exc:
            raise self._error(exc) from exc

    def _append(self, rows: Iterable[Iterable[Any]]) -> None:
        """Format rows completely first, then write them with one call and flush."""
        text = io.StringIO(newline='')
        csv.writer(text).writerows(rows)
        if not text.tell():
            return
        try:
            self._stream.write(text.getvalue())
            self._stream.flush()
        except OSError as exc:
            raise self._error(exc) from exc

    def _error(self, exc: OSError) -> ConeFeederError:
        return ConeFeederError(f'cannot write events to {self.path}: {exc.strerror or exc}')
