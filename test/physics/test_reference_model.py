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
Tests of the plain world-frame reference model against known answers.

The expected values here are computed with plain scalar arithmetic (math module),
not with the reference module's own helpers, so that a slip in either shows up.
"""

import math
import os
from pathlib import Path
import subprocess
import sys
from typing import Any

import numpy as np
import pytest
import reference_model as rm
R_CONE = 0.225
H_CONE = 0.225 * math.tan(7.5 * math.pi / 180.0)
R_T = math.log((1.0 + 0.99) / (1.0 - 0.99)) / (0.025 - 0.0125)   # 2 artanh(x) = ln(...)
R_C = (0.025 + 0.0125) / 2.0
MASS = 0.125
G = 9.81


def _activation(s: float) -> float:
    """Return R_a written as a logistic function: (1 - tanh x) / 2 = 1 / (1 + e^(2x))."""
    return 1.0 / (1.0 + math.exp(2.0 * R_T * (s - R_C)))


def _plain_rhs(y: list[float], omega: float, d: float, tip_eps: float,
               normal_force: str = 'newton', direction: str = 'full') -> list[float]:
    """Return eq. 38 / eq. 37 written out with scalars only (independent of numpy)."""
    q1, q2, q3, u1, u2, u3, f1, f2, f3 = y
    rho = math.sqrt(q1 * q1 + q2 * q2 + tip_eps * tip_eps)
    k = H_CONE / R_CONE
    s = q3 - H_CONE * (1.0 - rho / R_CONE)
    vp = u3 + k * (q1 * u1 + q2 * u2) / rho
    e1, e2, e3 = k * q1 / rho, k * q2 / rho, 1.0
    ra = _activation(s)
    fc = 120.0 * (1.0 - math.tanh(120.0 * vp)) / 2.0
    normal = ra * fc if normal_force == 'newton' else ra * fc / 120.0
    w1, w2, w3 = u1 + omega * q2, u2 - omega * q1, u3        # qdot - omega x q
    full_speed = math.sqrt(w1 * w1 + w2 * w2 + w3 * w3)
    if direction == 'tangential':
        en = math.sqrt(e1 * e1 + e2 * e2 + e3 * e3)
        n1, n2, n3 = e1 / en, e2 / en, e3 / en
        dot = w1 * n1 + w2 * n2 + w3 * n3
        w1, w2, w3 = w1 - dot * n1, w2 - dot * n2, w3 - dot * n3
    v = math.sqrt(w1 * w1 + w2 * w2 + w3 * w3)
    fs_delta = (0.99 - 0.85 * math.tanh(0.1 / 0.00005)) * normal - ra * d * 0.1
    mag = (ra * d * v + 0.85 * normal * math.tanh(v / 0.00005)
           + fs_delta * (v / 0.1) * math.exp(0.5 - 0.5 * (v / 0.1) ** 2))
    qs = [-mag * w / (v + 1e-7) for w in (w1, w2, w3)]
    a = 1.0 - math.exp(-(full_speed / 0.0001) ** 2)
    dqd = [a / 0.0003 * (qs[i] - (f1, f2, f3)[i]) for i in range(3)]
    acc = [(f1 + ra * fc * e1) / MASS, (f2 + ra * fc * e2) / MASS,
           (f3 - MASS * G + ra * fc * e3) / MASS]
    return [u1, u2, u3] + acc + dqd


def _surface_z(q1: float, q2: float, tip_eps: float = 0.0) -> float:
    """Return the cone surface height below (q1, q2)."""
    return H_CONE * (1.0 - math.sqrt(q1 * q1 + q2 * q2 + tip_eps * tip_eps) / R_CONE)


def test_table2_params_and_geometry() -> None:
    """Table II values, per-sample damping, derived cone size and activation constants."""
    p = rm.table2_params()
    assert p['d'] == 225.0 and p['m'] == 0.125 and p['cone_tilt'] == 7.5
    assert [rm.table2_params(k)['d'] for k in range(1, 6)] == [225, 135, 750, 750, 30]
    assert rm.table2_params(3, mu_C=0.5)['mu_C'] == 0.5
    with pytest.raises(KeyError):
        rm.table2_params(mu_c=0.5)
    r, h = rm.cone_geometry(p)
    assert r == pytest.approx(0.225, rel=1e-15)
    assert h == pytest.approx(0.0296218119571641, rel=1e-12)
    r_t, r_c = rm.activation_constants(p)
    assert r_t == pytest.approx(R_T, rel=1e-12)
    assert r_t == pytest.approx(423.464385977959, rel=1e-12)
    assert r_c == pytest.approx(0.01875, rel=1e-15)


@pytest.mark.parametrize('s, expected', [
    (R_C, 0.5),                    # tanh(0) = 0
    (0.025, (1.0 - 0.99) / 2.0),   # s = s0: r_t (s0 - r_c) = artanh(r_a)
    (0.0125, (1.0 + 0.99) / 2.0),  # s = s_c
    (0.02, None),
    (0.03, None),
])
def test_activation_known_points(s: float, expected: float | None) -> None:
    """R_a at the model's characteristic distances, tip regularisation switched off."""
    p = rm.table2_params(tip_epsilon=0.0)
    q1, q2 = 0.06, -0.08
    q = np.array([q1, q2, _surface_z(q1, q2) + s])
    c = rm.constraint_terms(q, np.zeros(3), p)
    assert c['s_perp'] == pytest.approx(s, abs=1e-15)
    want = _activation(s) if expected is None else expected
    assert c['R_a'] == pytest.approx(want, rel=1e-12, abs=1e-15)
    assert c['F_c'] == pytest.approx(60.0, rel=1e-15)


