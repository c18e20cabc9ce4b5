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
use each piece's own Jacobian block only (exact, :func:`.model.jacobian`, reduced to 3x3
solves by :func:`.rosenbrock.factor_mechanical`); the histories' block is left out (their
rates are not stiff). So a stage costs what the pieces alone cost, plus the pairs.

Why this works: what is stiff is each piece's own friction (the regularised Coulomb slope,
the filter), which its block holds exactly; the soft contact of raw meat is not stiff at
the steps the pieces take (two default pieces pressed 2 mm: about 63 rad/s, 100 ms a
period). A method whose order does not depend on the Jacobian is needed for that: a W-method,
:data:`ROS34PW2` (Rang & Angermann 2005, as PETSc's TSROSWRA34PW2: 4 stages, order 3,
L-stable, stiffly accurate, embedded order 2). RODAS4 with the same block Jacobian loses
its order on the pair terms (``benchmarks/island_order.py`` measures both).

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
from .exact import history_rate
from .integrator import (
    ACTIVE, after_acceptance, error_norm, EXITED, FAILED, locate_exit,
    proposal_after_rejection, REASON_NOT_FINITE, REASON_STEP_UNDERFLOW, REASON_TOO_MANY_STEPS,
    STAT_ACCEPTED, STAT_REASON, STAT_REJECTED, STOPPED)
from .model import jacobian, rhs, rhs_omega_derivative, STATE_SIZE
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
                 out, hout):
    """
    Write the island's field: pieces' (n, 9) into out, histories' (m, 3) into hout.

    ys (n, 9), hs (m, 3) the states; members (n,) the pieces' rows in products; lpairs
    (m, 2) the pairs as local indices; active (n,) pieces still on the cone (the others get
    a zero field, their pairs none).
    """
    n = ys.shape[0]
    for p in range(n):
        if active[p]:
            rhs(ys[p], products[members[p]], machine, omega, domega, out[p])
        else:
            out[p, :] = 0.0
    for q in range(lpairs.shape[0]):
        i = lpairs[q, 0]
        j = lpairs[q, 1]
        if not (active[i] and active[j]):
            continue
        pi = products[members[i]]
        pj = products[members[j]]
        f = force_between(ys[i], ys[j], hs[q, 0], hs[q, 1], hs[q, 2], pi, pj, inter)
        inv_i = 1.0 / pi[P_M]
        inv_j = 1.0 / pj[P_M]
        for a in range(3):
            out[i, 3 + a] += f[a] * inv_i
            out[j, 3 + a] -= f[a] * inv_j
    for q in range(lpairs.shape[0]):
        i = lpairs[q, 0]
        j = lpairs[q, 1]
        if not (active[i] and active[j]):
            hout[q, 0] = hout[q, 1] = hout[q, 2] = 0.0
            continue
        r = history_rate(ys[i, 0] - ys[j, 0], ys[i, 1] - ys[j, 1], ys[i, 2] - ys[j, 2],
                         ys[i, 3] - ys[j, 3], ys[i, 4] - ys[j, 4], ys[i, 5] - ys[j, 5],
                         out[i, 3] - out[j, 3], out[i, 4] - out[j, 4], out[i, 5] - out[j, 5],
                         hs[q, 0], hs[q, 1], hs[q, 2], products[members[i]],
                         products[members[j]], inter)
        hout[q, 0] = r[0]
        hout[q, 1] = r[1]
        hout[q, 2] = r[2]


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
def island_error(err, errh, y0, y1, h0, h1, active, rtol, atol):
    """Return the largest scaled RMS error of an active piece (9) or a history (3)."""
    worst = 0.0
    for p in range(y0.shape[0]):
        if active[p]:
            worst = max(worst, error_norm(err[p], y0[p], y1[p], rtol, atol))
    for q in range(h0.shape[0]):
        worst = max(worst, error_norm(errh[q], h0[q], h1[q], rtol, atol))
    return worst


