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
The tests' own reference of the pair law: the soft-sphere law of DEM as LIGGGHTS writes it.

Written from the formulas (../shared/MODEL_NOTES.md, "Contact between pieces"), apart from
the product's kernels: Hertz normal force with the restitution's damping, SJKR cohesion, a
Mindlin tangential spring with history capped by Coulomb. :func:`dem_run` integrates pieces
in free flight (no cone, no gravity: high above a still cone gravity moves them alike) the
way a DEM code does, velocity Verlet with a step far below the contact time and the
history incremented by the tangential relative displacement of each step, rotated into
the tangent plane and capped.

:func:`cone_dem_run` does the same for pieces on the turning cone, compiled: each piece's
own model is the reference model's (``reference_model.piece_rhs_into``, the paper's
equations in the world frame), the pair law :func:`pair_force_compiled` (the transcription
of :func:`pair_force`, which a test holds it to), and the state is advanced by the classic
fourth-order Runge-Kutta method at a fixed step far below every time scale of the model
(the friction filter's 0.3 ms), the histories held over a step and then incremented by
the step's relative displacement in the frame turning with the cone (MODEL_NOTES: the
relative velocity is taken in that frame), turned with the cone, put into the new tangent
plane and capped, as a DEM code does.
"""

from dataclasses import dataclass
import math

import numba
import numpy as np
from reference_model import piece_rhs_into
from scipy.optimize import brentq, minimize_scalar

#: Default product (config/table2.yaml): kg, m, Pa, 1.
MASS, RADIUS, YOUNG, POISSON = 0.125, 0.025, 4.0e4, 0.45


@dataclass(frozen=True)
class Piece:
    """One piece's contact properties: m (kg), s0 (m), E (Pa), nu."""

    m: float = MASS
    s0: float = RADIUS
    E: float = YOUNG
    nu: float = POISSON


@dataclass(frozen=True)
class Law:
    """The pair law's parameters: restitution e, friction mu, cohesion density k (N/m^2)."""

    e: float = 0.3
    mu: float = 0.5
    k: float = 0.0


def effective(a: Piece, b: Piece) -> tuple[float, float, float, float]:
    """Return R* (m), m* (kg), Y* (Pa) and G* (Pa) of a pair (Hertz and Mindlin)."""
    r = a.s0 * b.s0 / (a.s0 + b.s0)
    m = a.m * b.m / (a.m + b.m)
    y = 1.0 / ((1.0 - a.nu ** 2) / a.E + (1.0 - b.nu ** 2) / b.E)
    g = 1.0 / (2.0 * (2.0 - a.nu) * (1.0 + a.nu) / a.E + 2.0 * (2.0 - b.nu) * (1.0 + b.nu) / b.E)
    return r, m, y, g


def beta(e: float) -> float:
    """Return ln e / sqrt(ln^2 e + pi^2)."""
    return math.log(e) / math.sqrt(math.log(e) ** 2 + math.pi ** 2)


def overlap_area(dist: float, ra: float, rb: float) -> float:
    """Return the area (m^2) of the circle where two spheres at distance dist meet."""
    if dist >= ra + rb:
        return 0.0
    # the radius of the intersection circle, from the chord of two circles
    x = (dist * dist - rb * rb + ra * ra) / (2.0 * dist)
    return math.pi * (ra * ra - x * x)


def net_pull(delta: float, k: float, a: Piece = Piece(), b: Piece = Piece()) -> float:
    """Return cohesion minus elastic push (N) of two pieces at rest at overlap delta (m)."""
    r, _, y, _ = effective(a, b)
    return k * overlap_area(a.s0 + b.s0 - delta, a.s0, b.s0) - 4.0 / 3.0 * y * math.sqrt(
        r) * delta ** 1.5


def largest_pull(k: float, a: Piece = Piece(), b: Piece = Piece()) -> float:
    """Return the largest net pull (N) over the overlap (the pull-off force)."""
    best = minimize_scalar(lambda d: -net_pull(d, k, a, b), bounds=(0.0, min(a.s0, b.s0)),
                           method='bounded', options={'xatol': 1e-14})
    return -float(best.fun)