def test_constraint_terms_known_point() -> None:
    """s_perp, v_perp, e_Fc and F_c at a moving point, by hand."""
    p = rm.table2_params(tip_epsilon=0.0)
    q = np.array([0.06, 0.08, 0.05])              # rho = 0.1 exactly
    qdot = np.array([0.3, -0.1, 0.02])
    c = rm.constraint_terms(q, qdot, p)
    k = H_CONE / R_CONE
    assert c['s_perp'] == pytest.approx(0.05 - H_CONE * (1.0 - 0.1 / 0.225), rel=1e-13)
    v_perp = 0.02 + k * (0.06 * 0.3 - 0.08 * 0.1) / 0.1   # = 0.02 + 0.1 k
    assert c['v_perp'] == pytest.approx(v_perp, rel=1e-13)
    assert c['v_perp'] == pytest.approx(0.0331652497587396, rel=1e-12)
    np.testing.assert_allclose(c['e_Fc'], [0.6 * k, 0.8 * k, 1.0], rtol=1e-14)
    assert c['F_c'] == pytest.approx(60.0 * (1.0 - math.tanh(120.0 * v_perp)), rel=1e-12)
    assert c['R_a'] == pytest.approx(_activation(c['s_perp']), rel=1e-10)


def test_tip_regularisation() -> None:
    """At the tip rho is tip_epsilon; the rhs stays finite and symmetric."""
    p = rm.table2_params()
    q = np.array([0.0, 0.0, H_CONE + 0.02])
    c = rm.constraint_terms(q, np.array([0.0, 0.0, -0.1]), p)
    assert c['rho'] == pytest.approx(1e-4, rel=1e-15)
    assert c['s_perp'] == pytest.approx(0.02 + H_CONE * 1e-4 / R_CONE, rel=1e-13)
    assert c['v_perp'] == pytest.approx(-0.1, rel=1e-15)
    np.testing.assert_array_equal(c['e_Fc'], [0.0, 0.0, 1.0])
    f = rm.reference_rhs(0.0, np.r_[q, 0.0, 0.0, -0.1, 0.0, 0.0, 0.0], p, 3.0)
    assert np.all(np.isfinite(f))
    np.testing.assert_array_equal(f[[0, 1, 3, 4, 6, 7]], 0.0)


