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

"""Tests of cone_feeder_sim.physics.integrator: error norm, step control, exit location, faults."""

from cone_feeder_sim.physics import integrator
from cone_feeder_sim.physics.params import product_row, ProductParams
from cone_feeder_sim.physics.simulation import SimParams
import numpy as np
import pytest

PP = product_row(ProductParams())
#: The global row and tolerances as a simulation hands them over (read-only), so that these
#: calls run the kernel the install compiled, not a specialisation of their own.
GP = SimParams().global_row
ATOL = SimParams().atol


def test_error_norm_by_hand() -> None:
    err = np.array([1e-6, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 3e-4])
    y0 = np.zeros(9)
    y1 = np.zeros(9)
    y1[8] = 1.0
    atol = np.full(9, 1e-6)
    # components: 1e-6 / 1e-6 = 1 and 3e-4 / (1e-6 + 1e-4 * 1) ~ 2.97
    expected = np.sqrt((1.0 + (3e-4 / (1e-6 + 1e-4)) ** 2) / 9)
    assert integrator.error_norm(err, y0, y1, 1e-4, atol) == pytest.approx(expected)


def test_step_factor_is_bounded_and_decreasing() -> None:
    order = integrator.ERROR_ORDER
    assert integrator.step_factor(0.0, order) == integrator.FAC_MAX
    assert integrator.step_factor(1e6, order) == integrator.FAC_MIN
    assert integrator.step_factor(1.0, order) == pytest.approx(integrator.SAFETY)
    assert integrator.step_factor(0.1, order) > integrator.step_factor(0.5, order)
    assert integrator.step_factor(0.5, 2.0) > integrator.step_factor(0.5, order)


def test_exit_location_on_a_straight_path_is_exact() -> None:
    # positions and velocities of uniform motion: the cubic Hermite reproduces it exactly
    ya = np.array([0.2, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    yb = np.array([0.3, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    theta = integrator.locate_exit(0.1, ya, yb, 0.225)
    assert theta == pytest.approx(0.25, abs=1e-15)
    # oblique path: radius(theta) = r at x = 0.2 + 0.1 theta, y = 0.1 theta
    ya = np.array([0.2, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0])
    yb = np.array([0.3, 0.1, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0])
    theta = integrator.locate_exit(0.1, ya, yb, 0.225)
    assert np.hypot(0.2 + 0.1 * theta, 0.1 * theta) == pytest.approx(0.225, abs=1e-14)


def _batch(y: np.ndarray, seg_t: list[float], omega: float, max_steps: int = 1_000_000,
           h_min: float = 1e-12) -> tuple[np.ndarray, ...]:
    n = y.shape[0]
    status = np.zeros(n, dtype=np.int64)
    t_event = np.zeros(n)
    h = np.full(n, 1e-5)
    stats = np.zeros((n, integrator.STAT_WIDTH), dtype=np.int64)
    products = np.tile(PP, (n, 1))
    seg = np.array(seg_t)
    integrator.advance_batch(y, products, GP, seg, np.full(seg.size - 1, omega),
                             np.zeros(seg.size - 1), 0.225, h, status, t_event, 1e-5, ATOL,
                             h_min, 0.01, 1e-5, max_steps, stats, np.zeros(1, dtype=np.int64))
    return status, t_event, stats


def test_a_failing_particle_is_reported_and_the_others_carry_on() -> None:
    good = np.array([0.1, 0.0, 0.0525, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    bad = good.copy()
    bad[3] = np.nan
    y = np.vstack([good, bad, good])
    status, t_event, stats = _batch(y, [0.0, 0.05], 0.0)
    assert status.tolist() == [integrator.ACTIVE, integrator.FAILED, integrator.ACTIVE]
    assert stats[1, integrator.STAT_REASON] == integrator.REASON_NOT_FINITE
    assert t_event[1] == 0.0
    np.testing.assert_array_equal(y[0], y[2])  # the failure did not disturb the others
    assert np.all(np.isfinite(y[0]))


def test_step_budget_exhaustion_is_a_failure() -> None:
    y = np.array([[0.1, 0.0, 0.03, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
    status, _, stats = _batch(y, [0.0, 0.5], 0.0, max_steps=3)
    assert status[0] == integrator.FAILED
    assert stats[0, integrator.STAT_REASON] == integrator.REASON_TOO_MANY_STEPS


def test_exit_time_does_not_depend_on_the_output_interval() -> None:
    start = np.array([0.2, 0.0, 0.026, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    y1 = start[None, :].copy()
    status, t_one, _ = _batch(y1, [0.0, 2.0], -12.0)
    assert status[0] == integrator.EXITED
    y2 = start[None, :].copy()
    t = 0.0
    while True:
        status, t_ev, _ = _batch(y2, [t, t + 0.01], -12.0)
        if status[0] == integrator.EXITED:
            break
        t += 0.01
        assert t < 2.0
    assert t_ev[0] == pytest.approx(t_one[0], abs=2e-6)
    assert np.hypot(y2[0, 0], y2[0, 1]) == pytest.approx(0.225, abs=1e-7)
    assert np.hypot(y1[0, 0], y1[0, 1]) == pytest.approx(0.225, abs=1e-7)
