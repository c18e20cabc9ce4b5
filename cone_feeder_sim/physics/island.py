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
The island coupling of pieces that touch: one linearly implicit step per island (compiled).

The default of ``interactions.coupling`` (``island``). Pieces linked by pairs within reach
form an island (:func:`.exact.islands_of`); every island has its own clock and step size,
and all its pieces take a common step of a Rosenbrock-W method. Each stage's field is the
island's whole field at that stage's states: every piece's own field
(:func:`.model.rhs`), the pair forces (:func:`.contact.force_between`, equal and
opposite) and the histories' own equation (:func:`.exact.history_rate`). The linear systems
use each piece's own Jacobian block only (exact, :func:`.model.rhs_jacobian`, reduced to 3x3
solves by :func:`.rosenbrock.factor_mechanical`); the histories' block is left out (their
rates are not stiff). So a stage costs what the pieces alone cost, plus the pairs.

Why this works: what is stiff is each piece's own friction (the regularised Coulomb slope,
the filter), which its block holds exactly; the soft contact of raw meat is not stiff at
the steps the pieces take (two default pieces pressed 2 mm: about 63 rad/s, 100 ms a
period). A method whose order does not depend on the Jacobian is needed for that: a W-method,
:data:`ROS34PW2` (Rang & Angermann 2005, as PETSc's TSROSWRA34PW2: 4 stages, order 3,
L-stable, stiffly accurate, embedded order 2). RODAS4 with the same block Jacobian loses
its order on the pair terms (``benchmarks/island_method.py`` measures both).