STATES = [
    # q, velocity RELATIVE to the cone (v_dif), Q_d
    # in contact and sliding fast (Stribeck hump region)
    [0.1, -0.03, 0.035, 0.02, 0.05, -0.01, 0.3, -0.2, 0.5],
    # compressed, creeping (Coulomb tanh not saturated, a < 1)
    [-0.05, 0.12, 0.025, 1.0e-5, -2.0e-5, 2e-6, -0.1, 0.05, 1.0],
    # lifting off, near the tip
    [0.003, 0.001, 0.046, 0.05, 0.0, 0.04, 0.0, 0.0, 0.0],
    # far above the cone: no contact
    [0.15, 0.0, 0.4, 0.0, 1.0, -2.0, 0.2, 0.1, -0.3],
]


@pytest.mark.parametrize('y', STATES)
@pytest.mark.parametrize('omega', [0.0, -7.0])
@pytest.mark.parametrize('normal_force, direction', [
    ('newton', 'full'), ('literal', 'full'), ('newton', 'tangential')])
def test_rhs_matches_plain_arithmetic(y: list[float], omega: float, normal_force: str,
                                      direction: str) -> None:
    """The vector implementation equals a scalar transcription of eqs. 2-38."""
    p = rm.table2_params(2, normal_force=normal_force, friction_direction=direction)
    state = list(y)
    state[3] += -omega * y[1]          # q_dot = v_dif + omega e_z x q
    state[4] += omega * y[0]
    got = rm.reference_rhs(0.3, np.array(state), p, omega, 1.0)
    want = _plain_rhs(state, omega, 135.0, 1e-4, normal_force, direction)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)


def _friction_from_rhs(p: dict[str, Any], q: np.ndarray, v_dif: np.ndarray,
                       omega: float) -> np.ndarray:
    """Recover Q_s^c from dQ_d/dt with Q_d = 0: Q_s = T_F dQ_d / a."""
    qdot = v_dif + np.array([-omega * q[1], omega * q[0], 0.0])
    f = rm.reference_rhs(0.0, np.r_[q, qdot, np.zeros(3)], p, omega)
    a = 1.0 - math.exp(-(np.linalg.norm(v_dif) / 1e-4) ** 2)
    return f[6:9] * 0.0003 / a


def test_friction_magnitude_at_stribeck_velocity() -> None:
    """Friction is mu_S N at v = v_S (eq. 10's purpose), R_a d v + mu_C N far above v_S."""
    p = rm.table2_params(1)
    q1, q2 = 0.1, 0.05
    q = np.array([q1, q2, _surface_z(q1, q2, 1e-4) + 0.022])
    omega = -4.0
    rho = math.hypot(q1, q2)
    tangent = np.array([q2, -q1, 0.0]) / rho          # horizontal, no v_perp change
    c = rm.constraint_terms(q, tangent * 0.1 + np.array([-omega * q2, omega * q1, 0.0]), p)
    normal = c['R_a'] * c['F_c']
    assert c['F_c'] == pytest.approx(60.0, rel=1e-12)
    qs = _friction_from_rhs(p, q, 0.1 * tangent, omega)
    assert np.linalg.norm(qs) == pytest.approx(0.99 * normal * 0.1 / (0.1 + 1e-7), rel=1e-10)
    np.testing.assert_allclose(qs / np.linalg.norm(qs), -tangent, atol=1e-14)
    qs_fast = _friction_from_rhs(p, q, 2.0 * tangent, omega)
    want = c['R_a'] * 225.0 * 2.0 + 0.85 * normal
    assert np.linalg.norm(qs_fast) == pytest.approx(want * 2.0 / (2.0 + 1e-7), rel=1e-10)
    # The literal reading divides N (not the viscous terms) by r_f.
    pl = rm.table2_params(1, normal_force='literal')
    qs_lit = _friction_from_rhs(pl, q, 0.1 * tangent, omega)
    assert np.linalg.norm(qs_lit) == pytest.approx(
        0.99 * normal / 120.0 * 0.1 / (0.1 + 1e-7), rel=1e-10)


