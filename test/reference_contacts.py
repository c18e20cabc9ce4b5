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
Plain world-frame reference of pieces that touch each other (test helper).

Written from the contact model of doc/model.md ("Pieces that touch"), independently of the
production kernel (cone_feeder_sim.physics.contact): numpy vectors, one piece after the
other, scipy's Radau on the full coupled system. Every piece is the one-piece model of
reference_model.reference_rhs; each pair within reach adds the contact force

    F_ij = (R_a F_c - A) n + Q_s(u_t, N)

with n = (q_i - q_j)/d, R_a and F_c the restriction function of eqs. 31-35 on the centre
distance d with the pair's radii summed (S0 = s0_i + s0_j, S_c = s_c_i + s_c_j), A the
adhesion f_po sech^2(r_t (d - S0)), and Q_s the static friction map (eqs. 4-10) of the
tangential slip u_t. The slip is taken in the frame of the cone: the pieces have no spin
and are taken to turn with the cone, so u = (qdot_i - qdot_j) - omega z x (q_i - q_j).
Coefficients of a pair are the means of the two pieces' values.
"""

import math
from typing import Any

import numpy as np
from reference_model import omega_of_t, reference_rhs, static_friction
from scipy.integrate import solve_ivp

PAIR_KEYS = ('r_a', 'r_d', 'r_f', 'd', 'mu_C', 'mu_S', 'v_C', 'v_S', 'epsilon')


def pair_params(p_i: dict[str, Any], p_j: dict[str, Any]) -> dict[str, Any]:
    """Return the pair's coefficients: means of the two pieces' values."""
    return {k: 0.5 * (p_i[k] + p_j[k]) for k in PAIR_KEYS}


def reference_pair_force(q_i: np.ndarray, qd_i: np.ndarray, p_i: dict[str, Any],
                         q_j: np.ndarray, qd_j: np.ndarray, p_j: dict[str, Any],
                         omega: float, pull_off: float) -> np.ndarray:
    """Return the contact force on piece i from piece j (N, world frame), shape (3,)."""
    pair = pair_params(p_i, p_j)
    dq = np.asarray(q_i, dtype=float) - np.asarray(q_j, dtype=float)
    dist = max(math.sqrt(float(dq @ dq)), 1e-9)
    n = dq / dist
    s0 = p_i['s0'] + p_j['s0']
    s_c = p_i['s_c_ratio'] * p_i['s0'] + p_j['s_c_ratio'] * p_j['s0']
    r_t = 2.0 * math.atanh(pair['r_a']) / (s0 - s_c)
    r_c = (s0 + s_c) / 2.0
    r_act = (1.0 - math.tanh(r_t * (dist - r_c))) / 2.0
    u = (np.asarray(qd_i, dtype=float) - np.asarray(qd_j, dtype=float)
         - omega * np.array([-dq[1], dq[0], 0.0]))
    v_n = float(u @ n)
    f_c = pair['r_f'] * (1.0 - math.tanh(pair['r_d'] * v_n)) / 2.0
    normal = r_act * f_c
    adhesion = pull_off / math.cosh(min(r_t * abs(dist - s0), 350.0)) ** 2
    q_s = static_friction(u - v_n * n, r_act, normal, pair)
    return (normal - adhesion) * n + q_s


def crowd_rhs(y: np.ndarray, params: list[dict[str, Any]], omega: float,
              pull_off: float) -> np.ndarray:
    """Return dy/dt of the coupled system; y (9 n,) = the pieces' [q, qdot, Q_d] in order."""
    count = len(params)
    states = y.reshape(count, 9)
    out = np.concatenate([reference_rhs(0.0, states[i], params[i], omega)
                          for i in range(count)]).reshape(count, 9)
    for i in range(count):
        for j in range(i + 1, count):
            reach = params[i]['s0'] + params[j]['s0']
            if float(np.sum((states[i, :3] - states[j, :3]) ** 2)) >= (2.0 * reach) ** 2:
                continue  # the activation is below 1e-9 there: no force worth a call
            f = reference_pair_force(states[i, :3], states[i, 3:6], params[i],
                                     states[j, :3], states[j, 3:6], params[j], omega,
                                     pull_off)
            out[i, 3:6] += f / params[i]['m']
            out[j, 3:6] -= f / params[j]['m']
    return out.reshape(-1)


def crowd_trajectory(params: list[dict[str, Any]], y0: np.ndarray, table: Any,
                     t_end: float, pull_off: float = 0.0, rtol: float = 1e-10,
                     t_eval: Any = None) -> Any:
    """
    Integrate the coupled pieces with Radau from t = 0 to t_end (no exits).

    params: one parameter dict per piece (reference_model.table2_params); y0 (n, 9) world
    states; table the rotation table [[t, omega], ...] (omega linear in between; the run is
    not split at its breakpoints, so give tables without kinks inside (0, t_end) or short
    runs). Returns scipy's OdeResult; its y has shape (9 n, len(t)).
    """
    atol = np.tile([1e-12] * 6 + [1e-10] * 3, len(params))
    return solve_ivp(lambda t, y: crowd_rhs(y, params, omega_of_t(table, t), pull_off),
                     (0.0, t_end), np.asarray(y0, dtype=float).reshape(-1), method='Radau',
                     rtol=rtol, atol=atol, t_eval=t_eval, dense_output=True)
