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

"""Tests of the wall-clock pacing of headless loops, with a made-up clock."""

from cone_feeder_sim.errors import ConeFeederError
from cone_feeder_sim.feeder.realtime import RealTime
import pytest


def test_real_time_pacing_with_a_made_up_clock() -> None:
    now = [100.0]
    slept = []

    def sleep(seconds: float) -> None:
        slept.append(seconds)
        now[0] += seconds

    pace = RealTime(2.0, clock=lambda: now[0], sleep=sleep)
    pace(1.0)  # the anchor: no wait
    assert slept == []
    pace(1.1)  # 0.05 s of wall time later
    assert now[0] == pytest.approx(100.05) and len(slept) == 1
    now[0] += 1.0  # a slow step: the loop is behind, goes on at once, no bunching after
    pace(1.2)
    pace(1.3)
    assert now[0] == pytest.approx(101.1)
    stopped = RealTime(0.01, stop=lambda: len(slept) >= 4, clock=lambda: now[0], sleep=sleep)
    stopped(0.0)
    stopped(1.0)  # 100 s due, but the stop request ends the wait after its slice
    assert len(slept) == 4 and max(slept) <= 0.05
    RealTime(float('inf'))(5.0)
    with pytest.raises(ConeFeederError, match='speed must be > 0'):
        RealTime(0.0)