def test_tangential_friction_ignores_normal_motion() -> None:
    """Pure normal relative motion: no tangential friction, but a keeps the full |v_dif|."""
    q1, q2 = 0.08, -0.06
    q = np.array([q1, q2, _surface_z(q1, q2, 1e-4) + 0.02])
    k = H_CONE / R_CONE
    rho = math.sqrt(q1 * q1 + q2 * q2 + 1e-8)
    n = np.array([k * q1 / rho, k * q2 / rho, 1.0])
    n /= np.linalg.norm(n)
    omega = 2.0
    v_dif = 3e-5 * n
    qdot = v_dif + np.array([-omega * q2, omega * q1, 0.0])
    q_d = np.array([0.4, -0.2, 1.1])
    y = np.r_[q, qdot, q_d]
    a = 1.0 - math.exp(-(3e-5 / 1e-4) ** 2)
    tang = rm.reference_rhs(0.0, y, rm.table2_params(friction_direction='tangential'), omega)
    np.testing.assert_allclose(tang[6:9], -a / 0.0003 * q_d, rtol=1e-6, atol=1e-9)
    full = rm.reference_rhs(0.0, y, rm.table2_params(), omega)
    assert np.linalg.norm(full[6:9] + a / 0.0003 * q_d) > 1.0   # full friction acts
    np.testing.assert_array_equal(full[0:6], tang[0:6])


@pytest.mark.parametrize('reading', [{}, {'normal_force': 'literal'},
                                     {'friction_direction': 'tangential'}])
def test_the_compiled_rhs_is_the_numpy_one(reading: dict[str, str]) -> None:
    # the solvers run the compiled transcription: at random states in and out of contact,
    # sliding and nearly sticking, one at a time and vectorised, it equals reference_rhs
    # within what two correct implementations of exp and tanh (numpy's SIMD loops, the C
    # library numba calls) allow: a few ulps of each call times the rhs's condition
    # (rm.rounding_bound). The other numpy code paths of this CPU: the test below.
    rng = np.random.default_rng(3)
    p = rm.table2_params(2, **reading)
    fun = rm.compiled_rhs(p)
    # a defect of one part in a billion (the mass), which the bound must catch
    off = rm.compiled_rhs({**p, 'm': p['m'] * (1.0 + 1e-9)})
    states = np.array([np.r_[rng.uniform(-0.2, 0.2, 2), rng.uniform(0.0, 0.06),
                             rng.normal(0.0, 0.3, 3) * rng.choice([1e-6, 1e-3, 1.0]),
                             rng.normal(0.0, 1.0, 3)] for _ in range(300)]).T  # (9, 300)
    for omega in (-8.0, 0.0, 5.5):
        expected = rm.reference_rhs(0.0, states, p, omega)
        bound = rm.rounding_bound(states, p, omega)
        assert (np.abs(fun(states, omega) - expected) <= bound).all()
        assert not (np.abs(off(states, omega) - expected) <= bound).all()
        # the bound is round-off: below 1e-13 of each block's largest value at most
        # states, 1e-8 where the rhs is ill-conditioned (1 - exp(-x^2) at tiny speeds)
        scale = np.abs(expected).reshape(3, 3, -1).max(axis=1).repeat(3, axis=0)
        assert np.median(bound / scale) < 1e-13 and (bound <= 1e-8 * scale).all()
        one = fun(states[:, 7], omega)
        assert one.shape == (9,) and np.array_equal(one, fun(states, omega)[:, 7])


#: numpy's SIMD groups to turn off (NPY_DISABLE_CPU_FEATURES) to run its other exp and tanh
#: loops: AVX-512 exp off, then AVX2 tanh too (numpy 2.x names; baseline X86_V2 stays).
NUMPY_PATHS = ('X86_V4 AVX512_ICL AVX512_SPR', 'X86_V3 X86_V4 AVX512_ICL AVX512_SPR')


