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

"""The pacer, driven by made-up wall times."""

from cone_feeder_sim.ros.pacing import Pacer
import pytest


def test_one_tick_per_period_on_time() -> None:
    pacer = Pacer(0.02, 1.0, 0.5)
    pacer.restart(100.0, 0.0)
    sim = 0.0
    for k in range(1, 50):
        due = pacer.due(100.0 + 0.02 * k, sim)
        assert due.ticks == 1 and due.given_up == 0.0
        sim += 0.02
    # a timer that fires a little early or late still gets its tick
    assert pacer.due(100.0 + 0.02 * 50 - 0.008, sim).ticks == 1
    assert pacer.due(100.0 + 0.02 * 50 + 0.008, sim).ticks == 1
    assert pacer.due(100.0 + 0.02 * 49 + 0.008, sim).ticks == 0  # not due yet


def test_a_late_tick_is_caught_up_within_the_limit() -> None:
    pacer = Pacer(0.02, 1.0, 0.5)
    pacer.restart(0.0, 0.0)
    due = pacer.due(0.2, 0.0)  # ten periods late
    assert due.ticks == 10 and due.given_up == 0.0 and due.lag == pytest.approx(0.2)


def test_lag_beyond_the_limit_is_given_up() -> None:
    pacer = Pacer(0.02, 1.0, 0.1)
    pacer.restart(0.0, 0.0)
    due = pacer.due(1.0, 0.0)
    assert due.ticks == 5 and due.given_up == pytest.approx(0.9)
    # the anchor moved: after those five ticks the simulation is on time again
    assert pacer.due(1.0, 0.1).ticks == 0
    assert pacer.due(1.02, 0.1).ticks == 1


def test_no_catch_up_loses_the_time_like_a_timer() -> None:
    pacer = Pacer(0.02, 1.0, 0.0)
    pacer.restart(0.0, 0.0)
    due = pacer.due(0.2, 0.0)
    assert due.ticks == 1 and due.given_up == pytest.approx(0.18)


def test_real_time_factor_scales_the_period() -> None:
    pacer = Pacer(0.02, 2.0, 0.5)
    assert pacer.period == 0.01
    pacer.restart(0.0, 1.0)
    assert pacer.due(0.05, 1.0).ticks == 5
    fast = Pacer(0.02, 0.0, 0.5)
    assert fast.period == 0.0 and fast.due(123.0, 0.0).ticks == 1


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match='dt > 0'):
        Pacer(0.0, 1.0, 0.5)
    with pytest.raises(ValueError, match='catch_up'):
        Pacer(0.02, 1.0, -1.0)
