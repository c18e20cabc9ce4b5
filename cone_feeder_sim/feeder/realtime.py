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
Pacing a headless loop to the wall clock: ``speed`` simulated seconds per wall second.

:class:`RealTime` is called with the simulation time after every step (the runner's
progress callback, an RL environment's step) and sleeps until the wall clock catches up.
Unlike the node's :class:`~cone_feeder_sim.ros.pacing.Pacer`, which tells a timer how many
ticks are due, it blocks the loop that calls it. Deterministic given its clock: the tests
drive it with a made-up one.
"""

from collections.abc import Callable
import math
import time
from typing import Any

from ..errors import ConeFeederError

__all__ = ['RealTime']

#: Longest single sleep (s): a stop request is seen within this time.
SLEEP_SLICE = 0.05


class RealTime:
    """
    Sleeps until ``t / speed`` wall seconds have passed since the first call (the anchor).

    ``speed`` inf never sleeps. A step that ran late is not made up by bunching the next
    ones: the anchor moves, so the loop is never more than one call behind. ``stop``, if
    given, ends a sleep early when it returns True (checked every SLEEP_SLICE s); clock and
    sleep are the wall clock (s) and the sleep to use.
    """

    def __init__(self, speed: float = 1.0, *, stop: Callable[[], bool] | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], Any] = time.sleep) -> None:
        """Pace at ``speed`` simulated seconds per wall second (> 0; inf: no pacing)."""
        if not speed > 0.0:
            raise ConeFeederError(f'speed must be > 0 (inf: as fast as possible), got {speed}')
        self.speed = float(speed)
        self._stop = stop
        self._clock = clock
        self._sleep = sleep
        self._anchor: tuple[float, float] | None = None

    def restart(self) -> None:
        """Forget the anchor: the next call starts the clock again (a new episode)."""
        self._anchor = None

    def __call__(self, t: float, *_: Any) -> None:
        """Wait until the wall clock reaches simulation time t (s)."""
        if math.isinf(self.speed):
            return
        now = self._clock()
        if self._anchor is None:
            self._anchor = (now, t)
            return
        wall0, t0 = self._anchor
        due = wall0 + (t - t0) / self.speed
        if due <= now:
            self._anchor = (now, t)  # behind: go on from here, do not bunch
            return
        while now < due and not (self._stop is not None and self._stop()):
            self._sleep(min(due - now, SLEEP_SLICE))
            now = self._clock()
