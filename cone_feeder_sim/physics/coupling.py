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
Multirate coupling of pieces that touch: each piece at its own pace (compiled).

The pair forces are slow in position and stiff in velocity; each piece's own friction is
what sets its step size. So the pieces are coupled over coupling intervals of length H,
much longer than their own steps, by an operator split (doc/model.md, "Multirate
coupling"):

1. **Predict, implicitly.** One linearly implicit Euler step of the whole coupled system
   over H, (I/H - J) k = f, with J every piece's own exact Jacobian plus the pair blocks
   (central differences, equal and opposite). It is solved through the velocities
   (3 n unknowns, one 3x3 block per piece and one per pair) by BiCGSTAB with a block-Jacobi
   preconditioner: O(n) per iteration, whatever the crowd's size or shape.
2. **The pair forces over the interval** are each pair's force at the predicted end,
   linearised: F_q = F_q(y) + G_q (k_i - k_j). This is backward Euler for the pair terms, so
   the stiff relative velocities are damped, not rung. Each piece gets the sum of its pairs'
   forces as a load: it ramps from its last value over the first RAMP of the interval to a
   plateau chosen so that the impulse is F_q H (a jump would ring the piece). The two
   pieces of a pair get exactly opposite loads.
3. **Each piece alone.** Every piece is integrated over the interval with the load by the
   per-piece kernel (:func:`integrator.advance_particle`): its own RODAS4 steps, step
   control, kinks and exit location, as when it is alone. The pieces run in parallel.
4. **Error control.** The load stands for the impulse of a pair force that changes over the
   interval. The raw estimate of the impulse error per piece, as a velocity (m/s), is the
   difference between the load and the trapezoidal rule on the pair forces at the start
   and the end, H/m sum (F_used - (F(y0) + F(y1))/2) over its pairs, with y1 the states
   the pieces reached. As in stiff integrators (Shampine), it is filtered through
   (I - H J)^-1 of the coupled system, the prediction's own matrix: in the stiff directions,
   where the implicit prediction is right and the trapezoidal rule is not, the raw estimate
   is damped. The interval is accepted where the largest position part of the filtered
   error (m) is within the tolerance, and the next one is sized for the split's order 1
   (local error O(H^2)). A rejected interval is a result: every piece goes back to the
   interval's start and it is tried again shorter.

Momentum: a pair's two loads are equal and opposite at every instant, so the impulses they
give over an interval are equal and opposite whatever steps the two pieces take.
"""

import math

import numba
import numpy as np

from .contact import pair_force, pair_jacobian
from .integrator import ACTIVE, advance_particle, GROUPS, STAT_REASON
from .model import jacobian, rhs, STATE_SIZE
from .params import G_EPS, P_M
from .rosenbrock import eliminate_filter, factor3, solve3

__all__ = ['advance_coupled', 'COUPLING_STAT_WIDTH', 'CST_ACCEPTED', 'CST_FORCED',
           'CST_ITERATIONS', 'CST_REJECTED']

jit = numba.njit(cache=True, error_model='numpy', nogil=True)
pjit = numba.njit(cache=True, error_model='numpy', nogil=True, parallel=True)

#: Relative residual at which the velocity system of the prediction is solved.
SOLVE_RTOL = 1.0e-10
#: Most BiCGSTAB iterations; an unsolved system rejects the interval.
SOLVE_MAX_ITERATIONS = 400
#: Step control of the coupling intervals (the split is of order 1: local error O(H^2)).
SAFETY = 0.9
FAC_MIN = 0.2
FAC_MAX = 4.0
#: Intervals shorter than this (s) are accepted whatever their estimate (counted as forced).
H_FLOOR = 1.0e-7
#: Crowds of fewer pieces are advanced on one thread: starting a parallel region costs more
#: than it saves, and far more on a loaded machine (every interval starts one).
PARALLEL_PIECES = 16
#: The load ramps from its last value to the interval's plateau over this fraction of the
#: interval, so that no piece sees a jump of its load (a jump rings each piece's lightly
#: damped pre-sliding oscillation, which then costs it many steps).
RAMP = 0.5

# counters of one call (counters array, int64)
CST_ACCEPTED = 0   # coupling intervals accepted
CST_REJECTED = 1   # coupling intervals rejected (tried again shorter)
CST_FORCED = 2     # intervals accepted at H_FLOOR although their estimate was above tolerance
CST_ITERATIONS = 3  # BiCGSTAB iterations, all intervals
COUPLING_STAT_WIDTH = 4


@jit
def adjacency(n, pairs):
    """
    Return each piece's pairs in CSR form: start (n+1,), pair (2m,), other (2m,), sign (2m,).

    Piece p's entries are start[p] .. start[p+1]-1, in pair order; sign is +1 where p is the
    pair's first piece (the pair force acts on it) and -1 where it is the second.
    """
    m = pairs.shape[0]
    start = np.zeros(n + 1, dtype=np.int64)
    for q in range(m):
        start[pairs[q, 0] + 1] += 1
        start[pairs[q, 1] + 1] += 1
    for p in range(n):
        start[p + 1] += start[p]
    fill = start[:n].copy()
    pair = np.empty(2 * m, dtype=np.int64)
    other = np.empty(2 * m, dtype=np.int64)
    sign = np.empty(2 * m)
    for q in range(m):
        i = pairs[q, 0]
        j = pairs[q, 1]
        pair[fill[i]] = q
        other[fill[i]] = j
        sign[fill[i]] = 1.0
        fill[i] += 1
        pair[fill[j]] = q
        other[fill[j]] = i
        sign[fill[j]] = -1.0
        fill[j] += 1
    return start, pair, other, sign


@jit
def pair_forces(y, products, pairs, status, pull_off, eps, out):
    """Write each pair's force on its first piece (N, cone axes) into out (m, 3)."""
    for q in range(pairs.shape[0]):
        i = pairs[q, 0]
        j = pairs[q, 1]
        if status[i] != ACTIVE or status[j] != ACTIVE:
            out[q, 0] = out[q, 1] = out[q, 2] = 0.0
            continue
        f0, f1, f2 = pair_force(y[i, 0:3], y[i, 3:6], products[i], y[j, 0:3], y[j, 3:6],
                                products[j], pull_off, eps)
        out[q, 0] = f0
        out[q, 1] = f1
        out[q, 2] = f2


@jit
def pair_jacobians(y, products, pairs, status, pull_off, eps, out):
    """
    Write d(F)/d(x_i, w_i) of every pair q = (i, j) into out (m, 3, 6), central differences.

    d(F)/d(x_j, w_j) = -out[q] (:func:`contact.pair_jacobian`); inactive pairs get zeros.
    """
    sx = np.empty(3)
    sw = np.empty(3)
    for q in range(pairs.shape[0]):
        i = pairs[q, 0]
        j = pairs[q, 1]
        if status[i] != ACTIVE or status[j] != ACTIVE:
            for a in range(3):
                for c in range(6):
                    out[q, a, c] = 0.0
            continue
        pair_jacobian(y[i, 0:3], y[i, 3:6], products[i], y[j, 0:3], y[j, 3:6], products[j],
                      pull_off, eps, out[q], sx, sw)


@jit
def assemble(y, products, machine, omega, domega, alpha, status, start, pair, sign, forces,
             jac, own, f, s_lu, s_piv, t_mat, d_mat, d_lu, d_piv, u, rv):
    """
    Build the velocity system of the prediction, piece by piece (see :func:`predict`).

    own (n, 9, 9) every piece's Jacobian with its pairs' diagonal blocks; f (n, 9) the
    coupled field; s_lu, s_piv, t_mat the filter elimination (as :func:`islands.island_factor`);
    d_mat (n, 3, 3) the diagonal blocks of the velocity system, d_lu and d_piv their
    factors (the preconditioner);
    u (n, 3) and rv (n, 3) the eliminated filter part and the right-hand side, the latter
    without its pair terms (added by :func:`pair_rhs`). Inactive pieces get an identity row
    and a zero right-hand side.
    """
    n = y.shape[0]
    for p in range(n):
        if status[p] != ACTIVE:
            for a in range(3):
                for b in range(3):
                    d_mat[p, a, b] = d_lu[p, a, b] = 1.0 if a == b else 0.0
                    t_mat[p, a, b] = 0.0
                d_piv[p, a] = a
                u[p, a] = 0.0
                rv[p, a] = 0.0
            for a in range(STATE_SIZE):
                f[p, a] = 0.0
            continue
        blk = own[p]
        jacobian(y[p], products[p], machine, omega, domega, blk)
        rhs(y[p], products[p], machine, omega, domega, f[p])
        mp = products[p, P_M]
        for e in range(start[p], start[p + 1]):
            q = pair[e]
            for a in range(3):
                f[p, 3 + a] += sign[e] * forces[q, a] / mp
                for c in range(6):
                    blk[3 + a, c] += jac[q, a, c] / mp
        eliminate_filter(blk, alpha, s_lu[p], s_piv[p], t_mat[p], d_mat[p])
        d_lu[p] = d_mat[p]
        factor3(d_lu[p], d_piv[p])
        r0 = f[p, 6] + (blk[6, 0] * f[p, 0] + blk[6, 1] * f[p, 1] + blk[6, 2] * f[p, 2]) / alpha
        r1 = f[p, 7] + (blk[7, 0] * f[p, 0] + blk[7, 1] * f[p, 1] + blk[7, 2] * f[p, 2]) / alpha
        r2 = f[p, 8] + (blk[8, 0] * f[p, 0] + blk[8, 1] * f[p, 1] + blk[8, 2] * f[p, 2]) / alpha
        u0, u1, u2 = solve3(s_lu[p], s_piv[p], r0, r1, r2)
        u[p, 0] = u0
        u[p, 1] = u1
        u[p, 2] = u2
        for a in range(3):
            acc = f[p, 3 + a]
            for c in range(3):
                acc += blk[3 + a, 6 + c] * u[p, c] + blk[3 + a, c] * f[p, c] / alpha
            rv[p, a] = acc


@jit
def neighbour_sum(p, start, pair, other, blocks, v):
    """Return sum over piece p's pairs q (partner o) of blocks[q] (3, 3) @ v[o] (3,)."""
    s0 = s1 = s2 = 0.0
    for e in range(start[p], start[p + 1]):
        q = pair[e]
        o = other[e]
        s0 += blocks[q, 0, 0] * v[o, 0] + blocks[q, 0, 1] * v[o, 1] + blocks[q, 0, 2] * v[o, 2]
        s1 += blocks[q, 1, 0] * v[o, 0] + blocks[q, 1, 1] * v[o, 1] + blocks[q, 1, 2] * v[o, 2]
        s2 += blocks[q, 2, 0] * v[o, 0] + blocks[q, 2, 1] * v[o, 1] + blocks[q, 2, 2] * v[o, 2]
    return s0, s1, s2


@jit
def pair_rhs(products, alpha, status, start, pair, other, jac, f, rv):
    """Add the pair terms -G_x f_x(other) / (alpha m_p) to the right-hand side rv (n, 3)."""
    for p in range(rv.shape[0]):
        if status[p] != ACTIVE:
            continue
        s0, s1, s2 = neighbour_sum(p, start, pair, other, jac[:, :, 0:3], f[:, 0:3])
        scale = 1.0 / (alpha * products[p, P_M])
        rv[p, 0] -= s0 * scale
        rv[p, 1] -= s1 * scale
        rv[p, 2] -= s2 * scale


@jit
def off_blocks(jac, alpha, out):
    """Write G_x / alpha + G_w of every pair, the velocity system's pair block, into out."""
    for q in range(jac.shape[0]):
        for a in range(3):
            for b in range(3):
                out[q, a, b] = jac[q, a, b] / alpha + jac[q, a, 3 + b]


@jit
def matvec(products, status, start, pair, other, d_mat, off, v, out):
    """Write M v into out: M the velocity system, blocks d_mat and off / m_p."""
    for p in range(v.shape[0]):
        for a in range(3):
            out[p, a] = (d_mat[p, a, 0] * v[p, 0] + d_mat[p, a, 1] * v[p, 1]
                         + d_mat[p, a, 2] * v[p, 2])
        if status[p] != ACTIVE:
            continue
        s0, s1, s2 = neighbour_sum(p, start, pair, other, off, v)
        mp = products[p, P_M]
        out[p, 0] += s0 / mp
        out[p, 1] += s1 / mp
        out[p, 2] += s2 / mp


@jit
def precondition(d_lu, d_piv, v, out):
    """Write D^-1 v into out, D the factored diagonal blocks."""
    for p in range(v.shape[0]):
        o0, o1, o2 = solve3(d_lu[p], d_piv[p], v[p, 0], v[p, 1], v[p, 2])
        out[p, 0] = o0
        out[p, 1] = o1
        out[p, 2] = o2


@jit
def dot(a, b):
    """Return the sum of a * b over (n, 3) arrays, in a fixed order (thread-independent)."""
    acc = 0.0
    for p in range(a.shape[0]):
        acc += a[p, 0] * b[p, 0] + a[p, 1] * b[p, 1] + a[p, 2] * b[p, 2]
    return acc


@jit
def bicgstab(products, status, start, pair, other, d_mat, d_lu, d_piv, off, b, x, scratch):
    """
    Solve M x = b (n, 3) by BiCGSTAB with the block-Jacobi preconditioner; return iterations.

    x receives the solution; a negative return is the iteration count of a solve that did
    not reach SOLVE_RTOL (or broke down). scratch (7, n, 3).
    """
    r = scratch[0]
    r_hat = scratch[1]
    p_vec = scratch[2]
    v = scratch[3]
    p_hat = scratch[4]
    s_hat = scratch[5]
    t = scratch[6]
    precondition(d_lu, d_piv, b, x)
    matvec(products, status, start, pair, other, d_mat, off, x, t)
    n = b.shape[0]
    for p in range(n):
        for a in range(3):
            r[p, a] = b[p, a] - t[p, a]
            r_hat[p, a] = r[p, a]
            p_vec[p, a] = 0.0
            v[p, a] = 0.0
    b_norm = math.sqrt(dot(b, b))
    if b_norm == 0.0:
        return 0
    goal = SOLVE_RTOL * b_norm
    if math.sqrt(dot(r, r)) <= goal:
        return 0
    rho = 1.0
    alpha = 1.0
    omega = 1.0
    for it in range(1, SOLVE_MAX_ITERATIONS + 1):
        rho_new = dot(r_hat, r)
        if rho_new == 0.0 or omega == 0.0:
            return -it
        beta = (rho_new / rho) * (alpha / omega)
        for p in range(n):
            for a in range(3):
                p_vec[p, a] = r[p, a] + beta * (p_vec[p, a] - omega * v[p, a])
        precondition(d_lu, d_piv, p_vec, p_hat)
        matvec(products, status, start, pair, other, d_mat, off, p_hat, v)
        denom = dot(r_hat, v)
        if denom == 0.0:
            return -it
        alpha = rho_new / denom
        for p in range(n):
            for a in range(3):
                r[p, a] -= alpha * v[p, a]   # r is now s
                x[p, a] += alpha * p_hat[p, a]
        if math.sqrt(dot(r, r)) <= goal:
            return it
        precondition(d_lu, d_piv, r, s_hat)
        matvec(products, status, start, pair, other, d_mat, off, s_hat, t)
        tt = dot(t, t)
        if tt == 0.0:
            return -it
        omega = dot(t, r) / tt
        for p in range(n):
            for a in range(3):
                x[p, a] += omega * s_hat[p, a]
                r[p, a] -= omega * t[p, a]
        if not math.isfinite(omega):
            return -it
        if math.sqrt(dot(r, r)) <= goal:
            return it
        rho = rho_new
    return -SOLVE_MAX_ITERATIONS


@jit
def segment_index(seg_t, t):
    """Return s with seg_t[s] <= t < seg_t[s + 1] (the last segment for t at the end)."""
    n_seg = seg_t.shape[0] - 1
    s = 0
    while s < n_seg - 1 and seg_t[s + 1] <= t:
        s += 1
    return s


@jit
def sub_segments(seg_t, seg_omega, seg_domega, ta, tb, out_t, out_omega, out_domega):
    """Write the segments of [ta, tb] into out_*; return their count."""
    n_seg = seg_omega.shape[0]
    s = segment_index(seg_t, ta)
    count = 0
    out_t[0] = ta
    while s < n_seg:
        lo = max(seg_t[s], ta)
        hi = min(seg_t[s + 1], tb)
        out_omega[count] = seg_omega[s] + seg_domega[s] * (lo - seg_t[s])
        out_domega[count] = seg_domega[s]
        out_t[count + 1] = hi
        count += 1
        if seg_t[s + 1] >= tb:
            break
        s += 1
    out_t[count] = tb
    return count


@jit
def advance_group(g, groups, y, products, machine, ramp_t, ramp_omega, ramp_domega, flat_t,
                  flat_omega, flat_domega, r_exit, h_prop, status, t_event, rtol, atol, h_min,
                  h_max, h_kink, max_steps, stats, ramp_load, ramp_rate, flat_load, kink):
    """
    Advance the ACTIVE pieces g, g + groups, ... over one interval: the ramp, then the plateau.

    ramp_* and flat_* are the sub-segments of the two parts; ramp_load (n, 3) (m/s^2) the
    load at the interval's start and ramp_rate (n, 3) (m/s^3) its rate over the ramp;
    flat_load (n, 3) the plateau. A piece that exits or fails in the ramp stops there.
    """
    n = STATE_SIZE
    count = y.shape[0]
    none = np.zeros(3)
    work = np.empty((2, n, n))
    piv = np.empty((2, 3), dtype=np.int64)
    k = np.empty((n, n))
    y1 = np.empty(n)
    f0 = np.empty(n)
    for p in range(g, count, groups):
        if status[p] != ACTIVE:
            continue
        hp = min(h_prop[p], h_kink) if kink else h_prop[p]
        st, t_ev, hp = advance_particle(y[p], products[p], machine, ramp_t, ramp_omega,
                                        ramp_domega, r_exit, hp, rtol, atol, h_min, h_max,
                                        h_kink, max_steps, stats[p], work, piv, k, y1, f0,
                                        ramp_load[p], ramp_rate[p])
        if st == ACTIVE:
            st, t_ev, hp = advance_particle(y[p], products[p], machine, flat_t, flat_omega,
                                            flat_domega, r_exit, hp, rtol, atol, h_min, h_max,
                                            h_kink, max_steps, stats[p], work, piv, k, y1, f0,
                                            flat_load[p], none)
        status[p] = st
        t_event[p] = t_ev
        h_prop[p] = hp


@pjit
def advance_pieces(y, products, machine, ramp_t, ramp_omega, ramp_domega, flat_t, flat_omega,
                   flat_domega, r_exit, h_prop, status, t_event, rtol, atol, h_min, h_max,
                   h_kink, max_steps, stats, ramp_load, ramp_rate, flat_load, kink):
    """
    Advance every ACTIVE piece over one interval on numba's threads (:func:`advance_group`).

    The only parallel region of an interval: pieces are independent inside it, so the result
    does not depend on the thread count.
    """
    groups = min(y.shape[0], GROUPS)
    for g in numba.prange(groups):
        advance_group(g, groups, y, products, machine, ramp_t, ramp_omega, ramp_domega, flat_t,
                      flat_omega, flat_domega, r_exit, h_prop, status, t_event, rtol, atol,
                      h_min, h_max, h_kink, max_steps, stats, ramp_load, ramp_rate, flat_load,
                      kink)


@jit
def shapes(used, begin, ramp, plateau):
    """
    Write each pair's plateau: the load that ramps from begin over ramp of the interval.

    The pair's impulse over the interval is that of ``used`` (m, 3) held over all of it:
    ramp (fraction of the interval) from begin (m, 3) to the plateau, then the plateau,
    so plateau = (used - ramp begin / 2) / (1 - ramp / 2).
    """
    for q in range(used.shape[0]):
        for a in range(3):
            plateau[q, a] = (used[q, a] - 0.5 * ramp * begin[q, a]) / (1.0 - 0.5 * ramp)


@jit
def piece_loads(products, start, pair, sign, begin, plateau, ramp_time, ramp_load, ramp_rate,
                flat_load):
    """Sum each piece's pair loads (m/s^2): at the start, their rate in the ramp, plateau."""
    for p in range(ramp_load.shape[0]):
        mp = products[p, P_M]
        for a in range(3):
            b0 = 0.0
            b1 = 0.0
            for e in range(start[p], start[p + 1]):
                b0 += sign[e] * begin[pair[e], a]
                b1 += sign[e] * plateau[pair[e], a]
            ramp_load[p, a] = b0 / mp
            flat_load[p, a] = b1 / mp
            ramp_rate[p, a] = (b1 - b0) / (mp * ramp_time)


@jit
def loads_from(y_pred_delta, status, pairs, forces, jac, used):
    """
    Write each pair's force at the predicted end into used (m, 3).

    used_q = F_q + G_q (k_i - k_j) over positions and velocities (k the prediction, (n, 9)).
    """
    for q in range(pairs.shape[0]):
        i = pairs[q, 0]
        j = pairs[q, 1]
        for a in range(3):
            acc = forces[q, a]
            if status[i] == ACTIVE and status[j] == ACTIVE:
                for c in range(6):
                    acc += jac[q, a, c] * (y_pred_delta[i, c] - y_pred_delta[j, c])
            used[q, a] = acc


@jit
def raw_error(products, status, start, pair, other, sign, used, f_start, f_end, h, alpha, out):
    """
    Write alpha times each piece's raw impulse error (m/s), alpha H/m sum (F_used - F_avg).

    F_avg = (F(y0) + F(y1)) / 2 over the piece's pairs, out (n, 3). A pair whose other piece
    left the cone (or failed) inside the interval is not counted: its force ended with it.
    Pieces no longer ACTIVE get zeros.
    """
    for p in range(status.shape[0]):
        out[p, 0] = out[p, 1] = out[p, 2] = 0.0
        if status[p] != ACTIVE:
            continue
        scale = alpha * h / products[p, P_M]
        for e in range(start[p], start[p + 1]):
            if status[other[e]] != ACTIVE:
                continue
            q = pair[e]
            s = sign[e] * scale
            for a in range(3):
                out[p, a] += s * (used[q, a] - 0.5 * (f_start[q, a] + f_end[q, a]))


@jit
def largest_norm(v):
    """Return the largest Euclidean norm of the rows of v (n, 3); inf if any is not finite."""
    worst = 0.0
    for p in range(v.shape[0]):
        norm = math.sqrt(v[p, 0] * v[p, 0] + v[p, 1] * v[p, 1] + v[p, 2] * v[p, 2])
        if not math.isfinite(norm):
            return np.inf
        worst = max(worst, norm)
    return worst


@jit
def advance_serially(y, products, machine, ramp_t, ramp_omega, ramp_domega, flat_t, flat_omega,
                     flat_domega, r_exit, h_prop, status, t_event, rtol, atol, h_min, h_max,
                     h_kink, max_steps, stats, ramp_load, ramp_rate, flat_load, kink):
    """Advance every ACTIVE piece over one interval on this thread (a small crowd)."""
    advance_group(0, 1, y, products, machine, ramp_t, ramp_omega, ramp_domega, flat_t,
                  flat_omega, flat_domega, r_exit, h_prop, status, t_event, rtol, atol, h_min,
                  h_max, h_kink, max_steps, stats, ramp_load, ramp_rate, flat_load, kink)


@jit
def advance_coupled(y, products, pairs, machine, seg_t, seg_omega, seg_domega, r_exit, h_prop,
                    status, t_event, rtol, atol, h_min, h_max, h_kink, max_steps, stats,
                    pull_off, h_coupling, tolerance, counters):
    """
    Advance pieces that touch over seg_t[0]..seg_t[-1] by multirate coupling; return H.

    y (n, 9) cone-axes states, products (n, W), pairs (m, 2) int64 local indices i < j;
    h_prop (n,), status (n,), t_event (n,), stats (n, STAT_WIDTH) as in
    :func:`integrator.advance_batch`, updated in place; h_coupling (s) the proposed first
    coupling interval; tolerance (m) the largest position error one interval may give a
    piece (the filtered estimate's position part);
    counters (COUPLING_STAT_WIDTH,) int64. Pieces that exit or fail inside an interval
    leave the coupling at their time, their pairs with them. Returns the proposed next
    coupling interval (s).
    """
    n = y.shape[0]
    m = pairs.shape[0]
    start, pair, other, sign = adjacency(n, pairs)
    eps = machine[G_EPS]
    forces = np.empty((m, 3))
    f_end = np.empty((m, 3))
    used = np.empty((m, 3))
    jac = np.empty((m, 3, 6))
    off = np.empty((m, 3, 3))
    own = np.empty((n, STATE_SIZE, STATE_SIZE))
    field = np.empty((n, STATE_SIZE))
    s_lu = np.empty((n, 3, 3))
    s_piv = np.empty((n, 3), dtype=np.int64)
    t_mat = np.empty((n, 3, 3))
    d_mat = np.empty((n, 3, 3))
    d_lu = np.empty((n, 3, 3))
    d_piv = np.empty((n, 3), dtype=np.int64)
    u = np.empty((n, 3))
    rv = np.empty((n, 3))
    kw = np.empty((n, 3))
    delta = np.empty((n, STATE_SIZE))
    begin = np.empty((m, 3))
    plateau = np.empty((m, 3))
    ramp_load = np.empty((n, 3))
    ramp_rate = np.empty((n, 3))
    flat_load = np.empty((n, 3))
    scratch = np.empty((7, n, 3))
    y_save = np.empty_like(y)
    h_save = np.empty_like(h_prop)
    status_save = np.empty_like(status)
    event_save = np.empty_like(t_event)
    reason_save = np.empty(n, dtype=np.int64)
    n_seg = seg_omega.shape[0]
    sub_t = np.empty(n_seg + 1)
    sub_omega = np.empty(n_seg)
    sub_domega = np.empty(n_seg)
    sub2_t = np.empty(n_seg + 1)
    sub2_omega = np.empty(n_seg)
    sub2_domega = np.empty(n_seg)
    t = seg_t[0]
    t1 = seg_t[n_seg]
    h = h_coupling
    pair_forces(y, products, pairs, status, pull_off, eps, forces)
    begin[:] = forces  # the loads start from the pair forces, and stay continuous
    rejected = False
    while t < t1:
        remaining = t1 - t
        truncated = h >= remaining
        hc = remaining if truncated else h
        s = segment_index(seg_t, t)
        omega = seg_omega[s] + seg_domega[s] * (t - seg_t[s])
        kink = s > 0 and t == seg_t[s] and seg_domega[s] != seg_domega[s - 1]
        alpha = 1.0 / hc
        # 1. the prediction: one linearly implicit Euler step of the coupled system
        pair_jacobians(y, products, pairs, status, pull_off, eps, jac)
        assemble(y, products, machine, omega, seg_domega[s], alpha, status, start, pair, sign,
                 forces, jac, own, field, s_lu, s_piv, t_mat, d_mat, d_lu, d_piv, u, rv)
        pair_rhs(products, alpha, status, start, pair, other, jac, field, rv)
        off_blocks(jac, alpha, off)
        its = bicgstab(products, status, start, pair, other, d_mat, d_lu, d_piv, off, rv, kw,
                       scratch)
        counters[CST_ITERATIONS] += abs(its)
        if its < 0:
            counters[CST_REJECTED] += 1
            h = hc * FAC_MIN
            rejected = True
            if h < H_FLOOR:
                h = H_FLOOR
            continue
        for p in range(n):
            for a in range(3):
                delta[p, a] = (field[p, a] + kw[p, a]) / alpha
                delta[p, 3 + a] = kw[p, a]
        # 2. the pair forces at the predicted end, each piece's load
        loads_from(delta, status, pairs, forces, jac, used)
        ramp_time = RAMP * hc
        shapes(used, begin, RAMP, plateau)
        piece_loads(products, start, pair, sign, begin, plateau, ramp_time, ramp_load,
                    ramp_rate, flat_load)
        # 3. every piece alone, with its load
        y_save[:] = y
        h_save[:] = h_prop
        status_save[:] = status
        event_save[:] = t_event
        for p in range(n):
            reason_save[p] = stats[p, STAT_REASON]
        t_mid = t + ramp_time
        t_end = t1 if truncated else t + hc
        c0 = sub_segments(seg_t, seg_omega, seg_domega, t, t_mid, sub_t, sub_omega, sub_domega)
        c1 = sub_segments(seg_t, seg_omega, seg_domega, t_mid, t_end, sub2_t, sub2_omega,
                          sub2_domega)
        if n >= PARALLEL_PIECES:
            advance_pieces(y, products, machine, sub_t[:c0 + 1], sub_omega[:c0],
                           sub_domega[:c0], sub2_t[:c1 + 1], sub2_omega[:c1],
                           sub2_domega[:c1], r_exit, h_prop, status, t_event, rtol, atol,
                           h_min, h_max, h_kink, max_steps, stats, ramp_load, ramp_rate,
                           flat_load, kink)
        else:
            advance_serially(y, products, machine, sub_t[:c0 + 1], sub_omega[:c0],
                             sub_domega[:c0], sub2_t[:c1 + 1], sub2_omega[:c1],
                             sub2_domega[:c1], r_exit, h_prop, status, t_event, rtol, atol,
                             h_min, h_max, h_kink, max_steps, stats, ramp_load, ramp_rate,
                             flat_load, kink)
        # 4. the error of the interval's impulses
        pair_forces(y, products, pairs, status, pull_off, eps, f_end)
        raw_error(products, status, start, pair, other, sign, used, forces, f_end, hc, alpha,
                  rv)
        its = bicgstab(products, status, start, pair, other, d_mat, d_lu, d_piv, off, rv,
                       kw, scratch)
        counters[CST_ITERATIONS] += abs(its)
        err = hc * largest_norm(kw) if its >= 0 else np.inf  # its position part (m)
        ratio = err / tolerance
        if not (ratio <= 1.0) and hc > H_FLOOR:
            counters[CST_REJECTED] += 1
            y[:] = y_save
            h_prop[:] = h_save
            status[:] = status_save
            t_event[:] = event_save
            for p in range(n):
                stats[p, STAT_REASON] = reason_save[p]
            fac = SAFETY / math.sqrt(ratio) if math.isfinite(ratio) else FAC_MIN
            h = hc * min(FAC_MIN if rejected else 1.0, max(FAC_MIN, fac))
            h = max(h, H_FLOOR)
            rejected = True
            continue
        if not (ratio <= 1.0):
            counters[CST_FORCED] += 1
        counters[CST_ACCEPTED] += 1
        grow = FAC_MAX if ratio == 0.0 else min(FAC_MAX, max(FAC_MIN, SAFETY / math.sqrt(ratio)))
        if rejected:
            grow = min(grow, 1.0)
        h_next = min(h_max, hc * grow)
        h = max(h, h_next) if truncated else h_next
        h = min(h, h_max)
        rejected = False
        t = t_end
        forces[:] = f_end
        begin[:] = plateau
    return h