def density_for(pull_off: float, a: Piece = Piece(), b: Piece = Piece()) -> float:
    """Return the cohesion density k whose pull-off force is pull_off (N)."""
    return brentq(lambda k: largest_pull(k, a, b) - pull_off, 1.0, 1.0e9, xtol=1e-12,
                  rtol=1e-13)


def pair_force(a: Piece, b: Piece, law: Law, d: np.ndarray, u: np.ndarray,
               xi: np.ndarray) -> tuple[np.ndarray, float, float]:
    """
    Return the force on a (N, (3,)), the normal force F_n (N) and S_t (N/m).

    F_n includes the cohesion (> 0 pushes); d = x_a - x_b, u = v_a - v_b, xi the history
    (m, (3,)). Zero apart.
    """
    dist = float(np.linalg.norm(d))
    delta = a.s0 + b.s0 - dist
    if delta <= 0.0:
        return np.zeros(3), 0.0, 0.0
    n = d / dist
    r, m, y, g = effective(a, b)
    s_n = 2.0 * y * math.sqrt(r * delta)
    s_t = 8.0 * g * math.sqrt(r * delta)
    damp = -2.0 * math.sqrt(5.0 / 6.0) * beta(law.e)
    v_n = float(u @ n)
    f_n = (4.0 / 3.0 * y * math.sqrt(r) * delta ** 1.5 - damp * math.sqrt(s_n * m) * v_n
           - law.k * overlap_area(dist, a.s0, b.s0))
    v_t = u - v_n * n
    f_t = -s_t * xi - damp * math.sqrt(s_t * m) * v_t
    cap = law.mu * abs(f_n)
    if np.linalg.norm(s_t * xi) >= cap:  # the spring alone at the cap: sliding along xi
        size = np.linalg.norm(xi)
        f_t = -cap * xi / size if size > 0.0 else np.zeros(3)
    elif np.linalg.norm(f_t) > cap:  # spring and damping over the cap: scaled to it
        f_t *= cap / np.linalg.norm(f_t)
    return f_n * n + f_t, f_n, s_t


def dem_run(pieces: list[Piece], law: Law, x: np.ndarray, v: np.ndarray, t_end: float,
            dt: float) -> dict[str, np.ndarray]:
    """
    Integrate pieces in free flight with velocity Verlet at step dt (s) to t_end (s).

    x, v (n, 3) m and m/s. Returns the final 'x', 'v' and, per step, 't', the smallest
    distance 'dist_min' between pieces 0 and 1 and their 'f_n' (N).
    """
    n = len(pieces)
    masses = np.array([p.m for p in pieces])[:, None]
    x, v = x.astype(float).copy(), v.astype(float).copy()
    history: dict[tuple[int, int], np.ndarray] = {}

    def forces(x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, float]:
        out, first = np.zeros_like(x), 0.0
        for i in range(n):
            for j in range(i + 1, n):
                xi = history.get((i, j), np.zeros(3))
                f, f_n, _ = pair_force(pieces[i], pieces[j], law, x[i] - x[j], v[i] - v[j], xi)
                out[i] += f
                out[j] -= f
                if (i, j) == (0, 1):
                    first = f_n
        return out, first

    steps = int(round(t_end / dt))
    ts, dists, normals = np.empty(steps), np.empty(steps), np.empty(steps)
    f, _ = forces(x, v)
    for k in range(steps):
        v_half = v + 0.5 * dt * f / masses
        x_new = x + dt * v_half
        for i in range(n):  # histories: the tangential displacement of the step
            for j in range(i + 1, n):
                d = x_new[i] - x_new[j]
                dist = float(np.linalg.norm(d))
                if dist >= pieces[i].s0 + pieces[j].s0:
                    history.pop((i, j), None)
                    continue
                nn = d / dist
                step = (x_new[i] - x_new[j]) - (x[i] - x[j])
                xi = history.get((i, j), np.zeros(3)) + step
                xi -= (xi @ nn) * nn
                _, f_n, s_t = pair_force(pieces[i], pieces[j], law, d, v_half[i] - v_half[j],
                                         np.zeros(3))
                cap = law.mu * abs(f_n)
                if s_t * np.linalg.norm(xi) > cap:
                    xi *= cap / (s_t * np.linalg.norm(xi))
                history[(i, j)] = xi
        x = x_new
        f, _ = forces(x, v_half)
        v = v_half + 0.5 * dt * f / masses
        f_full, first = forces(x, v)
        f = f_full
        ts[k], dists[k], normals[k] = (k + 1) * dt, np.linalg.norm(x[0] - x[1]), first
    return {'x': x, 'v': v, 't': ts, 'dist': dists, 'f_n': normals}


