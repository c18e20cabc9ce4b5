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
Contact between two pieces in the paper's formalism (compiled), see doc/model.md.

Each piece is a soft body of outer radius s0 and compression radius s_c (Table II). Two
pieces at centre distance d touch through the cone's restriction function (eqs. 30-35)
applied to d, with the pair's radii summed: the activation

    R_a = (1 - tanh(r_t (d - r_c))) / 2,   r_c = (S0 + S_c) / 2,
    r_t = 2 artanh(r_a) / (S0 - S_c),      S0 = s0_i + s0_j, S_c = s_c_i + s_c_j,

is (1 + r_a)/2 where the pieces are compressed to S_c and (1 - r_a)/2 where they just
touch (d = S0), as on the cone (eq. 32). The dissipative constraint force
F_c = r_f (1 - tanh(r_d v_n)) / 2 acts along the line of centres n = (x_i - x_j) / d, with
v_n the normal relative velocity (> 0 separating); the normal force is N = R_a F_c.
Adhesion pulls the pieces together with A = f_po sech^2(r_t (d - S0)), largest (f_po, the
pull-off parameter) where they just touch. Friction is the paper's static friction map
(eqs. 6-10) of the tangential relative velocity with the contact's normal force N. The
coefficients r_a, r_d, r_f, d, mu_C, mu_S, v_C, v_S of a pair are the means of the two
pieces' values.

