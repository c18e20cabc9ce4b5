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

"""Tests of cone_feeder_sim.physics.rosenbrock: linear algebra and the order of RODAS4."""

import math

from cone_feeder_sim.physics import model, rosenbrock
from cone_feeder_sim.physics.params import ModelParams, product_row, ProductParams
from cone_feeder_sim.physics.rotation import rotate_z
import numpy as np
import pytest

PP = product_row(ProductParams())
GP = ModelParams().global_row()
NO_LOAD = np.zeros(3)  # no constant acceleration added to the field


def test_lu_matches_numpy() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        a = rng.normal(size=(9, 9))
        b = rng.normal(size=9)
        lu = a.copy()
        piv = np.zeros(9, dtype=np.int64)
        assert rosenbrock.lu_factor(lu, piv)
        x = b.copy()
        rosenbrock.lu_solve(lu, piv, x)
        np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-9, atol=1e-12)
    singular = np.zeros((3, 3))
    assert not rosenbrock.lu_factor(singular, np.zeros(3, dtype=np.int64))


def test_block_solve_of_w_matches_a_dense_solve() -> None:
    rng = np.random.default_rng(1)
    jac = np.zeros((9, 9))
    for _ in range(30):
        y = np.array([0.1, -0.03, 0.03, 1e-3, 2e-3, -1e-3, 0.3, -0.2, 0.1])
        y *= 1.0 + 0.5 * rng.standard_normal(9)
        model.jacobian(y, PP, GP, rng.uniform(-10, 10), rng.uniform(-30, 30), jac)
        alpha = 1.0 / (rosenbrock.GAMMA * 10.0 ** rng.uniform(-6, -1))
        work = np.zeros((2, 9, 9))
        work[0] = jac
        piv = np.zeros((2, 3), dtype=np.int64)
        assert rosenbrock.factor_mechanical(work[0], alpha, work[1, 0:3, 0:3],
                                            work[1, 3:6, 0:3], work[1, 6:9, 0:3], piv[1])
        b = rng.normal(size=9)
        kk = np.zeros((9, 9))
        kk[2] = b
        rosenbrock.solve_mechanical(work[0], alpha, work[1, 0:3, 0:3], work[1, 3:6, 0:3],
                                    piv[1], kk, 2)
        dense = np.linalg.solve(alpha * np.eye(9) - jac, b)
        np.testing.assert_allclose(kk[2], dense, rtol=1e-8, atol=1e-12 * np.abs(dense).max())


def _free_flight(t: float, omega0: float, domega: float) -> np.ndarray:
    """Exact cone-axes state of a piece in free flight far above the cone."""
    q0 = np.array([0.05, -0.02, 1.0])
    v0 = np.array([0.3, 0.1, 0.5])
    q = q0 + v0 * t + np.array([0.0, 0.0, -0.5 * 9.81 * t * t])
    qd = v0 + np.array([0.0, 0.0, -9.81 * t])
    omega = omega0 + domega * t
    angle = omega0 * t + 0.5 * domega * t * t
    w = qd - omega * np.cross([0.0, 0.0, 1.0], q)
    return np.concatenate([rotate_z(q, -angle), rotate_z(w, -angle), np.zeros(3)])


def _fixed_step_error(n: int, t_end: float, omega0: float, domega: float) -> float:
    y = _free_flight(0.0, omega0, domega)
    f0, y1 = np.zeros(9), np.zeros(9)
    work = np.zeros((2, 9, 9))
    piv = np.zeros((2, 3), dtype=np.int64)
    k = np.zeros((9, 9))
    h = t_end / n
    for i in range(n):
        omega = omega0 + domega * i * h
        rosenbrock.prepare_step(y, omega, domega, PP, GP, work, k, f0)
        assert rosenbrock.rodas_step(y, f0, h, omega, domega, PP, GP, NO_LOAD, NO_LOAD, work,
                                     piv, k, y1)
        y = y1.copy()
    return float(np.abs(y[:3] - _free_flight(t_end, omega0, domega)[:3]).max())


@pytest.mark.parametrize('omega0, domega', [(8.0, 0.0), (-6.0, 40.0)])
def test_rodas4_converges_with_order_four(omega0: float, domega: float) -> None:
    # exact answer: free flight (no contact, no friction) seen from the turning cone, with
    # Coriolis, centrifugal and, for domega != 0, Euler terms and a time-dependent field
    errors = [_fixed_step_error(n, 0.4, omega0, domega) for n in (10, 20, 40, 80)]
    orders = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
    assert min(orders[1:]) > 3.7, (errors, orders)
    assert errors[-1] < 1e-7


def test_embedded_error_estimate_is_small_on_exact_polynomial_free_fall() -> None:
    # with omega = 0 the free-flight solution is a quadratic polynomial, which the method
    # integrates exactly: the error estimate (k_6) must vanish to roundoff
    y = _free_flight(0.0, 0.0, 0.0)
    f0, y1 = np.zeros(9), np.zeros(9)
    work = np.zeros((2, 9, 9))
    piv = np.zeros((2, 3), dtype=np.int64)
    k = np.zeros((9, 9))
    rosenbrock.prepare_step(y, 0.0, 0.0, PP, GP, work, k, f0)
    assert rosenbrock.rodas_step(y, f0, 0.1, 0.0, 0.0, PP, GP, NO_LOAD, NO_LOAD, work, piv, k,
                                 y1)
    np.testing.assert_allclose(y1[:6], _free_flight(0.1, 0.0, 0.0)[:6], atol=1e-14)
    assert np.abs(k[5]).max() < 1e-13