@jit
def w_step(y0, hist0, f0, fh0, ft, h, omega0, domega, members, lpairs, active, products,
           inter, machine, jac, lu, piv, u, uh, ys, hs, fs, fhs, y1, h1, err, errh,
           a_tab, c_tab, times, d_tab, m_tab, e_tab, gamma):
    """
    Take one step of size h of the method (a_tab ... gamma) from (y0, hist0).

    f0, fh0 the field at the start and ft (n, 9) its time derivative; jac (n, 9, 9) each
    piece's own Jacobian; lu (n, 3, 3, 3) and piv (n, 2, 3) scratch for its factors; u
    (s, n, 9) and uh (s, m, 3) the stages. Writes the result into y1, h1 and the error
    estimate into err, errh. Returns False if a piece's system cannot be factored.
    """
    n = y0.shape[0]
    m = hist0.shape[0]
    s = times.shape[0]
    alpha = 1.0 / (gamma * h)
    inv_h = 1.0 / h
    for p in range(n):
        if active[p] and not factor_mechanical(jac[p], alpha, lu[p, 0], lu[p, 1], lu[p, 2],
                                               piv[p, 0], piv[p, 1]):
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
                         omega0 + domega * times[i] * h, domega, fs, fhs)
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
            solve_mechanical(jac[p], alpha, lu[p, 0], lu[p, 1], piv[p, 0], piv[p, 1], u[i], p)
        for q in range(m):
            for a in range(3):
                acc = fhs[q, a]
                for j in range(i):
                    acc += c_tab[i, j] * inv_h * uh[j, q, a]
                uh[i, q, a] = acc / alpha
    for p in range(n):
        for a in range(STATE_SIZE):
            acc = y0[p, a]
            e = 0.0
            for i in range(s):
                acc += m_tab[i] * u[i, p, a]
                e += e_tab[i] * u[i, p, a]
            y1[p, a] = acc
            err[p, a] = e
    for q in range(m):
        for a in range(3):
            acc = hist0[q, a]
            e = 0.0
            for i in range(s):
                acc += m_tab[i] * uh[i, q, a]
                e += e_tab[i] * uh[i, q, a]
            h1[q, a] = acc
            errh[q, a] = e
    for p in range(n):
        if active[p]:
            for a in range(STATE_SIZE):
                if not math.isfinite(y1[p, a]):
                    return False
    return True