@pytest.mark.parametrize('disabled', NUMPY_PATHS)
def test_the_bound_holds_on_numpy_s_other_code_paths(disabled: str) -> None:
    # numpy picks its exp and tanh loops by CPU (AVX-512, AVX2, baseline): the comparison
    # above runs again with this CPU's faster paths off, so one machine checks them all
    features = set(np._core._multiarray_umath.__cpu_dispatch__)  # what this numpy can turn off
    turned_off = [name for name in disabled.split() if name in features]
    if not turned_off:
        pytest.skip(f'numpy {np.__version__} dispatches none of {disabled}')
    env = {**os.environ, 'NPY_DISABLE_CPU_FEATURES': ' '.join(turned_off)}
    test = f'{__file__}::test_the_compiled_rhs_is_the_numpy_one'
    done = subprocess.run([sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider',
                           '-p', 'no:xdist', test], env=env, capture_output=True, text=True,
                          timeout=300, cwd=Path(__file__).parent)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    assert '3 passed' in done.stdout


def test_invalid_options_raise() -> None:
    """Unknown model options are rejected."""
    y = np.r_[0.1, 0.0, 0.05, np.zeros(6)]
    with pytest.raises(ValueError):
        rm.reference_rhs(0.0, y, rm.table2_params(normal_force='n/r_f'), 0.0)
    with pytest.raises(ValueError):
        rm.reference_rhs(0.0, y, rm.table2_params(friction_direction='normal'), 0.0)


def test_omega_of_t_piecewise_linear() -> None:
    """Linear between points, held before the first and after the last point."""
    table = [[0.2, 1.0], [0.4, -3.0], [1.0, -3.0], [1.5, 2.0]]
    assert rm.omega_of_t(table, -1.0) == 1.0
    assert rm.omega_of_t(table, 0.2) == 1.0
    assert rm.omega_of_t(table, 0.3) == pytest.approx(-1.0, abs=1e-15)
    assert rm.omega_of_t(table, 0.7) == -3.0
    assert rm.omega_of_t(table, 1.25) == pytest.approx(-0.5, abs=1e-15)
    assert rm.omega_of_t(table, 9.0) == 2.0
    assert rm.omega_of_t([[0.0, -10.47]], 3.0) == -10.47
    assert rm.domega_of_t(table, 0.3) == pytest.approx(-20.0)
    assert rm.domega_of_t(table, 0.1) == 0.0
    assert rm.domega_of_t(table, 2.0) == 0.0
    with pytest.raises(ValueError):
        rm.omega_of_t([[0.0, 1.0], [0.0, 2.0]], 0.0)


def test_initial_state_moves_with_feeder() -> None:
    """q_dot0 = omega(0) e_z x q0 and Q_d0 = 0."""
    y0 = rm.initial_state_on_feeder((0.11, -0.01, 0.03), -2.0)
    np.testing.assert_allclose(y0, [0.11, -0.01, 0.03, -0.02, -0.22, 0, 0, 0, 0], atol=1e-16)


@pytest.mark.parametrize('angle, channel', [
    (93.6, 1), (69.5, 2), (63.5, 2), (115.2, 14), (147.4, 13), (287.4, 8),
    (107.999, 1), (108.0, 14), (82.3, 1), (82.2, 2), (0.0, 5), (359.9, 5), (-10.0, 5),
    (468.0, 14)])
def test_channel_clockwise(angle: float, channel: int) -> None:
    """Clockwise layout fitting Table I: channel 1 is [108 - 360/14, 108)."""
    assert rm.channel_of_angle(angle) == channel


def test_channel_counterclockwise_and_errors() -> None:
    """Counter-clockwise numbering starts at the boundary and goes up with the angle."""
    assert rm.channel_of_angle(108.0, numbering='counterclockwise') == 1
    assert rm.channel_of_angle(107.9, numbering='counterclockwise') == 14
    assert rm.channel_of_angle(134.0, numbering='counterclockwise') == 2
    assert rm.channel_of_angle(45.0, count=4, boundary_deg=0.0,
                               numbering='counterclockwise') == 1
    assert rm.channel_of_angle(45.0, count=4, boundary_deg=0.0) == 4
    with pytest.raises(ValueError):
        rm.channel_of_angle(10.0, numbering='ccw')


def test_exit_angle_range() -> None:
    """Angles are atan2(y, x) folded into [0, 360)."""
    assert rm.exit_angle_deg([0.0, 1.0]) == pytest.approx(90.0)
    assert rm.exit_angle_deg([-1.0, -1e-300]) == pytest.approx(180.0)
    assert rm.exit_angle_deg([1.0, -1.0]) == pytest.approx(315.0)
    assert rm.exit_angle_deg([1.0, -1e-30]) == 0.0   # 360 - 6e-29 rounds to 360


