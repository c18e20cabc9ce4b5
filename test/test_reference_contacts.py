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


"""Checks of the contact reference itself (test/reference_contacts.py)."""

import math

import numpy as np
import pytest
from reference_contacts import compiled_crowd_rhs, crowd_rhs, crowd_trajectory
from reference_model import table2_params
from scipy.integrate import solve_ivp

STILL = [[0.0, 0.0], [100.0, 0.0]]


def head_on(v: float, t_end: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """Collide two default pieces 6 cm apart, 20 m above the cone, one closing at v (m/s)."""
    y0 = np.zeros((2, 9))
    y0[0, :3] = [-0.06, 0.0, 20.0]
    y0[0, 3] = v
    y0[1, :3] = [0.0, 0.0, 20.0]
    t = np.linspace(0.0, t_end, 301)
    sol = crowd_trajectory([table2_params(1), table2_params(1)], y0, STILL, t_end, t_eval=t)
    assert sol.status == 0
    return t, sol.y.reshape(2, 9, -1)


def reduced(v: float, t_end: float = 0.3) -> np.ndarray:
    """Solve the collision as one degree of freedom: m/2 s'' = R_a(s) F_c(s'), s = distance."""
    p = table2_params(1)
    s0, s_c = 2.0 * p['s0'], 2.0 * p['s_c_ratio'] * p['s0']
    r_t = 2.0 * math.atanh(p['r_a']) / (s0 - s_c)
    r_c = (s0 + s_c) / 2.0

    def rhs(t: float, z: np.ndarray) -> list[float]:
        r_act = (1.0 - math.tanh(r_t * (z[0] - r_c))) / 2.0
        f_c = p['r_f'] * (1.0 - math.tanh(p['r_d'] * z[1])) / 2.0
        return [z[1], r_act * f_c / (p['m'] / 2.0)]

    sol = solve_ivp(rhs, (0.0, t_end), [0.06, -v], method='Radau', rtol=1e-10, atol=1e-12,
                    t_eval=np.linspace(0.0, t_end, 301))
    return sol.y


@pytest.mark.parametrize('v', [0.05, 0.5, 1.0])
def test_head_on_collision_is_the_one_dimensional_contact_law(v: float) -> None:
    t, y = head_on(v)
    momentum = 0.125 * (y[0, 3] + y[1, 3])
    assert np.abs(momentum - 0.125 * v).max() < 1e-15  # to round-off
    # the pair's distance and closing speed follow the 1-D law of the restriction function
    dist = np.linalg.norm(y[0, :3] - y[1, :3], axis=0)
    s = reduced(v)
    np.testing.assert_allclose(dist, s[0], atol=1e-8)
    np.testing.assert_allclose(y[1, 3] - y[0, 3], s[1], atol=1e-7)
    # inelastic: the pieces part at a small fraction of the closing speed
    assert 0.0 < (y[1, 3, -1] - y[0, 3, -1]) / v < 0.3


def test_a_piece_on_another_rests_where_the_restriction_balances_its_weight() -> None:
    # the lower piece is held by the cone at its tip, the upper one dropped on it
    p = table2_params(1)
    y0 = np.zeros((2, 9))
    y0[0, :3] = [0.0, 0.0, 0.04]
    y0[1, :3] = [0.0, 0.0, 0.10]
    sol = crowd_trajectory([p, p], y0, STILL, 3.0, t_eval=[3.0])
    y = sol.y.reshape(2, 9)
    gap = y[1, 2] - y[0, 2]
    r_t = 2.0 * math.atanh(p['r_a']) / (p['s0'])  # S0 - S_c = 2 s0 - s0
    r_c = 0.75 * 2.0 * p['s0']
    # at rest: R_a(gap) r_f / 2 = m g
    expected = r_c + math.atanh(1.0 - 2.0 * 2.0 * p['m'] * p['g'] / p['r_f']) / r_t
    assert gap == pytest.approx(expected, abs=2e-6)  # it creeps to it: 27 um off at 1.5 s
    assert y[1, 0] == y[1, 1] == 0.0  # and stays on the axis


def test_the_compiled_crowd_is_the_numpy_one() -> None:
    # the solvers run the compiled transcription: four pieces of three products near each
    # other (touching, apart, sliding, nearly sticking), with adhesion, at random states
    rng = np.random.default_rng(2)
    params = [table2_params(1), table2_params(1, m=0.2, s0=0.03), table2_params(3),
              table2_params(5)]
    fun = compiled_crowd_rhs(params, 0.05)
    states = np.array([np.concatenate([np.r_[0.1 + rng.uniform(-0.03, 0.03, 2),
                                             rng.uniform(0.02, 0.05),
                                             rng.normal(0.0, 0.3, 3) * rng.choice([1e-6, 1.0]),
                                             rng.normal(0.0, 1.0, 3)] for _ in range(4)])
                       for _ in range(300)]).T  # (36, 300)
    for omega in (-8.0, 0.0, 5.5):
        expected = crowd_rhs(states, params, omega, 0.05)
        assert np.array_equal(expected[:, 11], crowd_rhs(states[:, 11], params, omega, 0.05))
        scale = np.abs(expected).reshape(4, 3, 3, -1).max(axis=2).repeat(3, axis=1)
        got = fun(states, omega)
        assert (np.abs(got - expected) <= 1e-12 * scale.reshape(36, -1)).all()
        assert np.array_equal(fun(states[:, 5], omega), got[:, 5])
