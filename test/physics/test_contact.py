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


"""The piece-piece contact force against hand-computed values, symmetries and limits."""

import math

from cone_feeder_sim.physics.contact import pair_force_py
from cone_feeder_sim.physics.params import product_row, ProductParams
from cone_feeder_sim.physics.rotation import rotate_z
import numpy as np
import pytest

ROW = product_row(ProductParams())
ZERO = np.zeros(3)


def test_activation_at_compression_and_at_touch_as_on_the_cone() -> None:
    p = ProductParams()
    # at rest, no adhesion: the force is R_a r_f / 2 along the line of centres
    for dist, r_a_act in ((2.0 * p.s_c, (1.0 + p.r_a) / 2.0), (2.0 * p.s0, (1.0 - p.r_a) / 2.0),
                          (p.s0 + p.s_c, 0.5)):
        f = pair_force_py([0.0, 0.0, dist], ZERO, ROW, ZERO, ZERO, ROW)
        assert f[:2] == pytest.approx([0.0, 0.0], abs=1e-15)
        assert f[2] == pytest.approx(r_a_act * p.r_f / 2.0, rel=1e-12)


def test_hand_computed_value_approaching() -> None:
    # two default pieces 4 cm apart along x, closing at 0.01 m/s
    p = ProductParams()
    r_t = 2.0 * math.atanh(0.99) / (0.05 - 0.025)
    r_a_act = 0.5 * (1.0 - math.tanh(r_t * (0.04 - 0.0375)))
    f_c = 0.5 * 120.0 * (1.0 - math.tanh(120.0 * -0.01))
    f = pair_force_py([0.04, 0.0, 0.0], [-0.01, 0.0, 0.0], ROW, ZERO, ZERO, ROW)
    assert f == pytest.approx([r_a_act * f_c, 0.0, 0.0], rel=1e-12, abs=1e-15)
    assert p.r_f == 120.0 and p.r_d == 120.0


def test_far_apart_there_is_almost_no_force() -> None:
    f = pair_force_py([0.2, 0.0, 0.0], ZERO, ROW, ZERO, ZERO, ROW)
    assert np.abs(f).max() < 1e-30


def test_equal_and_opposite_for_any_state() -> None:
    rng = np.random.default_rng(3)
    other = product_row(ProductParams(m=0.2, s0=0.03, r_f=90.0, mu_C=0.5, d=30.0))
    for _ in range(200):
        xi, xj = rng.normal(0.0, 0.02, 3), rng.normal(0.0, 0.02, 3)
        wi, wj = rng.normal(0.0, 0.05, 3), rng.normal(0.0, 0.05, 3)
        fij = pair_force_py(xi, wi, ROW, xj, wj, other, 0.3)
        fji = pair_force_py(xj, wj, other, xi, wi, ROW, 0.3)
        np.testing.assert_allclose(fij, -fji, rtol=1e-12, atol=1e-12)


def test_friction_opposes_the_tangential_sliding() -> None:
    # i above j, sliding in +x relative to j: friction on i points to -x, bounded by mu N
    xi = [0.0, 0.0, 0.04]
    f = pair_force_py(xi, [0.05, 0.0, 0.0], ROW, ZERO, ZERO, ROW)
    normal = pair_force_py(xi, ZERO, ROW, ZERO, ZERO, ROW)[2]
    assert f[0] < 0.0 and f[1] == pytest.approx(0.0, abs=1e-15)
    assert f[2] == pytest.approx(normal, rel=1e-12)
    # the map at 0.05 m/s: viscous R_a d v + Coulomb + Stribeck (eqs. 6-10)
    p = ProductParams()
    r_t = 2.0 * math.atanh(0.99) / 0.025
    r_a_act = 0.5 * (1.0 - math.tanh(r_t * (0.04 - 0.0375)))
    c_s = p.mu_S - p.mu_C * math.tanh(p.v_S / p.v_C)
    xi_s = 0.05 / p.v_S
    expected = (r_a_act * p.d * 0.05 + p.mu_C * normal * math.tanh(0.05 / p.v_C)
                + (c_s * normal - r_a_act * p.d * p.v_S) * xi_s * math.exp(0.5 - 0.5 * xi_s ** 2))
    assert -f[0] == pytest.approx(expected * 0.05 / (0.05 + 1e-7), rel=1e-10)