def test_free_fall_far_above_cone() -> None:
    """Far above the cone R_a is negligible: exact ballistic motion, Q_d stays 0."""
    z0 = 0.5
    t_end = 0.2
    q0 = np.array([0.05, 0.02, z0])
    # Lowest point of the run, well above the surface: R_a there below 1e-90.
    s_min = z0 - 0.5 * G * t_end ** 2 - H_CONE
    assert s_min > 0.27
    assert _activation(s_min) < 1e-90
    y0 = np.r_[q0, 0.1, -0.05, 0.0, np.zeros(3)]
    times = [0.05, 0.1, 0.15, 0.2]
    res = rm.reference_trajectory(rm.table2_params(), y0, [[0.0, 3.0], [0.12, -5.0]], t_end,
                                  t_out=times)
    assert not res.exited
    np.testing.assert_allclose(res.t_out, times)
    for t, y in zip(res.t_out, res.y_out):
        np.testing.assert_allclose(y[0:3], [0.05 + 0.1 * t, 0.02 - 0.05 * t,
                                            z0 - 0.5 * G * t * t], rtol=0, atol=1e-11)
        np.testing.assert_allclose(y[3:6], [0.1, -0.05, -G * t], rtol=0, atol=1e-10)
        np.testing.assert_allclose(y[6:9], 0.0, atol=1e-12)
    # The rotation table breakpoint and the output times are segment boundaries.
    starts = [seg[0] for seg in res.segments]
    assert 0.12 in starts and 0.05 in starts and 0.15 in starts
    np.testing.assert_allclose(res.state_at(0.125)[2], z0 - 0.5 * G * 0.125 ** 2, atol=1e-9)
    np.testing.assert_allclose(res.state_at(times), res.y_out, rtol=0, atol=1e-12)


def test_exit_event_in_free_flight() -> None:
    """The rim event stops the run where sqrt(q1^2 + q2^2) = r, at the right time and angle."""
    q0 = np.array([0.1, 0.05, 0.6])
    vel = np.array([0.8, 1.5, 0.0])
    y0 = np.r_[q0, vel, np.zeros(3)]
    res = rm.reference_trajectory(rm.table2_params(), y0, [[0.0, -3.0]], 0.5)
    # |q0 + vel t| = r  ->  |vel|^2 t^2 + 2 (q0.vel) t + |q0|^2 - r^2 = 0
    a = vel[0] ** 2 + vel[1] ** 2
    b = 2.0 * (q0[0] * vel[0] + q0[1] * vel[1])
    c = q0[0] ** 2 + q0[1] ** 2 - R_CONE ** 2
    t_hit = (-b + math.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)
    assert res.exited
    assert res.t_exit == pytest.approx(t_hit, rel=1e-9)
    x, y = q0[0] + vel[0] * t_hit, q0[1] + vel[1] * t_hit
    assert res.angle_deg == pytest.approx(math.degrees(math.atan2(y, x)), abs=1e-7)
    assert math.hypot(res.y_exit[0], res.y_exit[1]) == pytest.approx(R_CONE, abs=1e-10)
    np.testing.assert_array_equal(res.y_final, res.y_exit)
    assert res.t_final == res.t_exit


def test_exit_disabled_and_start_outside() -> None:
    """Without r_exit the run goes on past the rim; a start outside the rim is rejected."""
    y0 = np.r_[0.2, 0.0, 0.6, 1.0, 0.0, 0.0, np.zeros(3)]
    res = rm.reference_trajectory(rm.table2_params(), y0, [[0.0, 0.0]], 0.05, r_exit=False)
    assert not res.exited and res.t_final == 0.05
    assert res.y_final[0] == pytest.approx(0.25, abs=1e-10)
    with pytest.raises(ValueError):
        rm.reference_trajectory(rm.table2_params(), res.y_final, [[0.0, 0.0]], 0.1)