@jit
def advance_island(y, hist, members, lpairs, products, inter, machine, seg_t, seg_omega,
                   seg_domega, r_exit, h_start, status, t_event, rtol, atol, h_min, h_max,
                   h_kink, max_steps, stats, stop, a_tab, c_tab, times, d_tab, m_tab, e_tab,
                   gamma, order):
    """
    Advance one island through the segments with the method (a_tab ... order).

    y (N, 9) every coupled piece's state, hist (M, 3) every pair's history (rows members
    (n,) and the island's pair rows are its own); lpairs (m, 2) its pairs as local
    indices, with their histories in hist (m, 3) (a view of the island's rows); status,
    t_event (N,) and stats (N, STAT_WIDTH) as in :func:`.integrator.advance_batch`, of the
    members' rows; h_start (s) the first trial step. Pieces that exit leave at their time;
    a failure (step underflow, too many steps, a non-finite state) fails the whole island,
    the others keep their last accepted state. Returns the proposed next step (s).
    """
    n = members.shape[0]
    m = lpairs.shape[0]
    s = times.shape[0]
    y0 = np.empty((n, STATE_SIZE))
    for p in range(n):
        y0[p] = y[members[p]]
    hist0 = hist.copy()
    active = np.ones(n, dtype=np.bool_)
    f0 = np.empty((n, STATE_SIZE))
    fh0 = np.empty((m, 3))
    ft = np.empty((n, STATE_SIZE))
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
    ft1 = np.empty(STATE_SIZE)
    n_seg = seg_omega.shape[0]
    steps = 0
    accepted = 0
    rejected_count = 0
    t = seg_t[0]
    h_prop = h_start
    h_acc = 0.0
    err_acc = 1.0
    r2 = r_exit * r_exit
    outcome = ACTIVE
    reason = 0
    for seg in range(n_seg):
        if outcome != ACTIVE:
            break
        t_seg = seg_t[seg]
        t_end = seg_t[seg + 1]
        omega_s = seg_omega[seg]
        domega = seg_domega[seg]
        if seg > 0 and domega != seg_domega[seg - 1]:
            h_prop = min(h_prop, h_kink)
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
                island_field(y0, hist0, members, lpairs, active, products, inter, machine,
                             omega0, domega, f0, fh0)
                for p in range(n):
                    if active[p]:
                        jacobian(y0[p], products[members[p]], machine, omega0, domega,
                                 jac[p])
                        rhs_omega_derivative(y0[p], omega0, ft1)
                        for a in range(STATE_SIZE):
                            ft[p, a] = domega * ft1[a]
                    else:
                        ft[p, :] = 0.0
                fresh = False
            ok = w_step(y0, hist0, f0, fh0, ft, h, omega0, domega, members, lpairs, active,
                        products, inter, machine, jac, lu, piv, u, uh, ys, hs, fs, fhs, y1,
                        h1, err, errh, a_tab, c_tab, times, d_tab, m_tab, e_tab, gamma)
            e_norm = island_error(err, errh, y0, y1, hist0, h1, active, rtol,
                                  atol) if ok else np.inf
            steps += 1
            if steps > max_steps:
                outcome = FAILED
                reason = REASON_TOO_MANY_STEPS
                break
            if not (e_norm <= 1.0):
                rejected_count += 1
                h_prop = proposal_after_rejection(h, e_norm, rejected, order)
                rejected = True
                if h_prop < h_min:
                    outcome = FAILED
                    reason = (REASON_NOT_FINITE if not math.isfinite(e_norm)
                              else REASON_STEP_UNDERFLOW)
                    break
                continue
            accepted += 1
            first = -1
            theta = 2.0
            for p in range(n):
                if active[p] and y1[p, 0] * y1[p, 0] + y1[p, 1] * y1[p, 1] >= r2:
                    th = locate_exit(h, y0[p], y1[p], r_exit)
                    if th < theta:
                        theta = th
                        first = p
            if first >= 0:
                h_exit = theta * h
                ok = w_step(y0, hist0, f0, fh0, ft, h_exit, omega0, domega, members, lpairs,
                            active, products, inter, machine, jac, lu, piv, u, uh, ys, hs,
                            fs, fhs, y1, h1, err, errh, a_tab, c_tab, times, d_tab, m_tab,
                            e_tab, gamma)
                if not ok:
                    outcome = FAILED
                    reason = REASON_NOT_FINITE
                    break
                y0[:] = y1
                hist0[:] = h1
                active[first] = False
                status[members[first]] = EXITED
                t_event[members[first]] = t + h_exit
                settle(y0, hist0, members, lpairs, active, products, inter)
                y[members[first]] = y0[first]
                t = t + h_exit
                fresh = True
                rejected = False
                remaining_active = 0
                for p in range(n):
                    remaining_active += active[p]
                if remaining_active == 0:
                    break
                continue
            y0[:] = y1
            hist0[:] = h1
            settle(y0, hist0, members, lpairs, active, products, inter)
            fresh = True
            t, h_prop, h_acc, err_acc = after_acceptance(t, t_end, h, h_prop, h_max, e_norm,
                                                         h_acc, err_acc, rejected,
                                                         truncated, order)
            rejected = False
        if outcome != ACTIVE:
            break
    for p in range(n):
        row = members[p]
        stats[row, STAT_ACCEPTED] += accepted
        stats[row, STAT_REJECTED] += rejected_count
        if not active[p]:
            continue  # exited: its state and time are set
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
                    times, d_tab, m_tab, e_tab, gamma, order):
    """
    Advance every island over seg_t[0]..seg_t[-1], islands in parallel on numba's threads.

    y (N, 9) the coupled pieces' states, products (N, W); island k's pieces are rows
    members[member_start[k]:member_start[k + 1]], its pairs lpairs[pair_start[k]:
    pair_start[k + 1]] (local indices into its members) with histories hist (M, 3) in
    the same rows. h_prop (N,) proposed steps (an island starts from its members'
    smallest and gives them its next), status, t_event (N,), stats (N, STAT_WIDTH): as in
    :func:`.integrator.advance_batch`; all updated in place. The method: :class:`Method`'s
    arrays. An island's result depends on nothing but its own data.
    """
    count = member_start.shape[0] - 1
    for k in numba.prange(count):
        rows = members[member_start[k]:member_start[k + 1]]
        h_start = np.inf
        for r in rows:
            h_start = min(h_start, h_prop[r])
        pairs_k = lpairs[pair_start[k]:pair_start[k + 1]]
        hist_k = hist[pair_start[k]:pair_start[k + 1]]
        h_next = advance_island(y, hist_k, rows, pairs_k, products, inter, machine, seg_t,
                                seg_omega, seg_domega, r_exit, h_start, status, t_event,
                                rtol, atol, h_min, h_max, h_kink, max_steps, stats, stop,
                                a_tab, c_tab, times, d_tab, m_tab, e_tab, gamma, order)
        for r in rows:
            h_prop[r] = h_next