@numba.njit(cache=True)
def _overlap_area(dist: float, ra: float, rb: float) -> float:
    """overlap_area, compiled."""
    if dist >= ra + rb:
        return 0.0
    x = (dist * dist - rb * rb + ra * ra) / (2.0 * dist)
    return math.pi * (ra * ra - x * x)


@numba.njit(cache=True)
def pair_force_compiled(a: np.ndarray, b: np.ndarray, law: np.ndarray, d: np.ndarray,
                        u: np.ndarray, xi: np.ndarray, out: np.ndarray) -> tuple[float, float]:
    """
    :func:`pair_force`, compiled: the force on a into out (3,); return (F_n N, S_t N/m).

    a, b: [m, s0, E, nu] of each piece; law: [e, mu, k].
    """
    out[:] = 0.0
    dist = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    delta = a[1] + b[1] - dist
    if delta <= 0.0:
        return 0.0, 0.0
    n = d / dist
    r = a[1] * b[1] / (a[1] + b[1])
    m = a[0] * b[0] / (a[0] + b[0])
    y = 1.0 / ((1.0 - a[3] ** 2) / a[2] + (1.0 - b[3] ** 2) / b[2])
    g = 1.0 / (2.0 * (2.0 - a[3]) * (1.0 + a[3]) / a[2]
               + 2.0 * (2.0 - b[3]) * (1.0 + b[3]) / b[2])
    s_n = 2.0 * y * math.sqrt(r * delta)
    s_t = 8.0 * g * math.sqrt(r * delta)
    log_e = math.log(law[0])
    damp = -2.0 * math.sqrt(5.0 / 6.0) * log_e / math.sqrt(log_e * log_e + math.pi * math.pi)
    v_n = u[0] * n[0] + u[1] * n[1] + u[2] * n[2]
    f_n = (4.0 / 3.0 * y * math.sqrt(r) * delta ** 1.5 - damp * math.sqrt(s_n * m) * v_n
           - law[2] * _overlap_area(dist, a[1], b[1]))
    v_t = u - v_n * n
    f_t = -s_t * xi - damp * math.sqrt(s_t * m) * v_t
    cap = law[1] * abs(f_n)
    size = math.sqrt(xi[0] * xi[0] + xi[1] * xi[1] + xi[2] * xi[2])
    if s_t * size >= cap:
        f_t = -cap * xi / size if size > 0.0 else np.zeros(3)
    else:
        f_size = math.sqrt(f_t[0] * f_t[0] + f_t[1] * f_t[1] + f_t[2] * f_t[2])
        if f_size > cap:
            f_t = f_t * (cap / f_size)
    for k in range(3):
        out[k] = f_n * n[k] + f_t[k]
    return f_n, s_t


@numba.njit(cache=True)
def _omega(table_t: np.ndarray, table_w: np.ndarray, t: float) -> float:
    """Return the rotation table's omega at t (rad/s): linear between points, held outside."""
    if t <= table_t[0]:
        return table_w[0]
    for k in range(table_t.shape[0] - 1):
        if t < table_t[k + 1]:
            return table_w[k] + (table_w[k + 1] - table_w[k]) * (t - table_t[k]) / (
                table_t[k + 1] - table_t[k])
    return table_w[-1]


