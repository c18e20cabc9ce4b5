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
Wall-clock pacing of the live node: how many ticks are due now.

Simulated time follows the wall clock at ``real_time_factor``, measured from an anchor
(start, resume, change of the factor). A tick that took longer than the period (a cone
reversal excites every piece at once) leaves the simulation behind; the following ticks
catch the lag up, as long as it stays within ``catch_up`` seconds of wall time. Beyond
that the machine cannot keep up: the anchor moves, the lag above ``catch_up`` is given up
(simulated time runs slower than asked, and the node says so), and ticks are never
bunched by more than ``catch_up`` worth of time.

Pure Python and deterministic given the wall times passed in (the tests drive it with
made-up times); no ROS.
"""

from dataclasses import dataclass
import math

__all__ = ['Due', 'Pacer']


@dataclass(frozen=True)
class Due:
    """What the pacer asks for at one moment."""

    #: Whole ticks due now (0: the next tick is not due yet).
    ticks: int
    #: Wall-clock seconds the simulation is behind, after giving up.
    lag: float
    #: Wall-clock seconds given up now (lag beyond ``catch_up``); 0 when keeping up.
    given_up: float


class Pacer:
    """
    Tells how many ticks of ``dt`` are due at a wall time, for a real-time factor.

    ``rtf`` 0 means as fast as possible: one tick is always due. ``catch_up`` (s of wall
    time, >= 0) bounds the lag that later ticks make up; 0 never catches up (a late tick
    is lost time, as with a plain timer).
    """

    def __init__(self, dt: float, rtf: float, catch_up: float) -> None:
        """Pace ticks of dt simulated seconds at rtf; start with restart()."""
        if not (dt > 0.0 and rtf >= 0.0 and catch_up >= 0.0):
            raise ValueError(f'Pacer needs dt > 0, rtf >= 0, catch_up >= 0; got {dt}, {rtf}, '
                             f'{catch_up}')
        self.dt = dt
        self.rtf = rtf
        self.catch_up = catch_up
        self._wall0 = 0.0
        self._sim0 = 0.0

    @property
    def period(self) -> float:
        """Return the wall-clock period of one tick (s); 0 when as fast as possible."""
        return 0.0 if self.rtf == 0.0 else self.dt / self.rtf

    def restart(self, wall: float, sim: float) -> None:
        """Anchor: simulated time ``sim`` (s) is on time at wall time ``wall`` (s)."""
        self._wall0 = wall
        self._sim0 = sim

    def due(self, wall: float, sim: float) -> Due:
        """
        Return the ticks due at wall time ``wall`` when the simulation is at ``sim``.

        A tick is due once the wall clock is within half a period of its end (timers fire
        a little early or late). Lag beyond ``catch_up`` is given up: the anchor moves.
        """
        if self.rtf == 0.0:
            return Due(1, 0.0, 0.0)
        period = self.period
        lag = (wall - self._wall0) - (sim - self._sim0) / self.rtf  # wall s behind
        given_up = 0.0
        limit = max(self.catch_up, period)  # one period late is still on time
        if lag > limit:
            given_up = lag - limit
            self._wall0 += given_up
            lag = limit
        return Due(max(0, math.floor(lag / period + 0.5)), max(lag, 0.0), given_up)
