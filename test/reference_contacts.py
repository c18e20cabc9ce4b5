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
"""

from dataclasses import dataclass
import math

import numpy as np
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
