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

import functools
import math
from typing import Any

import numpy as np
from reference_model import (
    initial_state_on_feeder, omega_of_t, reference_rhs, static_friction, table2_params)
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
    states; table the rotation table [[t, omega], ...], omega linear in between (the run
    restarts at each breakpoint, so no kink is stepped over); t_eval the output times
    (default: t_end). Returns an object with t and y, y of shape (9 n, len(t)), and status.
    """
    atol = np.tile([1e-12] * 6 + [1e-10] * 3, len(params))
    t_out = np.array([t_end] if t_eval is None else t_eval, dtype=float)
    cuts = sorted({0.0, t_end} | {float(t) for t, _ in table if 0.0 < t < t_end})
    y = np.asarray(y0, dtype=float).reshape(-1)
    found: dict[float, np.ndarray] = {0.0: y.copy()}
    status = 0
    for t_a, t_b in zip(cuts[:-1], cuts[1:]):
        points = sorted({float(t) for t in t_out if t_a < t <= t_b} | {t_b})
        sol = solve_ivp(lambda t, yy: crowd_rhs(yy, params, omega_of_t(table, t), pull_off),
                        (t_a, t_b), y, method='Radau', rtol=rtol, atol=atol, t_eval=points)
        status = min(status, sol.status)
        found.update({float(t): sol.y[:, k] for k, t in enumerate(sol.t)})
        y = sol.y[:, -1]
    result = type('CrowdSolution', (), {})()
    result.t = t_out
    result.y = np.column_stack([found[float(t)] for t in t_out])
    result.status = status
    return result


def crowd_exits(params: list[dict[str, Any]], y0: np.ndarray, table: Any, t_end: float,
                pull_off: float = 0.0, rtol: float = 1e-10) -> dict[int, tuple[float, float]]:
    """
    Integrate the coupled pieces until t_end, taking out each piece that crosses the rim.

    Returns {piece index: (exit time s, exit angle deg in [0, 360))}. The run restarts at
    every exit with the remaining pieces (a terminal event per piece) and at every
    breakpoint of the rotation table.
    """
    from reference_model import cone_geometry
    r, _ = cone_geometry(params[0])
    alive = list(range(len(params)))
    y = {i: np.asarray(y0[i], dtype=float) for i in alive}
    exits: dict[int, tuple[float, float]] = {}
    breaks = sorted({float(t) for t, _ in table if 0.0 < t < t_end} | {t_end})
    t = 0.0
    while alive and t < t_end:
        t_stop = next(b for b in breaks if b > t)
        own = [params[i] for i in alive]

        def rim(tt: float, yy: np.ndarray, k: int) -> float:
            return math.hypot(yy[9 * k], yy[9 * k + 1]) - r

        events = []
        for k in range(len(alive)):
            def event(tt: float, yy: np.ndarray, k: int = k) -> float:
                return rim(tt, yy, k)
            event.terminal = True  # type: ignore[attr-defined]
            event.direction = 1.0  # type: ignore[attr-defined]
            events.append(event)
        atol = np.tile([1e-12] * 6 + [1e-10] * 3, len(alive))
        sol = solve_ivp(lambda tt, yy, own=own: crowd_rhs(yy, own, omega_of_t(table, tt),
                                                          pull_off),
                        (t, t_stop), np.concatenate([y[i] for i in alive]), method='Radau',
                        rtol=rtol, atol=atol, events=events)
        assert sol.status >= 0, sol.message
        t = float(sol.t[-1])
        state = sol.y[:, -1].reshape(len(alive), 9)
        for k, i in enumerate(alive):
            y[i] = state[k]
        if sol.status == 1:
            k = next(k for k, ev in enumerate(sol.t_events) if len(ev))
            i = alive[k]
            exits[i] = (t, math.degrees(math.atan2(y[i][1], y[i][0])) % 360.0)
            alive.remove(i)
    return exits


#: The rotation that spins a crowd of touching pieces off the rim in the contact tests.
RIM_CROWD_TABLE = ((0.0, 0.0), (0.4, -8.0), (5.0, -8.0))


@functools.cache
def rim_crowd_exits(positions: tuple[tuple[float, float, float], ...]) -> dict:
    """Return the reference exits of the rim crowd at ``positions`` (computed once)."""
    y0 = np.array([initial_state_on_feeder(np.array(x), 0.0) for x in positions])
    return crowd_exits([table2_params(1)] * len(positions), y0, [list(r) for r in
                       RIM_CROWD_TABLE], 1.1, pull_off=0.05)


#: Four touching pieces (x, y in m, resting on the cone) on a cone spun up to -6 rad/s: the
#: convergence case of the contact tests, compared with the reference at 0.4 s.
FOUR_TOUCHING_XY = ((0.06, 0.0), (0.105, 0.005), (0.15, 0.0), (0.08, 0.04))
FOUR_TOUCHING_TABLE = ((0.0, 0.0), (0.3, -6.0), (5.0, -6.0))


@functools.cache
def four_touching_at(positions: tuple[tuple[float, float, float], ...]) -> np.ndarray:
    """Return the reference positions (4, 3) m at 0.4 s of the four pieces (computed once)."""
    y0 = np.array([initial_state_on_feeder(np.array(x), 0.0) for x in positions])
    return crowd_trajectory([table2_params(1)] * 4, y0, [list(r) for r in FOUR_TOUCHING_TABLE],
                            0.4, pull_off=0.05, t_eval=[0.4]).y[:, -1].reshape(4, 9)[:, :3]
