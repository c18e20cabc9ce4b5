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

import numba
import numpy as np
from reference_model import (cone_geometry, cone_row, friction_of, initial_state_on_feeder,
                             omega_of_t, PIECE_KEYS, piece_rhs_into, piece_row, readings,
                             reference_rhs, static_friction, table2_params)
from scipy.integrate import solve_ivp
from workers import shared

PAIR_KEYS = ('r_a', 'r_d', 'r_f', 'd', 'mu_C', 'mu_S', 'v_C', 'v_S', 'epsilon')


def pair_params(p_i: dict[str, Any], p_j: dict[str, Any]) -> dict[str, Any]:
    """Return the pair's coefficients: means of the two pieces' values."""
    return {k: 0.5 * (p_i[k] + p_j[k]) for k in PAIR_KEYS}


def reference_pair_force(q_i: np.ndarray, qd_i: np.ndarray, p_i: dict[str, Any],
                         q_j: np.ndarray, qd_j: np.ndarray, p_j: dict[str, Any],
                         omega: float, pull_off: float) -> np.ndarray:
    """
    Return the contact force on piece i from piece j (N, world frame).

    Vectors (3, ...): the components along the first axis, any further axes independent
    pairs; parameter values scalars or arrays that broadcast with q_i[0].
    """
    pair = pair_params(p_i, p_j)
    dq = np.asarray(q_i, dtype=float) - np.asarray(q_j, dtype=float)
    dist = np.maximum(np.sqrt(np.sum(dq * dq, axis=0)), 1e-9)
    n = dq / dist
    s0 = p_i['s0'] + p_j['s0']
    s_c = p_i['s_c_ratio'] * p_i['s0'] + p_j['s_c_ratio'] * p_j['s0']
    r_t = 2.0 * np.arctanh(pair['r_a']) / (s0 - s_c)
    r_c = (s0 + s_c) / 2.0
    r_act = (1.0 - np.tanh(r_t * (dist - r_c))) / 2.0
    u = (np.asarray(qd_i, dtype=float) - np.asarray(qd_j, dtype=float)
         - omega * np.stack([-dq[1], dq[0], np.zeros_like(dq[0])]))
    v_n = np.sum(u * n, axis=0)
    f_c = pair['r_f'] * (1.0 - np.tanh(pair['r_d'] * v_n)) / 2.0
    normal = r_act * f_c
    adhesion = pull_off / np.cosh(np.minimum(r_t * np.abs(dist - s0), 350.0)) ** 2
    q_s = static_friction(u - v_n * n, r_act, normal, pair)
    return (normal - adhesion) * n + q_s


def crowd_rhs(y: np.ndarray, params: list[dict[str, Any]], omega: float,
              pull_off: float) -> np.ndarray:
    """
    Return dy/dt of the coupled system.

    y (9 n,) = the pieces' [q, qdot, Q_d] in order, or (9 n, k): k such states at once
    (scipy's vectorised calls, which make the finite-difference Jacobian one call). Every
    piece is reference_rhs; every pair within reach adds reference_pair_force, equal and
    opposite. Returns the shape of y.
    """
    count = len(params)
    assert len({readings(p) for p in params}) == 1, 'a crowd takes one reading of the model'
    columns = np.asarray(y, dtype=float).reshape(count, 9, -1).transpose(1, 0, 2)  # (9, n, k)
    piece = {**params[0], **{key: np.array([p[key] for p in params])[:, None]
                             for key in PIECE_KEYS}}
    out = reference_rhs(0.0, columns, piece, omega)
    first, second = np.triu_indices(count, 1)
    if first.size:
        q, qdot = columns[0:3], columns[3:6]
        p_i = {key: value[first] for key, value in piece.items() if key in PIECE_KEYS}
        p_j = {key: value[second] for key, value in piece.items() if key in PIECE_KEYS}
        reach = p_i['s0'] + p_j['s0']
        dq = q[:, first] - q[:, second]
        # beyond twice the reach the activation is below 1e-9: no force there
        near = np.sum(dq * dq, axis=0) < (2.0 * reach) ** 2
        f = near * reference_pair_force(q[:, first], qdot[:, first], p_i, q[:, second],
                                        qdot[:, second], p_j, omega, pull_off)
        np.add.at(out[3:6], (slice(None), first), f / p_i['m'])
        np.add.at(out[3:6], (slice(None), second), -f / p_j['m'])
    return out.transpose(1, 0, 2).reshape(np.shape(y))