A piece much faster than its island does not set its pace (:func:`advance_island`): the
common step is sized so that about :data:`REFINED_FRACTION` of the pieces fail their own
error test, and those, with the pairs that fail, are refined: each connected part of them
is advanced alone over the step by its own adaptive steps with its loads from the rest of
the island linear over the step (Savcenco's multirate Rosenbrock); the rest of the island
is taken again with equal and opposite linear loads, so momentum is kept, and the step
counts only when the refined parts change the loads at its end within the tolerance.

Error control covers the island's whole state, pieces (as a piece alone) and histories
(positions' tolerance), at the solver's own tolerances; no coupling tolerance. Pieces that
reach the rim leave at their exit time, located inside the step as for a piece alone, and
the rest of the island goes on from there. A stiff contact (a user's glass spheres) is no
wrong answer either: the explicit part of the step then fails the error test and the step
shrinks, so it only costs more steps. Islands are independent: they run in parallel on
numba's threads, each on one, so results do not depend on the thread count.
"""

import math

import numba
import numpy as np

from .contact import contact_force
from .contact.law import force_between
from .contact.tangential import rotate_and_cap
from .exact import history_rate_of
from .integrator import (
    ACTIVE, advance_particle, after_acceptance, error_norm, EXITED, FAILED, locate_exit,
    proposal_after_rejection, REASON_NOT_FINITE, REASON_STEP_UNDERFLOW, REASON_TOO_MANY_STEPS,
    STAT_ACCEPTED, STAT_REASON, STAT_REJECTED, STOPPED)
from .model import rhs, rhs_jacobian, rhs_omega_derivative, STATE_SIZE
from .params import P_M
from .rosenbrock import factor_mechanical, solve_mechanical
from .stop import stop_requested

__all__ = ['advance_islands', 'Method', 'METHODS', 'ROS34PW2', 'RODAS4_BLOCK']

jit = numba.njit(cache=True, error_model='numpy', nogil=True)
pjit = numba.njit(cache=True, error_model='numpy', nogil=True, parallel=True)


class Method:
    """
    A Rosenbrock(-W) method in the transformed form of Hairer & Wanner (IV.7).

    The stages and the step::

        (I/(gamma h) - J) u_i = f(t + c_i h, y + sum_j a_ij u_j) + sum_j (c_ij / h) u_j
                                + d_i h f_t,
        y1 = y + sum_i m_i u_i,   error estimate sum_i e_i u_i.

    Arrays: a, c (s, s) strictly lower triangular; times, d, m, e (s,); gamma; order: that
    of the embedded estimate (the error is O(h^(order + 1))).
    """

    def __init__(self, name: str, gamma: float, a: list, c: list, times: list, d: list,
                 m: list, e: list, order: float) -> None:
        """Build the arrays from the lower triangles given row by row."""
        s = len(times)
        self.name = name
        self.gamma = gamma
        self.a = np.zeros((s, s))
        self.c = np.zeros((s, s))
        for i in range(s):
            self.a[i, :i] = a[i]
            self.c[i, :i] = c[i]
        self.times = np.array(times, dtype=float)
        self.d = np.array(d, dtype=float)
        self.m = np.array(m, dtype=float)
        self.e = np.array(e, dtype=float)
        self.order = float(order)
        for array in (self.a, self.c, self.times, self.d, self.m, self.e):
            array.setflags(write=False)


#: ROS34PW2 (Rang & Angermann 2005; PETSc's TSROSWRA34PW2), transformed from its Alpha,
#: Gamma, b and b-hat in 40-digit arithmetic (A = Alpha Gamma^-1, C = diag(Gamma^-1) -
#: Gamma^-1, m = b Gamma^-1, e = (b - b-hat) Gamma^-1; d the row sums of Gamma).
ROS34PW2 = Method(
    'ROS34PW2', 0.435866521508459,
    a=[[], [2.0], [1.4192173174557647, -0.2592322116729697],
       [4.18476048231916, -0.28519201735549593, 2.294280360279042]],
    c=[[], [-4.588560720558084], [-4.18476048231916, 0.28519201735549593],
       [-6.368179200128358, -6.795620944466836, 2.870098604331056]],
    times=[0.0, 0.871733043016918, 0.7315799577888524, 1.0],
    d=[0.435866521508459, -0.435866521508459, -0.4133333762338865, 0.0],
    m=[4.18476048231916, -0.2851920173554959, 2.2942803602790414, 1.0],
    e=[0.2777499476479681, -1.403239895175999, 1.7726301276675507, 0.5],
    order=2.0)


def _rodas4() -> Method:
    """Return RODAS4 (the pieces' own method, :mod:`.rosenbrock`) in the same form."""
    from . import rosenbrock as r
    a5 = [r.A51, r.A52, r.A53, r.A54]
    return Method(
        'RODAS4 (block Jacobian)', r.GAMMA,
        a=[[], [r.A21], [r.A31, r.A32], [r.A41, r.A42, r.A43], a5, a5 + [1.0]],
        c=[[], [r.C21], [r.C31, r.C32], [r.C41, r.C42, r.C43], [r.C51, r.C52, r.C53, r.C54],
           [r.C61, r.C62, r.C63, r.C64, r.C65]],
        times=[0.0, r.C2, r.C3, r.C4, 1.0, 1.0], d=[r.D1, r.D2, r.D3, r.D4, 0.0, 0.0],
        m=a5 + [1.0, 1.0], e=[0.0, 0.0, 0.0, 0.0, 0.0, 1.0], order=float(r.ERROR_ORDER))


#: RODAS4 with each piece's own Jacobian block only: for the comparison of the two.
RODAS4_BLOCK = _rodas4()
METHODS = {'ros34pw2': ROS34PW2, 'rodas4': RODAS4_BLOCK}


@jit
def island_field(ys, hs, members, lpairs, active, products, inter, machine, omega, domega,
                 ext, ext_rate, tau, out, hout):
    """
    Write the island's field: pieces' (n, 9) into out, histories' (m, 3) into hout.

    ys (n, 9), hs (m, 3) the states; members (n,) the pieces' rows in products; lpairs
    (m, 2) the pairs as local indices; active (n,) pieces still on the cone (the others get
    a zero field, their pairs none); ext + ext_rate tau (n, 3) (m/s^2) loads from pairs
    outside the island (a refined part of one: zeros for a whole island), tau (s) the time
    since the loads' start.
    """
    n = ys.shape[0]
    for p in range(n):
        if active[p]:
            rhs(ys[p], products[members[p]], machine, omega, domega, out[p])
            for a in range(3):
                out[p, 3 + a] += ext[p, a] + ext_rate[p, a] * tau
        else:
            out[p, :] = 0.0
    add_pairs_field(ys, hs, members, lpairs, active, products, inter, out, hout)


@jit
def add_pairs_field(ys, hs, members, lpairs, active, products, inter, out, hout):
    """Add the pairs' forces to the pieces' field out (n, 9); write the histories' hout."""
    for q in range(lpairs.shape[0]):
        i = lpairs[q, 0]
        j = lpairs[q, 1]
        hout[q, 0] = hout[q, 1] = hout[q, 2] = 0.0
        if not (active[i] and active[j]):
            continue
        pi = products[members[i]]
        pj = products[members[j]]
        f = force_between(ys[i], ys[j], hs[q, 0], hs[q, 1], hs[q, 2], pi, pj, inter)
        if f[3] <= 0.0:  # apart: no force, no history
            continue
        inv_i = 1.0 / pi[P_M]
        inv_j = 1.0 / pj[P_M]
        for a in range(3):
            out[i, 3 + a] += f[a] * inv_i
            out[j, 3 + a] -= f[a] * inv_j
    for q in range(lpairs.shape[0]):
        i = lpairs[q, 0]
        j = lpairs[q, 1]
        if not (active[i] and active[j]):
            continue
        pi = products[members[i]]
        pj = products[members[j]]
        d0, d1, d2 = ys[i, 0] - ys[j, 0], ys[i, 1] - ys[j, 1], ys[i, 2] - ys[j, 2]
        u0, u1, u2 = ys[i, 3] - ys[j, 3], ys[i, 4] - ys[j, 4], ys[i, 5] - ys[j, 5]
        f = contact_force(d0, d1, d2, u0, u1, u2, hs[q, 0], hs[q, 1], hs[q, 2], pi, pj, inter)
        if f[3] <= 0.0:
            continue
        r = history_rate_of(f, d0, d1, d2, u0, u1, u2, out[i, 3] - out[j, 3],
                            out[i, 4] - out[j, 4], out[i, 5] - out[j, 5], hs[q, 0], hs[q, 1],
                            hs[q, 2], pi, pj, inter)
        hout[q, 0] = r[0]
        hout[q, 1] = r[1]
        hout[q, 2] = r[2]


@jit
def pair_loads(ys, hs, members, lpairs, active, inside, products, inter, out):
    """
    Write the pieces' accelerations (n, 3) (m/s^2) from their pairs at (ys, hs) into out.

    inside (n,): with any piece marked, only the loads of marked pieces from unmarked ones
    (the loads a refined part gets from the rest of its island); with none, every pair.
    """
    out[:] = 0.0
    split = False
    for p in range(inside.shape[0]):
        split = split or inside[p]
    for q in range(lpairs.shape[0]):
        i = lpairs[q, 0]
        j = lpairs[q, 1]
        if not (active[i] and active[j]) or (split and inside[i] == inside[j]):
            continue
        pi = products[members[i]]
        pj = products[members[j]]
        f = force_between(ys[i], ys[j], hs[q, 0], hs[q, 1], hs[q, 2], pi, pj, inter)
        if not split or inside[i]:
            for a in range(3):
                out[i, a] += f[a] / pi[P_M]
        if not split or inside[j]:
            for a in range(3):
                out[j, a] -= f[a] / pj[P_M]


@jit
def settle(ys, hs, members, lpairs, active, products, inter):
    """
    Settle the histories after a step.

    A pair apart (or with a piece gone) loses its history; the others are turned into their
    tangent plane (round-off leaves a normal trace).
    """
    for q in range(lpairs.shape[0]):
        i = lpairs[q, 0]
        j = lpairs[q, 1]
        if not (active[i] and active[j]):
            hs[q, :] = 0.0
            continue
        f = contact_force(ys[i, 0] - ys[j, 0], ys[i, 1] - ys[j, 1], ys[i, 2] - ys[j, 2],
                          ys[i, 3] - ys[j, 3], ys[i, 4] - ys[j, 4], ys[i, 5] - ys[j, 5],
                          0.0, 0.0, 0.0, products[members[i]], products[members[j]], inter)
        if f[3] <= 0.0:
            hs[q, :] = 0.0
            continue
        h0, h1, h2 = rotate_and_cap(hs[q, 0], hs[q, 1], hs[q, 2], f[6], f[7], f[8], f[5],
                                    np.inf)
        hs[q, 0] = h0
        hs[q, 1] = h1
        hs[q, 2] = h2


@jit
def step_errors(err, errh, y0, y1, h1, members, lpairs, active, products, inter, rtol, atol,
                e_mem, e_pair):
    """
    Write each active piece's scaled RMS error into e_mem (n,) and each pair's into e_pair.

    A history (m) is a displacement: its error counts at the positions' tolerance (atol[0:3],
    rtol). (Counted by the force it makes, at the filter force's tolerance, the tolerance
    was looser than the positions': the paper's samples 1 and 5 with contact then left the
    cone 0.13 and 0.23 deg away from the exact coupling's exits.)
    """
    for p in range(y0.shape[0]):
        e_mem[p] = error_norm(err[p], y0[p], y1[p], rtol, atol) if active[p] else 0.0
    for q in range(h1.shape[0]):
        i = lpairs[q, 0]
        j = lpairs[q, 1]
        e_pair[q] = error_norm(errh[q], h1[q], h1[q], rtol, atol) if (
            active[i] and active[j]) else 0.0


@jit
def combine_stages(base, u, m_tab, e_tab, out, err):
    """Write the step's end out = base + sum_i m_i u_i and its error err = sum_i e_i u_i (k, w)."""
    for p in range(base.shape[0]):
        for a in range(base.shape[1]):
            acc = base[p, a]
            e = 0.0
            for i in range(u.shape[0]):
                acc += m_tab[i] * u[i, p, a]
                e += e_tab[i] * u[i, p, a]
            out[p, a] = acc
            err[p, a] = e


@jit
def w_step(y0, hist0, f0, fh0, ft, h, omega0, domega, members, lpairs, active, products,
           inter, machine, ext, ext_rate, jac, lu, piv, u, uh, ys, hs, fs, fhs, y1, h1, err,
           errh, a_tab, c_tab, times, d_tab, m_tab, e_tab, gamma):
    """
    Take one step of size h of the method (a_tab ... gamma) from (y0, hist0).

    f0, fh0 the field at the start and ft (n, 9) its time derivative (loads' rates
    included); ext, ext_rate the outside loads (:func:`island_field`), their time from the
    step's start; jac (n, 9, 9) each piece's own Jacobian; lu (n, 3, 3, 3) and piv
    (n, 2, 3) scratch for its factors; u (s, n, 9) and uh (s, m, 3) the stages. Writes the
    result into y1, h1 and the error estimate into err, errh. Returns False if a piece's
    system cannot be factored or its result is not finite.
    """
    n = y0.shape[0]
    m = hist0.shape[0]
    s = times.shape[0]
    alpha = 1.0 / (gamma * h)
    inv_h = 1.0 / h
    for p in range(n):
        if active[p] and not factor_mechanical(jac[p], alpha, lu[p, 0], lu[p, 1], lu[p, 2],
                                               piv[p, 1]):
            return False
    for i in range(s):
        if i == 0:
            fs[:] = f0
            fhs[:] = fh0
        else:
            for p in range(n):
                for a in range(STATE_SIZE):
                    acc = y0[p, a]
                    for j in range(i):
                        acc += a_tab[i, j] * u[j, p, a]
                    ys[p, a] = acc
            for q in range(m):
                for a in range(3):
                    acc = hist0[q, a]
                    for j in range(i):
                        acc += a_tab[i, j] * uh[j, q, a]
                    hs[q, a] = acc
            island_field(ys, hs, members, lpairs, active, products, inter, machine,
                         omega0 + domega * times[i] * h, domega, ext, ext_rate, times[i] * h,
                         fs, fhs)
        dh = d_tab[i] * h
        for p in range(n):
            if not active[p]:
                u[i, p, :] = 0.0
                continue
            for a in range(STATE_SIZE):
                acc = fs[p, a] + dh * ft[p, a]
                for j in range(i):
                    acc += c_tab[i, j] * inv_h * u[j, p, a]
                u[i, p, a] = acc
            solve_mechanical(jac[p], alpha, lu[p, 0], lu[p, 1], piv[p, 1], u[i], p)
        for q in range(m):
            for a in range(3):
                acc = fhs[q, a]
                for j in range(i):
                    acc += c_tab[i, j] * inv_h * uh[j, q, a]
                uh[i, q, a] = acc / alpha
    combine_stages(y0, u, m_tab, e_tab, y1, err)
    combine_stages(hist0, uh, m_tab, e_tab, h1, errh)
    for p in range(n):
        if active[p]:
            for a in range(STATE_SIZE):
                if not math.isfinite(y1[p, a]):
                    return False
    return True


@jit
def load_error(h, l1, l2, y1, active, rtol, atol):
    """
    Return the largest scaled error a change of the loads at a step's end gives a piece.

    l1, l2 (n, 3) (m/s^2): the loads with which the step was taken and those the refined
    pieces give; a load off by d at the end of a step of h (linear over it) moves a velocity
    by about h d / 2 and a position by h^2 d / 6.
    """
    worst = 0.0
    for p in range(y1.shape[0]):
        if not active[p]:
            continue
        acc = 0.0
        for a in range(3):
            d = abs(l2[p, a] - l1[p, a])
            ex = h * h * d / 6.0 / (atol[a] + rtol * abs(y1[p, a]))
            ev = 0.5 * h * d / (atol[3 + a] + rtol * abs(y1[p, 3 + a]))
            acc += ex * ex + ev * ev
        worst = max(worst, math.sqrt(acc / STATE_SIZE))
    return worst


@jit
def quantile_error(e_mem, active, fraction):
    """Return the error all but ``fraction`` of the active pieces stay within."""
    values = np.empty(e_mem.shape[0])
    count = 0
    for p in range(e_mem.shape[0]):
        if active[p]:
            values[count] = e_mem[p]
            count += 1
    if count == 0:
        return 0.0
    ranked = np.sort(values[:count])
    return ranked[max(0, min(count - 1, int(math.ceil((1.0 - fraction) * count)) - 1))]


@jit
def prepare(y0, hist0, members, lpairs, active, products, inter, machine, omega0, domega, ext,
            ext_rate, f0, fh0, jac, ft, ft1):
    """Evaluate what every step from (y0, hist0) needs: the field, Jacobians, f_t."""
    for p in range(y0.shape[0]):  # each piece's field and Jacobian in one call
        if active[p]:
            rhs_jacobian(y0[p], products[members[p]], machine, omega0, domega, f0[p], jac[p])
            for a in range(3):
                f0[p, 3 + a] += ext[p, a]
        else:
            f0[p, :] = 0.0
    add_pairs_field(y0, hist0, members, lpairs, active, products, inter, f0, fh0)
    for p in range(y0.shape[0]):
        if active[p]:
            rhs_omega_derivative(y0[p], omega0, ft1)
            for a in range(STATE_SIZE):
                ft[p, a] = domega * ft1[a]
            for a in range(3):
                ft[p, 3 + a] += ext_rate[p, a]
        else:
            ft[p, :] = 0.0


@jit
def advance_part(y0, hist0, members, lpairs, active, products, inter, machine, t, h_total,
                 omega0, domega, ext, ext_rate, r_exit, h_start, rtol, atol, h_min, h_max,
                 max_steps, stats, stop, a_tab, c_tab, times, d_tab, m_tab, e_tab, gamma,
                 order, scratch, scratch3, scratch_s, scratch_sh, scratch_jac, scratch_lu,
                 scratch_piv, scratch_e):
    """
    Advance a refined part of an island (k pieces, its pairs) alone over [t, t + h_total].

    Its own adaptive steps of the method, with the loads of its pairs to the rest of the
    island linear over the interval (ext at t, ext_rate); y0 (k, 9), hist0 (m, 3) updated in
    place; stats (STAT_WIDTH,) counts its steps. Returns (status, time reached, exiting
    piece or -1, next step): ACTIVE at t + h_total; EXITED when a piece reached the rim
    (the part is then at that time); FAILED or STOPPED with the time reached.
    """
    n = y0.shape[0]
    m = hist0.shape[0]
    f0, ft, ys, fs, y1, err = (scratch[0, :n], scratch[1, :n], scratch[2, :n],
                               scratch[3, :n], scratch[4, :n], scratch[5, :n])
    fh0, hs, fhs, h1, errh = (scratch3[0, :m], scratch3[1, :m], scratch3[2, :m],
                              scratch3[3, :m], scratch3[4, :m])
    ext_now = scratch3[5, :n]
    u = scratch_s[:, :n]
    uh = scratch_sh[:, :m]
    jac = scratch_jac[:n]
    lu = scratch_lu[:n]
    piv = scratch_piv[:n]
    e_mem = scratch_e[0, :n]
    e_pair = scratch_e[1, :m]
    ft1 = scratch_e[2, :STATE_SIZE]
    r2 = r_exit * r_exit
    t_end = t + h_total
    tau = 0.0
    h_prop = h_start
    h_acc = 0.0
    err_acc = 1.0
    rejected = False
    steps = 0
    while t < t_end:
        if stop_requested(stop):
            return STOPPED, t, -1, h_prop
        remaining = t_end - t
        truncated = h_prop >= remaining
        h = remaining if truncated else h_prop
        omega = omega0 + domega * tau
        for p in range(n):
            for a in range(3):
                ext_now[p, a] = ext[p, a] + ext_rate[p, a] * tau
        prepare(y0, hist0, members, lpairs, active, products, inter, machine, omega, domega,
                ext_now, ext_rate, f0, fh0, jac, ft, ft1)
        while True:
            ok = w_step(y0, hist0, f0, fh0, ft, h, omega, domega, members, lpairs, active,
                        products, inter, machine, ext_now, ext_rate, jac, lu, piv, u, uh, ys,
                        hs, fs, fhs, y1, h1, err, errh, a_tab, c_tab, times, d_tab, m_tab,
                        e_tab, gamma)
            steps += 1
            if steps > max_steps:
                stats[STAT_REASON] = REASON_TOO_MANY_STEPS
                return FAILED, t, -1, h_prop
            e_all = np.inf
            if ok:
                step_errors(err, errh, y0, y1, h1, members, lpairs, active, products, inter,
                            rtol, atol, e_mem, e_pair)
                e_all = 0.0
                for p in range(n):
                    e_all = max(e_all, e_mem[p])
                for q in range(m):
                    e_all = max(e_all, e_pair[q])
            if e_all <= 1.0:
                break
            stats[STAT_REJECTED] += 1
            h_prop = proposal_after_rejection(h, e_all, rejected, order)
            rejected = True
            if h_prop < h_min:
                stats[STAT_REASON] = (REASON_NOT_FINITE if not math.isfinite(e_all)
                                      else REASON_STEP_UNDERFLOW)
                return FAILED, t, -1, h_prop
            h = h_prop
            truncated = False
        stats[STAT_ACCEPTED] += 1
        first = -1
        theta = 2.0
        for p in range(n):
            if active[p] and y1[p, 0] * y1[p, 0] + y1[p, 1] * y1[p, 1] >= r2:
                th = locate_exit(h, y0[p], y1[p], r_exit)
                if th < theta:
                    theta = th
                    first = p
        if first >= 0:  # the part goes to the exit time of its first piece out, and stops
            h_exit = theta * h
            ok = w_step(y0, hist0, f0, fh0, ft, h_exit, omega, domega, members, lpairs,
                        active, products, inter, machine, ext_now, ext_rate, jac, lu, piv, u,
                        uh, ys, hs, fs, fhs, y1, h1, err, errh, a_tab, c_tab, times, d_tab,
                        m_tab, e_tab, gamma)
            if not ok:
                stats[STAT_REASON] = REASON_NOT_FINITE
                return FAILED, t, -1, h_prop
            y0[:] = y1
            hist0[:] = h1
            return EXITED, t + h_exit, first, h_prop
        y0[:] = y1
        hist0[:] = h1
        settle(y0, hist0, members, lpairs, active, products, inter)
        t_new, h_prop, h_acc, err_acc = after_acceptance(t, t_end, h, h_prop, h_max, e_all,
                                                         h_acc, err_acc, rejected, truncated,
                                                         order)
        tau += t_new - t
        t = t_new
        rejected = False
    return ACTIVE, t, -1, h_prop


#: The common step of an island is sized so that about this fraction of its pieces are
#: refined alone; at most REFINE_MAX_FRACTION may be, else the common step is shortened.
REFINED_FRACTION = 0.25
REFINE_MAX_FRACTION = 0.5

# counters of an island (counters (ISLAND_COUNTERS,) int64): common steps tried, accepted,
# pieces refined in accepted steps, and steps rejected for each reason: a piece's system
# singular or non-finite, too many fast pieces and pairs, the refined parts' loads, an error
# that refining cannot take
(IC_STEPS, IC_ACCEPTED, IC_REFINED, IC_REJECT_FAILED, IC_REJECT_CROWDED, IC_REJECT_LOADS,
 IC_REJECT_ERROR) = range(7)
ISLAND_COUNTERS = 7


@jit
def label_parts(fast, lpairs, labels):
    """
    Label the refined parts: connected components of the fast pieces over their pairs.

    fast (n,) marks the pieces to refine; labels (n,) receives each fast piece's part (its
    smallest member) and -1 for the others. Returns the number of parts.
    """
    n = fast.shape[0]
    for p in range(n):
        labels[p] = p if fast[p] else -1
    changed = True
    while changed:  # a few sweeps: the parts are small
        changed = False
        for q in range(lpairs.shape[0]):
            i = lpairs[q, 0]
            j = lpairs[q, 1]
            if fast[i] and fast[j] and labels[i] != labels[j]:
                low = min(labels[i], labels[j])
                labels[i] = labels[j] = low
                changed = True
    count = 0
    for p in range(n):
        count += labels[p] == p
    return count


@jit
def advance_island(y, hist, members, lpairs, products, inter, machine, seg_t, seg_omega,
                   seg_domega, r_exit, h_prop_rows, status, t_event, rtol, atol, h_min, h_max,
                   h_kink, max_steps, stats, stop, a_tab, c_tab, times, d_tab, m_tab, e_tab,
                   gamma, order, counters):
    """
    Advance one island through the segments with the method (a_tab ... order).

    y (N, 9) every coupled piece's state; members (n,) this island's rows in y, products,
    h_prop_rows, status, t_event and stats (as in :func:`.integrator.advance_batch`);
    lpairs (m, 2) its pairs as local indices, with their histories hist (m, 3) (a view).

    Every step is a common step of the island, sized by its error. Pieces and pairs whose
    own error fails where the rest of the island passes (a sticking piece in its
    self-excited oscillation, a piece breaking free, two pieces colliding) are refined:
    each connected part of them is advanced alone over that step by its own adaptive steps
    (a piece alone by its own integrator, :func:`.integrator.advance_particle`), its pair
    loads from the rest of the island linear from the step's start to its end (Savcenco's
    multirate Rosenbrock). The step is taken only when the refined parts change the loads
    at its end by less than the tolerance for every piece; else it is tried again shorter,
    as when too many pieces would be refined. So a piece much faster than its island does
    not set its pace. Pieces that exit leave at their time (the step is sized to reach it);
    a failure of a common step fails the whole island, whose pieces keep their last
    accepted state; a refined piece that fails alone fails alone. Counts into counters
    (:data:`ISLAND_COUNTERS`). Returns the proposed next common step (s); each piece's own
    next step goes to h_prop_rows.
    """
    n = members.shape[0]
    m = lpairs.shape[0]
    s = times.shape[0]
    y0 = np.empty((n, STATE_SIZE))
    h_own = np.empty(n)
    h_prop = np.inf
    for p in range(n):
        y0[p] = y[members[p]]
        h_own[p] = h_prop_rows[members[p]]
        h_prop = min(h_prop, h_own[p])
    hist0 = hist.copy()
    active = np.ones(n, dtype=np.bool_)
    none = np.zeros(n, dtype=np.bool_)
    zero_load = np.zeros((n, 3))
    f0 = np.empty((n, STATE_SIZE))
    fh0 = np.empty((m, 3))
    ft = np.empty((n, STATE_SIZE))
    ft1 = np.empty(STATE_SIZE)
    jac = np.empty((n, STATE_SIZE, STATE_SIZE))
    lu = np.empty((n, 3, 3, 3))
    piv = np.empty((n, 2, 3), dtype=np.int64)
    u = np.empty((s, n, STATE_SIZE))
    uh = np.empty((s, m, 3))
    ys = np.empty((n, STATE_SIZE))
    hs = np.empty((m, 3))
    fs = np.empty((n, STATE_SIZE))
    fhs = np.empty((m, 3))
    y1 = np.empty((n, STATE_SIZE))
    h1 = np.empty((m, 3))
    err = np.empty((n, STATE_SIZE))
    errh = np.empty((m, 3))
    e_mem = np.empty(n)
    e_pair = np.empty(m)
    fast = np.zeros(n, dtype=np.bool_)
    slow = np.zeros(n, dtype=np.bool_)
    labels = np.empty(n, dtype=np.int64)
    sext0 = np.empty((n, 3))
    sext1 = np.empty((n, 3))
    sext_rate = np.empty((n, 3))
    f02 = np.empty((n, STATE_SIZE))
    fh02 = np.empty((m, 3))
    ft2 = np.empty((n, STATE_SIZE))
    y2 = np.empty((n, STATE_SIZE))
    h2 = np.empty((m, 3))
    err2 = np.empty((n, STATE_SIZE))
    errh2 = np.empty((m, 3))
    e_mem2 = np.empty(n)
    e_pair2 = np.empty(m)
    load1 = np.empty((n, 3))
    load2 = np.empty((n, 3))
    ext0 = np.empty((n, 3))
    ext1 = np.empty((n, 3))
    part_status = np.zeros(n, dtype=np.int64)
    part_t = np.zeros(n)
    part_first = np.full(n, -1, dtype=np.int64)
    one_t = np.empty(2)
    one_omega = np.empty(1)
    one_domega = np.empty(1)
    rate = np.empty(3)
    p_work = np.empty((2, STATE_SIZE, STATE_SIZE))
    p_piv = np.empty((2, 3), dtype=np.int64)
    p_k = np.empty((STATE_SIZE, STATE_SIZE))
    p_y1 = np.empty(STATE_SIZE)
    p_f0 = np.empty(STATE_SIZE)
    # the refined parts' scratch (a part is at most the island)
    big = max(n, m, STATE_SIZE)
    part_scratch = np.empty((6, n, STATE_SIZE))
    part_scratch3 = np.empty((6, big, 3))
    part_scratch_s = np.empty((s, n, STATE_SIZE))
    part_scratch_sh = np.empty((s, m, 3))
    part_jac = np.empty((n, STATE_SIZE, STATE_SIZE))
    part_lu = np.empty((n, 3, 3, 3))
    part_piv = np.empty((n, 2, 3), dtype=np.int64)
    part_e = np.empty((3, big))
    n_seg = seg_omega.shape[0]
    steps = 0
    accepted = 0
    rejected_count = 0
    t = seg_t[0]
    h_acc = 0.0
    err_acc = 1.0
    r2 = r_exit * r_exit
    outcome = ACTIVE
    reason = 0
    forced = -1  # the piece whose exit this step is sized to reach
    for seg in range(n_seg):
        if outcome != ACTIVE:
            break
        t_seg = seg_t[seg]
        t_end = seg_t[seg + 1]
        omega_s = seg_omega[seg]
        domega = seg_domega[seg]
        if seg > 0 and domega != seg_domega[seg - 1]:
            h_prop = min(h_prop, h_kink)
            for p in range(n):
                h_own[p] = min(h_own[p], h_kink)
        fresh = True
        rejected = False
        while t < t_end:
            if stop_requested(stop):
                outcome = STOPPED
                break
            remaining = t_end - t
            truncated = h_prop >= remaining
            h = remaining if truncated else h_prop
            omega0 = omega_s + domega * (t - t_seg)
            if fresh:
                prepare(y0, hist0, members, lpairs, active, products, inter, machine, omega0,
                        domega, zero_load, zero_load, f0, fh0, jac, ft, ft1)
                fresh = False
            ok = w_step(y0, hist0, f0, fh0, ft, h, omega0, domega, members, lpairs, active,
                        products, inter, machine, zero_load, zero_load, jac, lu, piv, u, uh,
                        ys, hs, fs, fhs, y1, h1, err, errh, a_tab, c_tab, times, d_tab, m_tab,
                        e_tab, gamma)
            steps += 1
            counters[IC_STEPS] += 1
            if steps > max_steps:
                outcome = FAILED
                reason = REASON_TOO_MANY_STEPS
                break
            e_all = np.inf
            e_slow = 0.0
            count = 0
            n_fast = 0
            if ok:
                step_errors(err, errh, y0, y1, h1, members, lpairs, active, products, inter,
                            rtol, atol, e_mem, e_pair)
                e_all = 0.0
                for p in range(n):
                    fast[p] = active[p] and e_mem[p] > 1.0
                    if active[p]:
                        count += 1
                        e_all = max(e_all, e_mem[p])
                for q in range(m):
                    e_all = max(e_all, e_pair[q])
                    if e_pair[q] > 1.0:
                        fast[lpairs[q, 0]] = True
                        fast[lpairs[q, 1]] = True
                for p in range(n):
                    if fast[p]:
                        n_fast += 1
                    elif active[p]:
                        e_slow = max(e_slow, e_mem[p])
            refined = False
            e_loads = 0.0
            if ok and e_all > 1.0 and n_fast <= REFINE_MAX_FRACTION * count:
                # each connected part of the fast pieces alone, its outside loads linear
                label_parts(fast, lpairs, labels)
                for p in range(n):
                    slow[p] = active[p] and not fast[p]
                pair_loads(y0, hist0, members, lpairs, active, fast, products, inter, ext0)
                pair_loads(y1, h1, members, lpairs, active, fast, products, inter, ext1)
                pair_loads(y0, hist0, members, lpairs, active, slow, products, inter, sext0)
                pair_loads(y1, h1, members, lpairs, active, slow, products, inter, sext1)
                pair_loads(y1, h1, members, lpairs, active, none, products, inter, load1)
                failed = False
                for root in range(n):
                    part_status[root] = ACTIVE
                    part_first[root] = -1
                    if not fast[root] or labels[root] != root:
                        continue
                    k = 0
                    for p in range(n):
                        k += labels[p] == root
                    if k == 1:  # a piece alone: its own integrator
                        one_t[0] = t
                        one_t[1] = t + h
                        one_omega[0] = omega0
                        one_domega[0] = domega
                        for a in range(3):
                            rate[a] = (ext1[root, a] - ext0[root, a]) / h
                        y1[root] = y0[root]
                        st, t_p, h_own[root] = advance_particle(
                            y1[root], products[members[root]], machine, one_t, one_omega,
                            one_domega, r_exit, h_own[root], rtol, atol, h_min, h_max, h_kink,
                            max_steps, stats[members[root]], p_work, p_piv, p_k, p_y1, p_f0,
                            ext0[root], rate, stop)
                        part_status[root] = st
                        part_t[root] = t_p
                        part_first[root] = root if st == EXITED else -1
                    else:  # pieces that touch: the part's own common steps
                        part = np.empty(k, dtype=np.int64)
                        local = np.full(n, -1, dtype=np.int64)
                        c = 0
                        for p in range(n):
                            if labels[p] == root:
                                part[c] = p
                                local[p] = c
                                c += 1
                        mk = 0
                        for q in range(m):
                            mk += local[lpairs[q, 0]] >= 0 and local[lpairs[q, 1]] >= 0
                        part_pairs = np.empty((mk, 2), dtype=np.int64)
                        part_rows = np.empty(mk, dtype=np.int64)
                        c = 0
                        for q in range(m):
                            if local[lpairs[q, 0]] >= 0 and local[lpairs[q, 1]] >= 0:
                                part_pairs[c, 0] = local[lpairs[q, 0]]
                                part_pairs[c, 1] = local[lpairs[q, 1]]
                                part_rows[c] = q
                                c += 1
                        py = np.empty((k, STATE_SIZE))
                        ph = np.empty((mk, 3))
                        pe0 = np.empty((k, 3))
                        pr = np.empty((k, 3))
                        for c in range(k):
                            py[c] = y0[part[c]]
                            for a in range(3):
                                pe0[c, a] = ext0[part[c], a]
                                pr[c, a] = (ext1[part[c], a] - ext0[part[c], a]) / h
                        for c in range(mk):
                            ph[c] = hist0[part_rows[c]]
                        h_part = np.inf
                        for c in range(k):
                            h_part = min(h_part, h_own[part[c]])
                        part_active = np.ones(k, dtype=np.bool_)
                        part_members = members[part]
                        own_row = members[root]
                        before_a = stats[own_row, STAT_ACCEPTED]
                        before_r = stats[own_row, STAT_REJECTED]
                        st, t_p, first_p, h_next = advance_part(
                            py, ph, part_members, part_pairs, part_active, products, inter,
                            machine, t, h, omega0, domega, pe0, pr, r_exit, min(h_part, h),
                            rtol, atol, h_min, h_max, max_steps, stats[members[root]], stop,
                            a_tab, c_tab, times, d_tab, m_tab, e_tab, gamma, order,
                            part_scratch, part_scratch3, part_scratch_s, part_scratch_sh,
                            part_jac, part_lu, part_piv, part_e)
                        for c in range(k):  # every piece of the part took its steps
                            y1[part[c]] = py[c]
                            h_own[part[c]] = h_next
                            if part[c] != root:
                                stats[members[part[c]], STAT_ACCEPTED] += (
                                    stats[own_row, STAT_ACCEPTED] - before_a)
                                stats[members[part[c]], STAT_REJECTED] += (
                                    stats[own_row, STAT_REJECTED] - before_r)
                        for c in range(mk):
                            h1[part_rows[c]] = ph[c]
                        part_status[root] = st
                        part_t[root] = t_p
                        part_first[root] = part[first_p] if st == EXITED else -1
                    if part_status[root] == STOPPED:
                        outcome = STOPPED
                    elif part_status[root] == FAILED:
                        failed = True
                if outcome == STOPPED:
                    break
                if failed:  # its pieces go (as a piece alone would); the step is retried
                    for root in range(n):
                        if fast[root] and labels[root] == root and part_status[root] == FAILED:
                            for p in range(n):
                                if labels[p] == root:
                                    active[p] = False
                                    status[members[p]] = FAILED
                                    t_event[members[p]] = t
                                    stats[members[p], STAT_REASON] = stats[members[root],
                                                                           STAT_REASON]
                                    y[members[p]] = y0[p]
                    fresh = True
                    continue
                # the rest of the island again, with the same loads from the refined parts
                # as they had (linear, equal and opposite: momentum is kept)
                for p in range(n):
                    for a in range(3):
                        sext_rate[p, a] = (sext1[p, a] - sext0[p, a]) / h
                prepare(y0, hist0, members, lpairs, slow, products, inter, machine, omega0,
                        domega, sext0, sext_rate, f02, fh02, jac, ft2, ft1)
                ok2 = w_step(y0, hist0, f02, fh02, ft2, h, omega0, domega, members, lpairs,
                             slow, products, inter, machine, sext0, sext_rate, jac, lu, piv, u,
                             uh, ys, hs, fs, fhs, y2, h2, err2, errh2, a_tab, c_tab, times,
                             d_tab, m_tab, e_tab, gamma)
                e_slow = np.inf
                if ok2:
                    step_errors(err2, errh2, y0, y2, h2, members, lpairs, slow, products, inter,
                                rtol, atol, e_mem2, e_pair2)
                    e_slow = 0.0
                    for p in range(n):
                        if slow[p]:
                            e_slow = max(e_slow, e_mem2[p])
                            y1[p] = y2[p]
                    for q in range(m):
                        if slow[lpairs[q, 0]] and slow[lpairs[q, 1]]:
                            e_slow = max(e_slow, e_pair2[q])
                            h1[q] = h2[q]
                pair_loads(y1, h1, members, lpairs, active, none, products, inter, load2)
                e_loads = load_error(h, load1, load2, y1, active, rtol, atol)
                refined = max(e_slow, e_loads) <= 1.0
                if refined:
                    counters[IC_REFINED] += n_fast
                else:
                    e_all = max(e_slow, e_loads)
            if not refined and not (e_all <= 1.0):
                if not math.isfinite(e_all):
                    counters[IC_REJECT_FAILED] += 1
                elif n_fast > REFINE_MAX_FRACTION * count:
                    counters[IC_REJECT_CROWDED] += 1
                elif n_fast:
                    counters[IC_REJECT_LOADS] += 1
                else:
                    counters[IC_REJECT_ERROR] += 1
                rejected_count += 1
                forced = -1
                h_prop = proposal_after_rejection(h, e_all, rejected, order)
                rejected = True
                if h_prop < h_min:
                    outcome = FAILED
                    reason = (REASON_NOT_FINITE if not math.isfinite(e_all)
                              else REASON_STEP_UNDERFLOW)
                    break
                continue
            # the common step is sized for all but the fastest pieces
            e_step = max(e_loads, quantile_error(e_mem, active, REFINED_FRACTION)) if (
                refined) else e_all
            # exits: the first piece to reach the rim sets where the step ends
            first = -1
            theta = 2.0
            for p in range(n):
                if not active[p]:
                    continue
                th = 2.0
                if refined and fast[p]:
                    root = labels[p]
                    if part_first[root] == p:
                        th = (part_t[root] - t) / h
                elif y1[p, 0] * y1[p, 0] + y1[p, 1] * y1[p, 1] >= r2:
                    th = locate_exit(h, y0[p], y1[p], r_exit)
                if th < theta:
                    theta = th
                    first = p
            if first >= 0 and first != forced and theta < 1.0:
                forced = first  # again, to the exit: the others reach that time too
                h_prop = theta * h
                continue
            accepted += 1
            counters[IC_ACCEPTED] += 1
            y0[:] = y1
            hist0[:] = h1
            if first >= 0:  # this step reached a piece's exit
                active[first] = False
                status[members[first]] = EXITED
                t_event[members[first]] = t + h
                y[members[first]] = y0[first]
            settle(y0, hist0, members, lpairs, active, products, inter)
            fresh = True
            forced = -1
            if first >= 0:
                t = t + h
                rejected = False
                left = 0
                for p in range(n):
                    left += active[p]
                if left == 0:
                    break
                continue
            t, h_prop, h_acc, err_acc = after_acceptance(t, t_end, h, h_prop, h_max, e_step,
                                                         h_acc, err_acc, rejected,
                                                         truncated, order)
            rejected = False
        if outcome != ACTIVE:
            break
    for p in range(n):
        row = members[p]
        stats[row, STAT_ACCEPTED] += accepted
        stats[row, STAT_REJECTED] += rejected_count
        h_prop_rows[row] = h_prop  # the common step: a refined piece starts from it again
        if not active[p]:
            continue  # exited or failed alone: its state and time are set
        y[row] = y0[p]
        if outcome == FAILED:
            status[row] = FAILED
            t_event[row] = t
            stats[row, STAT_REASON] = reason
        elif outcome == STOPPED:
            status[row] = STOPPED
            t_event[row] = t
    hist[:] = hist0
    return h_prop


@pjit
def advance_islands(y, hist, members, member_start, lpairs, pair_start, products, inter,
                    machine, seg_t, seg_omega, seg_domega, r_exit, h_prop, status, t_event,
                    rtol, atol, h_min, h_max, h_kink, max_steps, stats, stop, a_tab, c_tab,
                    times, d_tab, m_tab, e_tab, gamma, order, counters):
    """
    Advance every island over seg_t[0]..seg_t[-1], islands in parallel on numba's threads.

    y (N, 9) the coupled pieces' states, products (N, W); island k's pieces are rows
    members[member_start[k]:member_start[k + 1]], its pairs lpairs[pair_start[k]:
    pair_start[k + 1]] (local indices into its members) with histories hist (M, 3) in
    the same rows. h_prop (N,) proposed steps (an island starts from its members'
    smallest; each member gets its own next), status, t_event (N,), stats (N, STAT_WIDTH):
    as in :func:`.integrator.advance_batch`; all updated in place. The method:
    :class:`Method`'s arrays. counters (K, ISLAND_COUNTERS) int64: each island's
    (:data:`ISLAND_COUNTERS`). An island's result depends on nothing but its own data.
    """
    count = member_start.shape[0] - 1
    for k in numba.prange(count):
        rows = members[member_start[k]:member_start[k + 1]]
        pairs_k = lpairs[pair_start[k]:pair_start[k + 1]]
        hist_k = hist[pair_start[k]:pair_start[k + 1]]
        advance_island(y, hist_k, rows, pairs_k, products, inter, machine, seg_t, seg_omega,
                       seg_domega, r_exit, h_prop, status, t_event, rtol, atol, h_min, h_max,
                       h_kink, max_steps, stats, stop, a_tab, c_tab, times, d_tab, m_tab,
                       e_tab, gamma, order, counters[k])