@numba.njit(cache=True)
def _stage_history(y0, y, i, j, hist, w, tau, out):  # type: ignore[no-untyped-def]
    """
    Write into out (3,) the history of pair (i, j) at a stage tau (s) into the step from y0.

    The step's history (hist, at its start) turned with the cone by w tau, plus the
    relative displacement since the start in the frame turning with the cone, in the
    tangent plane of the stage (a DEM code increments the history before it computes the
    step's force; capping is the force's: :func:`pair_force_compiled` slides beyond it).
    """
    c, s = math.cos(w * tau), math.sin(w * tau)
    d0 = np.empty(3)
    d = np.empty(3)
    for k in range(3):
        d0[k] = y0[9 * i + k, 0] - y0[9 * j + k, 0]
        d[k] = y[9 * i + k, 0] - y[9 * j + k, 0]
    out[0] = c * hist[0] - s * hist[1] + d[0] - d0[0] + w * tau * 0.5 * (d0[1] + d[1])
    out[1] = s * hist[0] + c * hist[1] + d[1] - d0[1] - w * tau * 0.5 * (d0[0] + d[0])
    out[2] = hist[2] + d[2] - d0[2]
    dist = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    along = (out[0] * d[0] + out[1] * d[1] + out[2] * d[2]) / (dist * dist)
    for k in range(3):
        out[k] -= along * d[k]


@numba.njit(cache=True)
def _pair_state(y, i, j, w, contact, d, u):  # type: ignore[no-untyped-def]
    """
    Write x_i - x_j into d and v_i - v_j in the frame turning with the cone into u (3,).

    y (9n, 1) world states, w (rad/s) the cone's speed; return whether the pair touches.
    """
    for k in range(3):
        d[k] = y[9 * i + k, 0] - y[9 * j + k, 0]
        u[k] = y[9 * i + 3 + k, 0] - y[9 * j + 3 + k, 0]
    u[0] += w * d[1]
    u[1] -= w * d[0]
    return math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) < contact[i, 1] + contact[j, 1]


@numba.njit(cache=True)
def _field(t, tau, y0, y, active, hist, rows, contact, law, cone, literal, tangential,
           table_t, table_w, out):  # type: ignore[no-untyped-def]
    """dy/dt (9n, 1) at t + tau of the pieces on the cone with their pair forces."""
    n = active.shape[0]
    w = _omega(table_t, table_w, t + tau)
    w_mid = _omega(table_t, table_w, t + 0.5 * tau)
    out[:] = 0.0
    force = np.empty(3)
    d = np.empty(3)
    u = np.empty(3)
    xi = np.empty(3)
    for p in range(n):
        if active[p]:
            piece_rhs_into(out, y, 9 * p, 0, rows[p], cone, w, literal, tangential)
    for i in range(n):
        for j in range(i + 1, n):
            if not (active[i] and active[j]):
                continue
            if not _pair_state(y, i, j, w, contact, d, u):
                continue
            _stage_history(y0, y, i, j, hist[i, j], w_mid, tau, xi)
            pair_force_compiled(contact[i], contact[j], law, d, u, xi, force)
            for k in range(3):
                out[9 * i + 3 + k, 0] += force[k] / contact[i, 0]
                out[9 * j + 3 + k, 0] -= force[k] / contact[j, 0]