Forces are returned for piece i; piece j gets the opposite force (equal and opposite by
construction: swapping i and j flips n, v_n keeps its value, the tangential velocity flips).
Positions and velocities are in cone axes with the velocity relative to the turning cone
(the integrator's state). The pieces have no spin of their own: they are taken to turn
with the cone, so the slip at a contact is the relative velocity w_i - w_j in the cone's
frame (two pieces carried side by side do not rub). The normal relative velocity is the
same in every frame.
"""

from dataclasses import dataclass
import math
from typing import Any

import numba
import numpy as np
from scipy.integrate import solve_ivp

from .model import static_friction_magnitude
from .params import (
    P_D, P_MU_C, P_MU_S, P_R_A, P_R_D, P_R_F, P_S0, P_SC_RATIO, P_V_C, P_V_S)

__all__ = ['Collision', 'COLLISION_FORCE_FRACTION', 'head_on_collision', 'pair_force',
           'pair_force_py', 'pair_jacobian', 'PAIR_DISTANCE_FLOOR']

jit = numba.njit(cache=True, fastmath=False, error_model='numpy', nogil=True)

#: Centre distances below this (m) are taken as this (the direction of n stays defined).
PAIR_DISTANCE_FLOOR = 1.0e-9
#: Relative step of the central differences of :func:`pair_jacobian`.
FD_STEP = 1.0e-7


@jit
def pair_force(xi, wi, pi, xj, wj, pj, pull_off, epsilon):
    """
    Return the contact force on piece i from piece j (N, cone axes) as 3 floats.

    xi, xj (m) positions and wi, wj (m/s) velocities relative to the cone, shape (3,) in
    cone axes; pi, pj the pieces' product rows; pull_off (N) the adhesion amplitude;
    epsilon (m/s) the regularisation of eq. 4.
    """
    dx0, dx1, dx2 = xi[0] - xj[0], xi[1] - xj[1], xi[2] - xj[2]
    dist = max(math.sqrt(dx0 * dx0 + dx1 * dx1 + dx2 * dx2), PAIR_DISTANCE_FLOOR)
    n0, n1, n2 = dx0 / dist, dx1 / dist, dx2 / dist
    u0, u1, u2 = wi[0] - wj[0], wi[1] - wj[1], wi[2] - wj[2]
    v_n = u0 * n0 + u1 * n1 + u2 * n2
    outer = pi[P_S0] + pj[P_S0]
    inner = pi[P_S0] * pi[P_SC_RATIO] + pj[P_S0] * pj[P_SC_RATIO]
    r_a = 0.5 * (pi[P_R_A] + pj[P_R_A])
    r_t = 2.0 * math.atanh(r_a) / (outer - inner)
    r_c = 0.5 * (outer + inner)
    r_a_act = 0.5 * (1.0 - math.tanh(r_t * (dist - r_c)))
    f_c = 0.25 * (pi[P_R_F] + pj[P_R_F]) * (1.0 - math.tanh(0.5 * (pi[P_R_D] + pj[P_R_D]) * v_n))
    normal = r_a_act * f_c
    sech = 1.0 / math.cosh(min(r_t * abs(dist - outer), 350.0))
    along = normal - pull_off * sech * sech
    # friction: the static map of the tangential relative velocity, normal force N
    t0, t1, t2 = u0 - v_n * n0, u1 - v_n * n1, u2 - v_n * n2
    v_t = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    mu_c = 0.5 * (pi[P_MU_C] + pj[P_MU_C])
    v_c = 0.5 * (pi[P_V_C] + pj[P_V_C])
    v_s = 0.5 * (pi[P_V_S] + pj[P_V_S])
    c_s = 0.5 * (pi[P_MU_S] + pj[P_MU_S]) - mu_c * math.tanh(v_s / v_c)
    mag = static_friction_magnitude(v_t, normal, r_a_act, 0.5 * (pi[P_D] + pj[P_D]), mu_c,
                                    v_c, v_s, c_s)
    s = -mag / (v_t + epsilon)
    return along * n0 + s * t0, along * n1 + s * t1, along * n2 + s * t2


@jit
def pair_jacobian(xi, wi, pi, xj, wj, pj, pull_off, epsilon, out, sx, sw):
    """
    Write d(F)/d(x_i, w_i) of :func:`pair_force` into out (3, 6), by central differences.

    The force depends on the differences of the two pieces' positions and velocities only,
    so d(F)/d(x_j, w_j) = -out. sx, sw (3,) are scratch.
    """
    for c in range(6):
        delta = FD_STEP * max(abs(xi[c] if c < 3 else wi[c - 3]), 1e-3 if c < 3 else 1e-2)
        for m in range(3):
            sx[m] = xi[m]
            sw[m] = wi[m]
        if c < 3:
            sx[c] += delta
        else:
            sw[c - 3] += delta
        p0, p1, p2 = pair_force(sx, sw, pi, xj, wj, pj, pull_off, epsilon)
        if c < 3:
            sx[c] -= 2.0 * delta
        else:
            sw[c - 3] -= 2.0 * delta
        m0, m1, m2 = pair_force(sx, sw, pi, xj, wj, pj, pull_off, epsilon)
        out[0, c] = (p0 - m0) / (2.0 * delta)
        out[1, c] = (p1 - m1) / (2.0 * delta)
        out[2, c] = (p2 - m2) / (2.0 * delta)


def pair_force_py(xi: Any, wi: Any, pi: Any, xj: Any, wj: Any, pj: Any,
                  pull_off: float = 0.0, epsilon: float = 1.0e-7) -> np.ndarray:
    """Return :func:`pair_force` as an array, shape (3,) (N); for tests and tools."""
    a = [np.ascontiguousarray(v, dtype=np.float64) for v in (xi, wi, pi, xj, wj, pj)]
    return np.array(pair_force(a[0], a[1], a[2], a[3], a[4], a[5], float(pull_off),
                               float(epsilon)))


@dataclass(frozen=True)
class Collision:
    """
    What the contact law predicts for a head-on collision of two like pieces.

    restitution: the relative speed at t_max over the approach speed (the law is
    dissipative on approach only, so the pieces part slowly, if at all); duration (s): how
    long the contact force stays above 0.1 % of r_f; closest (m): the smallest centre
    distance; distance (m): the centre distance at the requested times, shape (K,).
    """

    restitution: float
    duration: float
    closest: float
    distance: np.ndarray


#: A collision's duration is the time the pair's force is above this fraction of r_f.
COLLISION_FORCE_FRACTION = 1.0e-3


def head_on_collision(m: float, s0: float, s_c: float, r_a: float, r_d: float, r_f: float,
                      pull_off: float, speed: float, t_max: float | None = None,
                      start: float | None = None,
                      times: np.ndarray | None = None) -> Collision:
    """
    Return the head-on collision of two like pieces in free flight, from the contact law.

    The pieces (mass m kg, radii s0 and s_c m, restriction coefficients r_a, r_d s/m,
    r_f N; adhesion pull_off N) approach along their line of centres at ``speed`` m/s
    relative to each other, from the centre distance ``start`` (m; default where the
    activation is 1e-9). With no friction along that line and gravity acting on both
    alike, the centre distance d obeys one equation, integrated with Radau at rtol 1e-10
    up to t_max (s): (m/2) d'' = R_a(d) r_f (1 - tanh(r_d d'))/2 - pull_off
    sech^2(r_t (d - S0)); t_max defaults to half a second after the pieces would touch
    (d = S0) at the approach speed. ``times`` (K,) in s from the start. doc/model.md quotes
    these figures for the default product.
    """
    outer, inner = 2.0 * s0, 2.0 * s_c
    r_t = 2.0 * math.atanh(r_a) / (outer - inner)
    r_c = 0.5 * (outer + inner)
    if start is None:
        start = r_c + math.atanh(1.0 - 2.0e-9) / r_t
    if t_max is None:
        t_max = max(start - outer, 0.0) / speed + 0.5

    def force(d: float, u: float) -> float:
        act = 0.5 * (1.0 - math.tanh(r_t * (d - r_c)))
        return act * 0.5 * r_f * (1.0 - math.tanh(r_d * u))

    def field(_t: float, z: np.ndarray) -> list[float]:
        d, u = z
        stick = pull_off / math.cosh(min(r_t * abs(d - outer), 350.0)) ** 2
        return [u, (force(d, u) - stick) / (0.5 * m)]

    def strong(_t: float, z: np.ndarray) -> float:
        return force(z[0], z[1]) - COLLISION_FORCE_FRACTION * r_f

    sol = solve_ivp(field, (0.0, t_max), [start, -speed], method='Radau', rtol=1e-10,
                    atol=[1e-13, 1e-11], events=strong, dense_output=True)
    crossings = sol.t_events[0]
    duration = float(crossings[1] - crossings[0]) if len(crossings) >= 2 else (
        math.inf if len(crossings) else 0.0)
    distance = (sol.sol(np.asarray(times, dtype=float))[0] if times is not None
                else np.empty(0))
    return Collision(restitution=float(sol.y[1, -1]) / speed, duration=duration,
                     closest=float(sol.y[0].min()), distance=distance)