def test_pieces_carried_together_do_not_rub() -> None:
    # the same velocity relative to the cone (carried side by side): no friction
    xi, xj = np.array([0.05, 0.01, 0.03]), np.array([0.09, 0.02, 0.031])
    w = np.array([0.3, -0.2, 0.01])
    np.testing.assert_allclose(pair_force_py(xi, w, ROW, xj, w, ROW),
                               pair_force_py(xi, ZERO, ROW, xj, ZERO, ROW), rtol=1e-12)


def test_frame_invariance_under_rotation_about_z() -> None:
    rng = np.random.default_rng(5)
    xi, xj, wi, wj = (rng.normal(0.0, 0.02, 3) for _ in range(4))
    f = pair_force_py(xi, wi, ROW, xj, wj, ROW, 0.1)
    g = pair_force_py(rotate_z(xi, 0.7), rotate_z(wi, 0.7), ROW, rotate_z(xj, 0.7),
                      rotate_z(wj, 0.7), ROW, 0.1)
    np.testing.assert_allclose(g, rotate_z(f, 0.7), rtol=1e-10, atol=1e-12)


def test_adhesion_pulls_at_touch_with_the_pull_off_force() -> None:
    p = ProductParams()
    xi = [0.0, 0.0, 2.0 * p.s0]
    repulsion = pair_force_py(xi, ZERO, ROW, ZERO, ZERO, ROW)[2]
    sticky = pair_force_py(xi, ZERO, ROW, ZERO, ZERO, ROW, 2.0)[2]
    assert repulsion == pytest.approx((1.0 - p.r_a) / 2.0 * p.r_f / 2.0)
    assert sticky == pytest.approx(repulsion - 2.0, rel=1e-12)
    # and fades with distance: sech^2(r_t (d - S0))
    far = pair_force_py([0.0, 0.0, 2.0 * p.s0 + 0.01], ZERO, ROW, ZERO, ZERO, ROW, 2.0)
    r_t = 2.0 * math.atanh(p.r_a) / (2.0 * (p.s0 - p.s_c))
    assert far[2] == pytest.approx(
        0.5 * (1.0 - math.tanh(r_t * (2.0 * p.s0 + 0.01 - 0.0375))) * 60.0
        - 2.0 / math.cosh(r_t * 0.01) ** 2, rel=1e-9)


def test_the_kernel_matches_the_independent_reference() -> None:
    from reference_contacts import reference_pair_force
    from reference_model import table2_params
    rng = np.random.default_rng(11)
    p_i, p_j = table2_params(1), table2_params(5, m=0.2, s0=0.03)
    row_i = product_row(ProductParams(d=p_i['d']))
    row_j = product_row(ProductParams(d=p_j['d'], m=0.2, s0=0.03))
    for _ in range(100):
        q_i, q_j = rng.normal(0.0, 0.025, 3), rng.normal(0.0, 0.025, 3)
        qd_i, qd_j = rng.normal(0.0, 0.05, 3), rng.normal(0.0, 0.05, 3)
        omega = rng.uniform(-8.0, 8.0)
        expected = reference_pair_force(q_i, qd_i, p_i, q_j, qd_j, p_j, omega, 0.4)
        # the kernel takes velocities relative to the turning cone (cone axes = world
        # axes at cone angle 0)
        w_i = qd_i - omega * np.array([-q_i[1], q_i[0], 0.0])
        w_j = qd_j - omega * np.array([-q_j[1], q_j[0], 0.0])
        got = pair_force_py(q_i, w_i, row_i, q_j, w_j, row_j, 0.4)
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)