@numba.njit(cache=True)
def _cone_dem(rows, contact, law, cone, literal, tangential, y0, table_t, table_w, t_end,
              dt, r_exit, t_exit, y_end):  # type: ignore[no-untyped-def]
    n = y0.shape[0]
    y = y0.reshape(9 * n, 1).copy()
    active = np.ones(n, dtype=np.bool_)
    hist = np.zeros((n, n, 3))
    k1 = np.empty_like(y)
    k2 = np.empty_like(y)
    k3 = np.empty_like(y)
    k4 = np.empty_like(y)
    stage = np.empty_like(y)
    force = np.empty(3)
    zero = np.zeros(3)
    d = np.empty(3)
    u = np.empty(3)
    xi = np.empty(3)
    steps = int(round(t_end / dt))
    half = 0.5 * dt
    for step in range(steps):
        t = step * dt
        _field(t, 0.0, y, y, active, hist, rows, contact, law, cone, literal, tangential,
               table_t, table_w, k1)
        stage[:] = y + half * k1
        _field(t, half, y, stage, active, hist, rows, contact, law, cone, literal,
               tangential, table_t, table_w, k2)
        stage[:] = y + half * k2
        _field(t, half, y, stage, active, hist, rows, contact, law, cone, literal,
               tangential, table_t, table_w, k3)
        stage[:] = y + dt * k3
        _field(t, dt, y, stage, active, hist, rows, contact, law, cone, literal,
               tangential, table_t, table_w, k4)
        stage[:] = y + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        # the histories at the step's end: incremented, in the tangent plane, capped
        w_mid = _omega(table_t, table_w, t + half)
        w = _omega(table_t, table_w, t + dt)
        for i in range(n):
            for j in range(i + 1, n):
                if not (active[i] and active[j]):
                    continue
                if not _pair_state(stage, i, j, w, contact, d, u):
                    hist[i, j, :] = 0.0
                    continue
                _stage_history(y, stage, i, j, hist[i, j], w_mid, dt, xi)
                f_n, s_t = pair_force_compiled(contact[i], contact[j], law, d, u, zero, force)
                cap = law[1] * abs(f_n)
                size = math.sqrt(xi[0] * xi[0] + xi[1] * xi[1] + xi[2] * xi[2])
                scale = cap / (s_t * size) if s_t * size > cap else 1.0
                for k in range(3):
                    hist[i, j, k] = xi[k] * scale
        for p in range(n):
            if not active[p]:
                continue
            b = 9 * p
            r_new = math.hypot(stage[b, 0], stage[b + 1, 0])
            if r_new >= r_exit:
                r_old = math.hypot(y[b, 0], y[b + 1, 0])
                theta = (r_exit - r_old) / (r_new - r_old)
                t_exit[p] = t + theta * dt
                for k in range(9):
                    y_end[p, k] = y[b + k, 0] + theta * (stage[b + k, 0] - y[b + k, 0])
                active[p] = False
                for q in range(n):
                    hist[min(p, q), max(p, q), :] = 0.0
        y[:] = stage
    for p in range(n):
        if active[p]:
            t_exit[p] = np.nan
            for k in range(9):
                y_end[p, k] = y[9 * p + k, 0]


@dataclass(frozen=True)
class ConeRun:
    """
    What :func:`cone_dem_run` returns.

    Per piece the exit time (s, NaN: stayed), the exit angle (deg, NaN: stayed) and the
    state at the exit or at the end, (n, 9), world frame.
    """

    t_exit: np.ndarray
    angle_deg: np.ndarray
    y: np.ndarray


def cone_dem_run(params: list[dict], law: Law, y0: np.ndarray, table: list[list[float]],
                 t_end: float, dt: float = 1.0e-6) -> ConeRun:
    """
    Integrate pieces on the turning cone with their pair forces, as a DEM code does.

    params: one reference_model parameter dict per piece (its product and the cone, the
    same cone for all; young_modulus and poisson_ratio default to the product's 40 kPa and
    0.45); law: the pair law; y0 (n, 9) world states [q, q_dot, Q_d]; table: the rotation
    table [[t s, omega rad/s], ...]; dt (s) the fixed step. Pieces that cross the rim are
    taken out at the crossing (linear within the step), with their pairs.
    """
    from reference_model import cone_row, piece_row, readings
    rows = np.array([piece_row(p) for p in params])
    contact = np.array([[p['m'], p['s0'], p.get('young_modulus', YOUNG),
                         p.get('poisson_ratio', POISSON)] for p in params])
    literal, tangential = readings(params[0])
    table_arr = np.asarray(table, dtype=float)
    n = len(params)
    t_exit = np.empty(n)
    y_end = np.empty((n, 9))
    cone = cone_row(params[0])
    _cone_dem(rows, contact, np.array([law.e, law.mu, law.k]), cone, literal, tangential,
              np.asarray(y0, dtype=float), table_arr[:, 0].copy(), table_arr[:, 1].copy(),
              float(t_end), float(dt), float(cone[0]), t_exit, y_end)
    angle = np.where(np.isnan(t_exit), np.nan,
                     np.mod(np.degrees(np.arctan2(y_end[:, 1], y_end[:, 0])), 360.0))
    return ConeRun(t_exit=t_exit, angle_deg=angle, y=y_end)