@numba.njit(cache=True)
def _compiled_crowd_rhs(y: np.ndarray, piece: np.ndarray, cone: np.ndarray, omega: float,
                        pull_off: float) -> np.ndarray:
    """
    Return dy/dt (9 n, k) of crowd_rhs for y (9 n, k), in plain loops.

    piece (n, 15): the PIECE_KEYS row of every piece; cone: reference_model.cone_row. The
    default readings of the model (newton normal force, full friction direction) only. The
    same equations as reference_pair_force, written out scalar by scalar so that numba
    compiles them; test_reference_contacts checks the two against each other.
    """
    count, columns = piece.shape[0], y.shape[1]
    out = np.empty_like(y)
    for c in range(columns):
        for i in range(count):
            piece_rhs_into(out, y, 9 * i, c, piece[i], cone, omega, False, False)
        for i in range(count):
            for j in range(i + 1, count):
                bi, bj = 9 * i, 9 * j
                dx = y[bi, c] - y[bj, c]
                dy = y[bi + 1, c] - y[bj + 1, c]
                dz = y[bi + 2, c] - y[bj + 2, c]
                reach = piece[i, 10] + piece[j, 10]
                if dx * dx + dy * dy + dz * dz >= (2.0 * reach) ** 2:
                    continue  # the activation is below 1e-9 there: no force worth a call
                pair = 0.5 * (piece[i] + piece[j])
                dist = max(math.sqrt(dx * dx + dy * dy + dz * dz), 1e-9)
                nx, ny, nz = dx / dist, dy / dist, dz / dist
                s0 = piece[i, 10] + piece[j, 10]
                s_c = piece[i, 11] * piece[i, 10] + piece[j, 11] * piece[j, 10]
                r_t = 2.0 * math.atanh(pair[12]) / (s0 - s_c)
                r_act = (1.0 - math.tanh(r_t * (dist - 0.5 * (s0 + s_c)))) / 2.0
                ux = y[bi + 3, c] - y[bj + 3, c] + omega * dy
                uy = y[bi + 4, c] - y[bj + 4, c] - omega * dx
                uz = y[bi + 5, c] - y[bj + 5, c]
                v_n = ux * nx + uy * ny + uz * nz
                normal = r_act * pair[14] * (1.0 - math.tanh(pair[13] * v_n)) / 2.0
                adhesion = pull_off / math.cosh(min(r_t * abs(dist - s0), 350.0)) ** 2
                qs = friction_of(ux - v_n * nx, uy - v_n * ny, uz - v_n * nz, r_act, normal,
                                 pair)
                f = ((normal - adhesion) * nx + qs[0], (normal - adhesion) * ny + qs[1],
                     (normal - adhesion) * nz + qs[2])
                for k in range(3):
                    out[bi + 3 + k, c] += f[k] / piece[i, 6]
                    out[bj + 3 + k, c] -= f[k] / piece[j, 6]
    return out


def compiled_crowd_rhs(params: list[dict[str, Any]], pull_off: float) -> Any:
    """
    Return fun(y, omega) = crowd_rhs(y, params, omega, pull_off), compiled.

    y (9 n,) or (9 n, k) as crowd_rhs takes it. The solvers below use it; crowd_rhs (numpy)
    is the readable definition it is checked against.
    """
    assert {readings(p) for p in params} == {(False, False)}, \
        'the compiled crowd takes the default readings'
    piece = np.array([piece_row(p) for p in params])
    cone = cone_row(params[0])

    def fun(y: np.ndarray, omega: float) -> np.ndarray:
        columns = np.asarray(y, dtype=float).reshape(9 * len(params), -1)
        return _compiled_crowd_rhs(columns, piece, cone, float(omega),
                                   float(pull_off)).reshape(np.shape(y))
    return fun


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
    fun = compiled_crowd_rhs(params, pull_off)
    t_out = np.array([t_end] if t_eval is None else t_eval, dtype=float)
    cuts = sorted({0.0, t_end} | {float(t) for t, _ in table if 0.0 < t < t_end})
    y = np.asarray(y0, dtype=float).reshape(-1)
    found: dict[float, np.ndarray] = {0.0: y.copy()}
    status = 0
    for t_a, t_b in zip(cuts[:-1], cuts[1:]):
        points = sorted({float(t) for t in t_out if t_a < t <= t_b} | {t_b})
        sol = solve_ivp(lambda t, yy: fun(yy, omega_of_t(table, t)),
                        (t_a, t_b), y, method='Radau', rtol=rtol, atol=atol, t_eval=points,
                        vectorized=True)
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
        fun = compiled_crowd_rhs(own, pull_off)
        sol = solve_ivp(lambda tt, yy, fun=fun: fun(yy, omega_of_t(table, tt)),
                        (t, t_stop), np.concatenate([y[i] for i in alive]), method='Radau',
                        rtol=rtol, atol=atol, events=events, vectorized=True)
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


@shared
def rim_crowd_exits(positions: tuple[tuple[float, float, float], ...]) -> dict:
    """Return the reference exits of the rim crowd at ``positions`` (computed once a run)."""
    y0 = np.array([initial_state_on_feeder(np.array(x), 0.0) for x in positions])
    return crowd_exits([table2_params(1)] * len(positions), y0, [list(r) for r in
                       RIM_CROWD_TABLE], 1.1, pull_off=0.05)


#: Four touching pieces (x, y in m, resting on the cone) on a cone spun up to -6 rad/s: the
#: convergence case of the contact tests, compared with the reference at 0.4 s.
FOUR_TOUCHING_XY = ((0.06, 0.0), (0.105, 0.005), (0.15, 0.0), (0.08, 0.04))
FOUR_TOUCHING_TABLE = ((0.0, 0.0), (0.3, -6.0), (5.0, -6.0))


@shared
def four_touching_at(positions: tuple[tuple[float, float, float], ...]) -> np.ndarray:
    """Return the reference positions (4, 3) m at 0.4 s of the four pieces (once a run)."""
    y0 = np.array([initial_state_on_feeder(np.array(x), 0.0) for x in positions])
    return crowd_trajectory([table2_params(1)] * 4, y0, [list(r) for r in FOUR_TOUCHING_TABLE],
                            0.4, pull_off=0.05, t_eval=[0.4]).y[:, -1].reshape(4, 9)[:, :3]
