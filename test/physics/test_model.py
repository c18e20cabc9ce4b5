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
Tests of cone_feeder_sim.physics.model: each equation group against values computed by hand.

Hand values are evaluated here with plain arithmetic from the paper's formulas (eqs. 2-38)
and Table II, independently of the compiled functions under test.
"""

import math

from cone_feeder_sim.physics import model
from cone_feeder_sim.physics.params import ModelParams, product_row, ProductParams
from cone_feeder_sim.physics.rotation import rotate_z
import numpy as np
import pytest

PROD = ProductParams()
MODEL = ModelParams()
PP = product_row(PROD)
GP = MODEL.global_row()
H = 0.225 * math.tan(math.radians(7.5))
K = H / 0.225


def test_relative_velocity_eq3() -> None:
    # a point at (1, 0, 0) on a cone turning at 2 rad/s moves with (0, 2, 0)
    assert model.relative_velocity(np.array([1.0, 0, 0]), np.array([0, 2.0, 0]), 2.0) == (
        0.0, 0.0, 0.0)
    u = model.relative_velocity(np.array([0.1, -0.2, 0.03]), np.array([0.5, 0.1, -0.2]), 3.0)
    assert u == pytest.approx((0.5 - 3.0 * 0.2, 0.1 - 3.0 * 0.1, -0.2))


def test_friction_direction_eq4_eq5() -> None:
    (e0, e1, e2), v = model.friction_direction(3.0, 4.0, 0.0, 1e-7)
    assert v == 5.0
    assert (e0, e1, e2) == pytest.approx((-3.0 / (5 + 1e-7), -4.0 / (5 + 1e-7), 0.0))
    (e0, e1, e2), v = model.friction_direction(0.0, 0.0, 0.0, 1e-7)
    assert v == 0.0 and (e0, e1, e2) == (0.0, 0.0, 0.0)  # eq. 4 has no 0/0 at rest


def test_static_friction_hand_values() -> None:
    n, r_act, d = 1.2, 0.3, 225.0
    c_s = 0.99 - 0.85 * math.tanh(0.1 / 5e-5)
    # at v = v_S the three terms add up to mu_S N exactly (that is what eq. 10 is built for)
    at_vs = model.static_friction_magnitude(0.1, n, r_act, d, 0.85, 5e-5, 0.1, c_s)
    assert at_vs == pytest.approx(0.99 * n, rel=1e-12)
    # at v = v_C: viscous + Coulomb tanh(1) + Stribeck (v/v_S) exp(1/2 - (v/v_S)^2/2)
    v = 5e-5
    xi = v / 0.1
    expected = (r_act * d * v + 0.85 * n * math.tanh(1.0)
                + (c_s * n - r_act * d * 0.1) * xi * math.exp(0.5 - 0.5 * xi * xi))
    got = model.static_friction_magnitude(v, n, r_act, d, 0.85, 5e-5, 0.1, c_s)
    assert got == pytest.approx(expected, rel=1e-12)
    assert model.static_friction_magnitude(0.0, n, r_act, d, 0.85, 5e-5, 0.1, c_s) == 0.0


def test_stribeck_shape_peaks_at_one() -> None:
    assert model.stribeck_shape(0.1, 0.1) == pytest.approx(1.0)
    assert model.stribeck_shape(0.05, 0.1) < 1.0 and model.stribeck_shape(0.2, 0.1) < 1.0


def test_filter_gain_eq14() -> None:
    assert model.filter_gain(1e-4, 1e-4) == pytest.approx(1.0 - math.exp(-1.0))
    assert model.filter_gain(0.0, 1e-4) == 0.0
    assert model.filter_gain(1.0, 1e-4) == 1.0


def test_cone_distance_eq27_eq28() -> None:
    s, rho = model.cone_distance(0.11, -0.01, 0.03, H, K, 0.0)
    rho_hand = math.sqrt(0.11 ** 2 + 0.01 ** 2)
    assert rho == pytest.approx(rho_hand)
    assert s == pytest.approx(0.03 - H * (1.0 - rho_hand / 0.225))
    assert s == pytest.approx(0.0149197, abs=1e-7)
    # at the tip the regularised radius is tip_epsilon and s is finite
    s_tip, rho_tip = model.cone_distance(0.0, 0.0, 0.05, H, K, 1e-4)
    assert rho_tip == 1e-4 and math.isfinite(s_tip)


def test_normal_velocity_and_direction_eq29_eq36() -> None:
    rho = 0.1
    assert model.normal_velocity(0.1, 0.0, 1.0, 0.0, -0.5, K, rho) == pytest.approx(
        -0.5 + K)
    assert model.constraint_direction(0.06, 0.08, K, rho) == pytest.approx(
        (K * 0.6, K * 0.8, 1.0))
    # e_Fc is the gradient of s_perp: check by central differences
    x = np.array([0.07, -0.05, 0.02])
    grad = []
    for i in range(3):
        dx = np.zeros(3)
        dx[i] = 1e-7
        sp, _ = model.cone_distance(*(x + dx), H, K, 1e-4)
        sm, _ = model.cone_distance(*(x - dx), H, K, 1e-4)
        grad.append((sp - sm) / 2e-7)
    _, rho = model.cone_distance(*x, H, K, 1e-4)
    assert model.constraint_direction(x[0], x[1], K, rho) == pytest.approx(grad, rel=1e-6)


def test_activation_eq31_at_characteristic_gaps() -> None:
    r_t, r_c = PROD.r_t, PROD.r_c
    # by eq. 32 and 33, r_t (s0 - r_c) = artanh(r_a): R_a(s0) = (1 - r_a)/2, R_a(s_c) = (1 + r_a)/2
    assert model.activation(0.025, r_t, r_c) == pytest.approx(0.005)
    assert model.activation(0.0125, r_t, r_c) == pytest.approx(0.995)
    assert model.activation(r_c, r_t, r_c) == 0.5


def test_power_function_and_its_derivative_eq34_eq35() -> None:
    assert model.power_function(0.0, 120.0, 120.0) == 0.0
    # hand value at v = 0.01 m/s: (v/2 - log(cosh(1.2)) / 240) * 120
    expected = (0.005 - math.log(math.cosh(1.2)) / 240.0) * 120.0
    assert model.power_function(0.01, 120.0, 120.0) == pytest.approx(expected, rel=1e-12)
    assert model.constraint_force(0.0, 120.0, 120.0) == 60.0
    assert model.constraint_force(0.01, 120.0, 120.0) == pytest.approx(
        60.0 * (1.0 - 0.8336546070121553))
    for v in (-0.3, -0.004, 0.0, 0.002, 0.05):
        dv = 1e-7
        numeric = (model.power_function(v + dv, 120.0, 120.0)
                   - model.power_function(v - dv, 120.0, 120.0)) / (2 * dv)
        assert numeric == pytest.approx(model.constraint_force(v, 120.0, 120.0), rel=1e-6,
                                        abs=1e-6)
    assert math.isfinite(model.power_function(100.0, 120.0, 120.0))  # no overflow


def test_normal_force_product() -> None:
    r_a_act, f_c, n = model.normal_force(0.02, -0.001, PROD.r_t, PROD.r_c, 120.0, 120.0)
    assert n == pytest.approx(r_a_act * f_c)
    assert f_c == pytest.approx(60.0 * (1.0 + math.tanh(0.12)))


def test_free_fall_far_above_the_cone() -> None:
    out = np.zeros(9)
    y = np.array([0.05, 0.02, 1.0, 0.3, -0.1, -0.5, 0.0, 0.0, 0.0])
    model.rhs_world(y, PP, GP, 0.0, out)
    np.testing.assert_allclose(out[:6], [0.3, -0.1, -0.5, 0.0, 0.0, -9.81], atol=1e-12)


def test_rhs_world_at_rest_on_stationary_cone_by_hand() -> None:
    # piece at rest on a stationary cone: only normal force and gravity act (Q_d = 0)
    q = np.array([0.1, 0.0, 0.03])
    out = np.zeros(9)
    model.rhs_world(np.concatenate([q, np.zeros(6)]), PP, GP, 0.0, out)
    rho = math.hypot(1e-4, 0.1)
    s = 0.03 - H * (1.0 - rho / 0.225)
    r_act = 0.5 * (1.0 - math.tanh(PROD.r_t * (s - PROD.r_c)))
    n = r_act * 60.0
    assert out[3] == pytest.approx(n * K * 0.1 / rho / 0.125)
    assert out[5] == pytest.approx(n / 0.125 - 9.81)
    np.testing.assert_allclose(out[6:], 0.0, atol=1e-14)  # a(0) = 0 freezes the filter


def _cone_derivative_from_world(yw: np.ndarray, angle: float, omega: float,
                                domega: float, machine: np.ndarray) -> np.ndarray:
    """Transform the world-frame derivative into the derivative of the cone-axes state."""
    q, qd, qf = yw[0:3], yw[3:6], yw[6:9]
    dw = np.zeros(9)
    model.rhs_world(yw, PP, machine, omega, dw)
    qdd, qfd = dw[3:6], dw[6:9]
    zx = np.cross([0, 0, 1.0], q)
    w_world = qd - omega * zx
    w = rotate_z(w_world, -angle)
    p = rotate_z(qf, -angle)
    wdot = (-omega * np.cross([0, 0, 1.0], w)
            + rotate_z(qdd - domega * zx - omega * np.cross([0, 0, 1.0], qd), -angle))
    pdot = -omega * np.cross([0, 0, 1.0], p) + rotate_z(qfd, -angle)
    return np.concatenate([w, wdot, pdot])


@pytest.mark.parametrize('literal', [False, True])
@pytest.mark.parametrize('tangential', [False, True])
def test_cone_frame_field_equals_transformed_world_field(literal: bool,
                                                         tangential: bool) -> None:
    machine = ModelParams(normal_force='literal' if literal else 'newton',
                          friction_direction='tangential' if tangential else 'full').global_row()
    rng = np.random.default_rng(7)
    for _ in range(25):
        angle, omega, domega = rng.uniform(-3, 3), rng.uniform(-10, 10), rng.uniform(-30, 30)
        yw = np.concatenate([[rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15),
                              rng.uniform(0.01, 0.05)],
                             rng.normal(0, 0.3, 3), rng.normal(0, 1.0, 3)])
        expected = _cone_derivative_from_world(yw, angle, omega, domega, machine)
        zx = np.cross([0, 0, 1.0], yw[0:3])
        yc = np.concatenate([rotate_z(yw[0:3], -angle), rotate_z(yw[3:6] - omega * zx, -angle),
                             rotate_z(yw[6:9], -angle)])
        got = np.zeros(9)
        model.rhs(yc, PP, machine, omega, domega, got)
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize('literal', [False, True])
@pytest.mark.parametrize('tangential', [False, True])
def test_jacobian_matches_finite_differences(literal: bool, tangential: bool) -> None:
    machine = ModelParams(normal_force='literal' if literal else 'newton',
                          friction_direction='tangential' if tangential else 'full').global_row()
    rng = np.random.default_rng(3)
    base = np.array([0.1, -0.03, 0.035, 1e-3, 2e-3, -1e-3, 0.3, -0.2, 0.1])
    f_plus, f_minus, jac = np.zeros(9), np.zeros(9), np.zeros((9, 9))
    for _ in range(20):
        y = base * (1.0 + 0.5 * rng.standard_normal(9))
        omega, domega = rng.uniform(-10, 10), rng.uniform(-30, 30)
        model.jacobian(y, PP, machine, omega, domega, jac)
        numeric = np.zeros((9, 9))
        for j in range(9):
            step = max(1e-5 * abs(y[j]), 1e-9)
            yp, ym = y.copy(), y.copy()
            yp[j] += step
            ym[j] -= step
            model.rhs(yp, PP, machine, omega, domega, f_plus)
            model.rhs(ym, PP, machine, omega, domega, f_minus)
            numeric[:, j] = (f_plus - f_minus) / (2 * step)
        scale = np.abs(numeric).max(axis=1, keepdims=True) + 1e-12
        assert np.max(np.abs(jac - numeric) / scale) < 1e-6


@pytest.mark.parametrize('literal', [False, True])
@pytest.mark.parametrize('tangential', [False, True])
def test_the_field_with_the_jacobian_is_the_field_bit_for_bit(
        literal: bool, tangential: bool) -> None:
    machine = ModelParams(normal_force='literal' if literal else 'newton',
                          friction_direction='tangential' if tangential else 'full').global_row()
    rng = np.random.default_rng(11)
    alone, together = np.zeros(9), np.zeros(9)
    jac, jac_alone = np.zeros((9, 9)), np.zeros((9, 9))
    for scale in (0.0, 1e-6, 1e-3, 0.3, 3.0):  # at rest, sticking, slipping, flying
        for _ in range(40):
            y = np.concatenate([[rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2),
                                 rng.uniform(0.0, 0.06)], rng.normal(0, scale, 3),
                                rng.normal(0, 1.0, 3)])
            omega, domega = rng.uniform(-10, 10), rng.uniform(-30, 30)
            model.rhs(y, PP, machine, omega, domega, alone)
            model.rhs_jacobian(y, PP, machine, omega, domega, together, jac)
            model.jacobian(y, PP, machine, omega, domega, jac_alone)
            assert alone.tobytes() == together.tobytes()
            assert jac.tobytes() == jac_alone.tobytes()


def test_omega_derivative_matches_finite_differences() -> None:
    y = np.array([0.1, -0.03, 0.035, 1e-3, 2e-3, -1e-3, 0.3, -0.2, 0.1])
    fp, fm, d = np.zeros(9), np.zeros(9), np.zeros(9)
    # the field is quadratic in omega, so a central difference is exact up to roundoff
    model.rhs(y, PP, GP, 2.0 + 1e-2, 5.0, fp)
    model.rhs(y, PP, GP, 2.0 - 1e-2, 5.0, fm)
    model.rhs_omega_derivative(y, 2.0, d)
    np.testing.assert_allclose(d, (fp - fm) / 2e-2, rtol=1e-9, atol=1e-9)