def test_mirror_symmetry() -> None:
    """Mirroring y -> -y and omega -> -omega mirrors the whole trajectory."""
    p = rm.table2_params(1)
    q0 = rm.TABLE1_STARTS[1]
    table = [[0.0, 0.0], [0.1, -6.0]]
    mirror = np.array([1.0, -1.0, 1.0] * 3)
    times = [0.1, 0.2, 0.3]
    ya = rm.initial_state_on_feeder(q0, 0.0)
    ra = rm.reference_trajectory(p, ya, table, 0.3, rtol=1e-8, t_out=times)
    rb = rm.reference_trajectory(p, mirror * ya, [[t, -w] for t, w in table], 0.3, rtol=1e-8,
                                 t_out=times)
    assert not ra.exited and not rb.exited
    # The run is not trivially symmetric by itself: the piece has moved off its start.
    assert abs(ra.y_out[-1][1] - q0[1]) > 0.05
    np.testing.assert_allclose(rb.y_out[:, 0:6], ra.y_out[:, 0:6] * mirror[0:6], rtol=0,
                               atol=1e-7)
    np.testing.assert_allclose(rb.y_out[:, 6:9], ra.y_out[:, 6:9] * mirror[6:9], rtol=0,
                               atol=1e-5)


def test_piece_rides_with_counterclockwise_cone() -> None:
    """A piece resting on a slowly turning cone (omega > 0) is carried counter-clockwise."""
    p = rm.table2_params(1)
    # Rest height: R_a F_c = m g with F_c = r_f / 2.
    s_rest = R_C + math.atanh(1.0 - 2.0 * MASS * G / 60.0) / R_T
    q0 = (0.1, 0.0, _surface_z(0.1, 0.0, 1e-4) + s_rest)
    y0 = rm.initial_state_on_feeder(q0, 1.0)
    res = rm.reference_trajectory(p, y0, [[0.0, 1.0]], 0.1, rtol=1e-7, t_out=[0.05, 0.1])
    for t, y in zip(res.t_out, res.y_out):
        assert rm.exit_angle_deg(y) == pytest.approx(math.degrees(1.0 * t), abs=1e-3)
        assert math.hypot(y[0], y[1]) == pytest.approx(0.1, abs=1e-5)
        assert y[2] == pytest.approx(q0[2], abs=1e-5)


def test_table1_start_on_stationary_cone_bounces_up_and_rests() -> None:
    """Table I sample 1 on a stationary cone: pushed up from compression, then at rest."""
    p = rm.table2_params(1)
    q0 = rm.TABLE1_STARTS[1]
    s0 = q0[2] - _surface_z(q0[0], q0[1], 1e-4)
    assert s0 < 0.025 and _activation(s0) > 0.9          # starts compressed
    y0 = rm.initial_state_on_feeder(q0, 0.0)
    times = [0.02, 0.5, 0.75, 1.0]
    res = rm.reference_trajectory(p, y0, [[0.0, 0.0]], 1.0, rtol=1e-8, t_out=times)
    assert not res.exited
    y_02, _, y_075, y_1 = res.y_out
    assert y_02[2] - q0[2] > 5e-4                          # pushed up
    speed = [np.linalg.norm(y[3:6]) for y in res.y_out]
    assert speed[1] < 1e-3 and speed[3] < 3e-4 and speed[3] < speed[1]
    assert np.linalg.norm(y_1[0:2] - y_075[0:2]) < 2e-5     # no longer sliding
    assert math.hypot(y_1[0], y_1[1]) < 0.15                # still well on the cone
    # No rotation, so the piece stays in the vertical plane through its start.
    for y in res.y_out:
        assert rm.exit_angle_deg(y) == pytest.approx(rm.exit_angle_deg(q0), abs=1e-6)
    # At rest the forces balance: Q_d + F_g + R_a F_c e_Fc = 0.
    c = rm.constraint_terms(y_1[0:3], y_1[3:6], p)
    total = y_1[6:9] + np.array([0.0, 0.0, -MASS * G]) + c['R_a'] * c['F_c'] * c['e_Fc']
    assert np.linalg.norm(total) < 0.01 * MASS * G
