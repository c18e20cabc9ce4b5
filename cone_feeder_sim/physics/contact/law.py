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
The pair law whole: the constants of a pair, its force and the update of its history.

A pair (i, j) is described by the difference of the two pieces' positions dx = x_i - x_j
(m) and velocities u = w_i - w_j (m/s), in cone axes with the velocities relative to the
turning cone (the integrator's state), and by its history xi (m, 3). The overlap is
delta = s0_i + s0_j - |dx|, the normal n = dx / |dx| points from j to i, and the force
returned acts on i (j gets the opposite):

    F = (F_n - F_coh) n + F_t,   F_n, S_n  from :func:`.normal.hertz`,
                                 F_coh = k A from :mod:`.cohesion`,
                                 F_t       from :func:`.tangential.mindlin` with the cap
                                           mu |F_n - F_coh| (LIGGGHTS adds the cohesion to
                                           the normal force before the tangential part).

The pair's constants: R* = s0_i s0_j / (s0_i + s0_j), m* = m_i m_j / (m_i + m_j),
1/Y* = (1 - nu_i^2)/E_i + (1 - nu_j^2)/E_j and 1/G* = 2(2 - nu_i)(1 + nu_i)/E_i + (the same
of j) (product rows P_Y_COMPLIANCE, P_G_COMPLIANCE). The interaction row holds what belongs
to the law: beta (from the restitution), mu and the cohesion density k (from the pull-off).
"""

import math

import numba
import numpy as np

from .cohesion import contact_area, density_for_pull_off
from .normal import damping_ratio, hertz
from .tangential import mindlin, rotate_and_cap
from ..params import (
    ModelParams, P_G_COMPLIANCE, P_M, P_S0, P_Y_COMPLIANCE, product_row)

__all__ = ['contact_force', 'contact_force_py', 'force_between', 'history_update',
           'interaction_row', 'INTERACTION_WIDTH', 'I_BETA', 'I_COHESION', 'I_MU',
           'moved_force', 'pair_constants']

jit = numba.njit(cache=True, error_model='numpy', nogil=True)

#: Columns of the interaction row: damping ratio beta, friction mu, cohesion density k.
I_BETA, I_MU, I_COHESION = range(3)
INTERACTION_WIDTH = 3


def interaction_row(model: ModelParams) -> np.ndarray:
    """
    Return the law's row (INTERACTION_WIDTH,): beta, mu and k (N/m^2), read-only.

    k is sized so that two pieces of the model's default product pull each other apart with
    at most ``pull_off`` (:func:`.cohesion.density_for_pull_off`), and is 0 where the law is
    off (no pair is evaluated then; sizing it loads scipy's root finder).
    """
    inter, product = model.interactions, model.product
    default = product_row(product)
    y_star = pair_constants(default, default)[2]
    cohesion = (density_for_pull_off(inter.pull_off, y_star, product.s0, product.s0)
                if inter.enabled else 0.0)
    row = np.array([damping_ratio(inter.restitution), inter.friction, cohesion])
    row.setflags(write=False)
    return row


@jit
def pair_constants(pi, pj):
    """Return (R* m, m* kg, Y* Pa, G* Pa) of pieces with product rows pi and pj."""
    r_star = pi[P_S0] * pj[P_S0] / (pi[P_S0] + pj[P_S0])
    m_star = pi[P_M] * pj[P_M] / (pi[P_M] + pj[P_M])
    y_star = 1.0 / (pi[P_Y_COMPLIANCE] + pj[P_Y_COMPLIANCE])
    g_star = 1.0 / (pi[P_G_COMPLIANCE] + pj[P_G_COMPLIANCE])
    return r_star, m_star, y_star, g_star


@jit
def contact_force(d0, d1, d2, u0, u1, u2, h0, h1, h2, pi, pj, inter):
    """
    Return the force on i (3 floats, N) and (delta m, F_n N, S_t N/m, n0, n1, n2).

    d = x_i - x_j (m), u = w_i - w_j (m/s), h the history (m). F_n is the normal force
    with the cohesion (> 0 pushes apart). Apart (delta <= 0): zero force, delta < 0.
    """
    dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    delta = pi[P_S0] + pj[P_S0] - dist
    if delta <= 0.0 or dist == 0.0:
        return 0.0, 0.0, 0.0, delta, 0.0, 0.0, 0.0, 0.0, 1.0
    n0, n1, n2 = d0 / dist, d1 / dist, d2 / dist
    v_n = u0 * n0 + u1 * n1 + u2 * n2
    t0, t1, t2 = u0 - v_n * n0, u1 - v_n * n1, u2 - v_n * n2
    r_star, m_star, y_star, g_star = pair_constants(pi, pj)
    beta = inter[I_BETA]
    push, _ = hertz(delta, v_n, y_star, r_star, m_star, beta)
    f_n = push - inter[I_COHESION] * contact_area(dist, pi[P_S0], pj[P_S0])
    s_t = 8.0 * g_star * math.sqrt(r_star * delta)
    f0, f1, f2, _ = mindlin(h0, h1, h2, t0, t1, t2, s_t, m_star, beta,
                            inter[I_MU] * abs(f_n))
    return (f_n * n0 + f0, f_n * n1 + f1, f_n * n2 + f2, delta, f_n, s_t, n0, n1, n2)


@jit
def history_update(h0, h1, h2, e0, e1, e2, d0, d1, d2, u0, u1, u2, pi, pj, inter):
    """
    Return a contact's history (3 floats, m) after the relative displacement e (m).

    e = the change of x_i - x_j over the interval (the integral of the tangential relative
    velocity, with its normal part, which goes); d, u the pair's position and velocity
    differences at the interval's end. The displacement is added, the history turned into
    the end's tangent plane and capped at mu |F_n| / S_t there (LIGGGHTS' order). A pair
    apart at the end has no history: zeros.
    """
    _, _, _, delta, f_n, s_t, n0, n1, n2 = contact_force(d0, d1, d2, u0, u1, u2, 0.0, 0.0,
                                                         0.0, pi, pj, inter)
    if delta <= 0.0:
        return 0.0, 0.0, 0.0
    return rotate_and_cap(h0 + e0, h1 + e1, h2 + e2, n0, n1, n2, s_t,
                          inter[I_MU] * abs(f_n))


@jit
def force_between(yi, yj, h0, h1, h2, pi, pj, inter):
    """
    Return :func:`contact_force` of pieces i and j from their state rows yi, yj.

    The rows are the integrator's (positions 0-2, velocities 3-5, cone frame); h the
    contact's history (m).
    """
    return contact_force(yi[0] - yj[0], yi[1] - yj[1], yi[2] - yj[2], yi[3] - yj[3],
                         yi[4] - yj[4], yi[5] - yj[5], h0, h1, h2, pi, pj, inter)


@jit
def moved_force(h0, h1, h2, e0, e1, e2, d0, d1, d2, u0, u1, u2, pi, pj, inter):
    """
    Return the history after the displacement e and the force with it (6 floats: m, N).

    :func:`history_update` then :func:`contact_force` at the position and velocity
    differences d (m), u (m/s) reached.
    """
    g0, g1, g2 = history_update(h0, h1, h2, e0, e1, e2, d0, d1, d2, u0, u1, u2, pi, pj, inter)
    f = contact_force(d0, d1, d2, u0, u1, u2, g0, g1, g2, pi, pj, inter)
    return g0, g1, g2, f[0], f[1], f[2]


def contact_force_py(dx: object, du: object, history: object, pi: object, pj: object,
                     inter: object) -> tuple[np.ndarray, dict[str, float]]:
    """
    Return :func:`contact_force` as (force (3,) N, quantities); for tests and tools.

    dx, du, history (3,) as the kernel takes them; the quantities are delta (m), F_n (N),
    S_t (N/m) and the normal n (3,).
    """
    a = [np.ascontiguousarray(v, dtype=np.float64) for v in (dx, du, history, pi, pj, inter)]
    out = contact_force(a[0][0], a[0][1], a[0][2], a[1][0], a[1][1], a[1][2], a[2][0],
                        a[2][1], a[2][2], a[3], a[4], a[5])
    return np.array(out[:3]), {'delta': out[3], 'F_n': out[4], 'S_t': out[5],
                               'n': np.array(out[6:9])}
