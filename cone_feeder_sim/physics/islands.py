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
Contact islands: pieces that touch, integrated as one stiff system (compiled).

An island is a set of pieces connected through pairs within reach (see
:func:`islands_of`). Its state is the pieces' states one after the other, shape (n, 9)
in cone axes; its vector field is every piece's own field (:func:`model.rhs`) plus the
pair forces of :func:`contact.pair_force`, equal and opposite. The island is advanced with
the same RODAS4 method, step control, kink handling and exit location as a single piece
(:mod:`integrator`), with the exact Jacobian in blocks: the pieces' own blocks plus one
block per pair by central differences, built equal and opposite so that a step keeps the
pair forces' momentum balance to round-off. The pair forces are therefore integrated
implicitly, with the error the step control measures; there is no splitting error.

The linear systems are solved through the velocities (3 n unknowns), banded in an order
where touching pieces are close (:mod:`band`): a crowd of n pieces in one layer costs
O(n w^2) per step, w the band width in pieces, instead of O(n^3), so no island is too
large to be coupled.
"""

import math

import numba
import numpy as np

from .band import band_factor, band_solve
from .contact import pair_force, pair_jacobian
from .integrator import (
    ACTIVE, after_acceptance, error_norm, EXITED, FAILED, locate_exit,
    proposal_after_rejection, REASON_NOT_FINITE, REASON_STEP_UNDERFLOW, REASON_TOO_MANY_STEPS,
    STAT_ACCEPTED, STAT_REASON, STAT_REJECTED)
from .model import jacobian, rhs, rhs_omega_derivative, STATE_SIZE
from .params import G_EPS, P_M
from .rosenbrock import (
    A21, A31, A32, A41, A42, A43, A51, A52, A53, A54, C2, C21, C3, C31, C32, C4, C41, C42,
    C43, C51, C52, C53, C54, C61, C62, C63, C64, C65, D1, D2, D3, D4, eliminate_filter,
    GAMMA, solve3)

__all__ = ['advance_island', 'islands_of']

jit = numba.njit(cache=True, error_model='numpy', nogil=True)

#: Accepted steps an island's Jacobian is kept for (1: every step). RODAS4 needs the exact
#: Jacobian for its order: kept for 2 or 4 steps, the 54-piece crowds of bench_states took
#: twice the steps and ran 1.5-2x slower (doc/model.md, "Jacobian reuse"), so it is not kept.
JACOBIAN_EVERY = 1


@jit
def island_rhs(y, products, pairs, machine, omega, domega, pull_off, out):
    """Write the island's field into out, both (n, 9): own fields plus pair forces."""
    n = y.shape[0]
    for p in range(n):
        rhs(y[p], products[p], machine, omega, domega, out[p])
    eps = machine[G_EPS]
    for q in range(pairs.shape[0]):
        i = pairs[q, 0]
        j = pairs[q, 1]
        f0, f1, f2 = pair_force(y[i, 0:3], y[i, 3:6], products[i], y[j, 0:3], y[j, 3:6],
                                products[j], pull_off, eps)
        mi = products[i, P_M]
        mj = products[j, P_M]
        out[i, 3] += f0 / mi
        out[i, 4] += f1 / mi
        out[i, 5] += f2 / mi
        out[j, 3] -= f0 / mj
        out[j, 4] -= f1 / mj
        out[j, 5] -= f2 / mj


@jit
def island_jacobian(y, products, pairs, machine, omega, domega, pull_off, own, pair_jac,
                    xi, wi):
    """
    Write the island's Jacobian in blocks: own (n, 9, 9) and pair_jac (m, 3, 6).

    own[p] is piece p's own block d(f_p)/d(y_p), its pairs' forces included; pair_jac[q]
    is d(F)/d(x_i, w_i) of pair q = (i, j), by central differences. The pair force depends
    on the differences of the two pieces' positions and velocities only, so this one block
    gives all four places, with the signs and masses of the force balance:
    d(f_i)/d(y_j) = -G/m_i and d(f_j)/d(y_i) = -G/m_j in the velocity rows. xi, wi (3,)
    are scratch.
    """
    n = y.shape[0]
    for p in range(n):
        jacobian(y[p], products[p], machine, omega, domega, own[p])
    eps = machine[G_EPS]
    for q in range(pairs.shape[0]):
        i = pairs[q, 0]
        j = pairs[q, 1]
        mi = products[i, P_M]
        mj = products[j, P_M]
        pair_jacobian(y[i, 0:3], y[i, 3:6], products[i], y[j, 0:3], y[j, 3:6], products[j],
                      pull_off, eps, pair_jac[q], xi, wi)
        for a in range(3):
            for c in range(6):
                g = pair_jac[q, a, c]
                own[i, 3 + a, c] += g / mi
                own[j, 3 + a, c] += g / mj


@jit
def island_factor(own, pair_jac, pairs, products, alpha, pos, kl, ab, piv, s_lu, s_piv,
                  t_mat):
    """
    Factor W = alpha I - J of an island through its velocities; False if singular.

    The Jacobian's structure makes this exact: the position rows are dx/dt = w and the
    filter rows couple a piece to itself only, so per piece k_x = (r_x + k_w)/alpha and
    k_P = S^-1 (r_P + J_Px r_x/alpha) + T k_w with S = alpha I - J_PP and
    T = S^-1 (J_Px/alpha + J_Pw). What is left is M k_w = r~, 3 n unknowns:
    M_pq = delta_pq (alpha I - J_wP T_p) - (J_{w_p x_q}/alpha + J_{w_p w_q}), non-zero off
    the diagonal only for pieces in a pair. Piece p's unknowns are rows 3 pos[p] ... + 2 of
    M, held banded (:mod:`band`) with kl sub-diagonals in ab (3 n, 3 kl + 1); piv (3 n,).
    s_lu (n, 3, 3), s_piv (n, 3) receive the factored S; t_mat (n, 3, 3) the T of every
    piece. Blocks as written by :func:`island_jacobian`.
    """
    n = s_lu.shape[0]
    for r in range(ab.shape[0]):
        for c in range(ab.shape[1]):
            ab[r, c] = 0.0
    diag = np.empty((3, 3))
    for p in range(n):
        if not eliminate_filter(own[p], alpha, s_lu[p], s_piv[p], t_mat[p], diag):
            return False
        o = 3 * pos[p]
        for a in range(3):
            for b in range(3):
                ab[o + a, b - a + kl] = diag[a, b]
    for q in range(pairs.shape[0]):
        i = pairs[q, 0]
        j = pairs[q, 1]
        oi = 3 * pos[i]
        oj = 3 * pos[j]
        mi = products[i, P_M]
        mj = products[j, P_M]
        for a in range(3):
            for b in range(3):
                g = pair_jac[q, a, b] / alpha + pair_jac[q, a, 3 + b]
                ab[oi + a, oj + b - oi - a + kl] += g / mi
                ab[oj + a, oi + b - oj - a + kl] += g / mj
    return band_factor(ab, piv, kl)


@jit
def island_solve(own, pair_jac, pairs, products, alpha, pos, kl, ab, piv, s_lu, s_piv,
                 t_mat, rhs_v, u, b):
    """Solve W k = b in place in b (9 n,) with the factors of :func:`island_factor`."""
    n = s_lu.shape[0]
    for p in range(n):
        blk = own[p]
        o = STATE_SIZE * p
        r0, r1, r2 = (b[o + 6], b[o + 7], b[o + 8])
        for c in range(3):
            x = b[o + c] / alpha
            r0 += blk[6, c] * x
            r1 += blk[7, c] * x
            r2 += blk[8, c] * x
        u0, u1, u2 = solve3(s_lu[p], s_piv[p], r0, r1, r2)
        u[p, 0] = u0
        u[p, 1] = u1
        u[p, 2] = u2
        ov = 3 * pos[p]
        for a in range(3):
            acc = b[o + 3 + a]
            for c in range(3):
                acc += blk[3 + a, 6 + c] * u[p, c] + blk[3 + a, c] * b[o + c] / alpha
            rhs_v[ov + a] = acc
    for q in range(pairs.shape[0]):
        i = pairs[q, 0]
        j = pairs[q, 1]
        oi = STATE_SIZE * i
        oj = STATE_SIZE * j
        mi = products[i, P_M]
        mj = products[j, P_M]
        for a in range(3):
            acc_i = 0.0
            acc_j = 0.0
            for c in range(3):
                acc_i += pair_jac[q, a, c] * b[oj + c]
                acc_j += pair_jac[q, a, c] * b[oi + c]
            rhs_v[3 * pos[i] + a] -= acc_i / (alpha * mi)
            rhs_v[3 * pos[j] + a] -= acc_j / (alpha * mj)
    band_solve(ab, piv, kl, rhs_v)
    for p in range(n):
        o = STATE_SIZE * p
        ov = 3 * pos[p]
        for a in range(3):
            kw = rhs_v[ov + a]
            b[o + a] = (b[o + a] + kw) / alpha
            b[o + 3 + a] = kw
        for a in range(3):
            acc = u[p, a]
            for c in range(3):
                acc += t_mat[p, a, c] * rhs_v[ov + c]
            b[o + 6 + a] = acc


@jit
def island_step(y0, f0, ft, h, omega0, domega, products, pairs, machine, pull_off, own,
                pair_jac, pos, kl, ab, piv, k, ys, f, y1, s_lu, s_piv, t_mat, rhs_v, u):
    """
    Take one RODAS4 step of size h for the island; return False if W cannot be factored.

    Flat arrays: y0, f0, ft (time derivative of the field), ys, f, y1 (9 n,); k (6, 9 n)
    the stages (row 5 the error estimate); own, pair_jac the Jacobian at y0 in blocks
    (:func:`island_jacobian`). W = I/(gamma h) - J is factored through the velocities
    (:func:`island_factor`, band order pos, kl): ab (3 n, 3 kl + 1), piv (3 n,), s_lu
    (n, 3, 3), s_piv (n, 3), t_mat (n, 3, 3), rhs_v (3 n,) and u (n, 3) are scratch.
    """
    size = y0.shape[0]
    n = size // STATE_SIZE
    alpha = 1.0 / (GAMMA * h)
    if not island_factor(own, pair_jac, pairs, products, alpha, pos, kl, ab, piv, s_lu, s_piv,
                         t_mat):
        return False
    ys2 = ys.reshape(n, STATE_SIZE)
    f2 = f.reshape(n, STATE_SIZE)
    for i in range(size):
        k[0, i] = f0[i] + h * D1 * ft[i]
    island_solve(own, pair_jac, pairs, products, alpha, pos, kl, ab, piv, s_lu, s_piv, t_mat,
                 rhs_v, u, k[0])
    for i in range(size):
        ys[i] = y0[i] + A21 * k[0, i]
    island_rhs(ys2, products, pairs, machine, omega0 + domega * C2 * h, domega, pull_off, f2)
    for i in range(size):
        k[1, i] = f[i] + h * D2 * ft[i] + C21 * k[0, i] / h
    island_solve(own, pair_jac, pairs, products, alpha, pos, kl, ab, piv, s_lu, s_piv, t_mat,
                 rhs_v, u, k[1])
    for i in range(size):
        ys[i] = y0[i] + A31 * k[0, i] + A32 * k[1, i]
    island_rhs(ys2, products, pairs, machine, omega0 + domega * C3 * h, domega, pull_off, f2)
    for i in range(size):
        k[2, i] = f[i] + h * D3 * ft[i] + (C31 * k[0, i] + C32 * k[1, i]) / h
    island_solve(own, pair_jac, pairs, products, alpha, pos, kl, ab, piv, s_lu, s_piv, t_mat,
                 rhs_v, u, k[2])
    for i in range(size):
        ys[i] = y0[i] + A41 * k[0, i] + A42 * k[1, i] + A43 * k[2, i]
    island_rhs(ys2, products, pairs, machine, omega0 + domega * C4 * h, domega, pull_off, f2)
    for i in range(size):
        k[3, i] = f[i] + h * D4 * ft[i] + (C41 * k[0, i] + C42 * k[1, i] + C43 * k[2, i]) / h
    island_solve(own, pair_jac, pairs, products, alpha, pos, kl, ab, piv, s_lu, s_piv, t_mat,
                 rhs_v, u, k[3])
    for i in range(size):
        ys[i] = y0[i] + A51 * k[0, i] + A52 * k[1, i] + A53 * k[2, i] + A54 * k[3, i]
    omega1 = omega0 + domega * h
    island_rhs(ys2, products, pairs, machine, omega1, domega, pull_off, f2)
    for i in range(size):
        k[4, i] = f[i] + (C51 * k[0, i] + C52 * k[1, i] + C53 * k[2, i] + C54 * k[3, i]) / h
    island_solve(own, pair_jac, pairs, products, alpha, pos, kl, ab, piv, s_lu, s_piv, t_mat,
                 rhs_v, u, k[4])
    for i in range(size):
        ys[i] += k[4, i]
    island_rhs(ys2, products, pairs, machine, omega1, domega, pull_off, f2)
    for i in range(size):
        k[5, i] = f[i] + (C61 * k[0, i] + C62 * k[1, i] + C63 * k[2, i] + C64 * k[3, i]
                          + C65 * k[4, i]) / h
    island_solve(own, pair_jac, pairs, products, alpha, pos, kl, ab, piv, s_lu, s_piv, t_mat,
                 rhs_v, u, k[5])
    for i in range(size):
        y1[i] = ys[i] + k[5, i]
    return True


@jit
def advance_island(y, products, pairs, pos, kl, machine, seg_t, seg_omega, seg_domega, r_exit,
                   h_prop, rtol, atol, h_min, h_max, h_kink, max_steps, pull_off, stats):
    """
    Advance an island through the segments, or until one of its pieces exits, or it fails.

    y (n, 9) cone-axes states, updated in place; products (n, PRODUCT_WIDTH); pairs (m, 2)
    int64 local indices; pos (n,) int64 and kl the band order of the velocity system:
    piece p's unknowns are rows 3 pos[p] ... + 2, with at most kl (>= 2) sub-diagonals
    (:func:`band.band_order`: kl = 3 width + 2); atol (9,); stats (STAT_WIDTH,) int64
    counters of the island. The step control is that of :func:`integrator.advance_particle`.
    Returns (status, t, h_prop, piece): ACTIVE with the end time; EXITED with the exit
    time of ``piece`` (y then holds every piece's state at that time); FAILED with the time
    reached.
    """
    n = y.shape[0]
    size = STATE_SIZE * n
    flat = y.reshape(size)
    m = pairs.shape[0]
    own = np.empty((n, STATE_SIZE, STATE_SIZE))
    pair_jac = np.empty((m, 3, 6))
    kl = min(kl, 3 * n - 1)
    ab = np.empty((3 * n, 3 * kl + 1))
    piv = np.empty(3 * n, dtype=np.int64)
    s_lu = np.empty((n, 3, 3))
    s_piv = np.empty((n, 3), dtype=np.int64)
    t_mat = np.empty((n, 3, 3))
    rhs_v = np.empty(3 * n)
    u = np.empty((n, 3))
    k = np.empty((6, size))
    ys = np.empty(size)
    f = np.empty(size)
    f0 = np.empty(size)
    ft = np.empty(size)
    y1 = np.empty(size)
    xi = np.empty(3)
    wi = np.empty(3)
    atol_flat = np.empty(size)
    for i in range(size):
        atol_flat[i] = atol[i % STATE_SIZE]
    f0_2 = f0.reshape(n, STATE_SIZE)
    ft_2 = ft.reshape(n, STATE_SIZE)
    n_seg = seg_omega.shape[0]
    steps = 0
    age = 0
    t = seg_t[0]
    h_acc = 0.0
    err_acc = 1.0
    r2 = r_exit * r_exit
    for s in range(n_seg):
        t_seg = seg_t[s]
        t_end = seg_t[s + 1]
        omega_s = seg_omega[s]
        domega = seg_domega[s]
        if s > 0 and domega != seg_domega[s - 1]:
            h_prop = min(h_prop, h_kink)
        fresh = True
        rejected = False
        while t < t_end:
            remaining = t_end - t
            truncated = h_prop >= remaining
            h = remaining if truncated else h_prop
            omega0 = omega_s + domega * (t - t_seg)
            if fresh:
                island_rhs(y, products, pairs, machine, omega0, domega, pull_off, f0_2)
                if age % JACOBIAN_EVERY == 0:
                    island_jacobian(y, products, pairs, machine, omega0, domega, pull_off, own,
                                    pair_jac, xi, wi)
                age += 1
                for p in range(n):
                    rhs_omega_derivative(y[p], omega0, ft_2[p])
                for i in range(size):
                    ft[i] *= domega
                fresh = False
            ok = island_step(flat, f0, ft, h, omega0, domega, products, pairs, machine,
                             pull_off, own, pair_jac, pos, kl, ab, piv, k, ys, f, y1, s_lu,
                             s_piv, t_mat, rhs_v, u)
            err = error_norm(k[5], flat, y1, rtol, atol_flat) if ok else np.inf
            steps += 1
            if steps > max_steps:
                stats[STAT_REASON] = REASON_TOO_MANY_STEPS
                return FAILED, t, h_prop, -1
            if not (err <= 1.0):
                stats[STAT_REJECTED] += 1
                if age % JACOBIAN_EVERY != 1 % JACOBIAN_EVERY:  # stale: refresh it
                    island_jacobian(y, products, pairs, machine, omega0, domega, pull_off, own,
                                    pair_jac, xi, wi)
                    age = 1
                h_prop = proposal_after_rejection(h, err, rejected)
                rejected = True
                if h_prop < h_min:
                    stats[STAT_REASON] = (REASON_NOT_FINITE if not math.isfinite(err)
                                          else REASON_STEP_UNDERFLOW)
                    return FAILED, t, h_prop, -1
                continue
            stats[STAT_ACCEPTED] += 1
            first = -1
            theta = 2.0
            for p in range(n):
                o = STATE_SIZE * p
                if y1[o] * y1[o] + y1[o + 1] * y1[o + 1] >= r2:
                    th = locate_exit(h, flat[o:o + STATE_SIZE], y1[o:o + STATE_SIZE], r_exit)
                    if th < theta:
                        theta = th
                        first = p
            if first >= 0:
                h_exit = theta * h
                ok = island_step(flat, f0, ft, h_exit, omega0, domega, products, pairs,
                                 machine, pull_off, own, pair_jac, pos, kl, ab, piv, k, ys, f,
                                 y1, s_lu, s_piv, t_mat, rhs_v, u)
                if not ok:
                    stats[STAT_REASON] = REASON_NOT_FINITE
                    return FAILED, t, h_prop, -1
                for i in range(size):
                    flat[i] = y1[i]
                return EXITED, t + h_exit, h_prop, first
            for i in range(size):
                flat[i] = y1[i]
            fresh = True
            t, h_prop, h_acc, err_acc = after_acceptance(t, t_end, h, h_prop, h_max, err,
                                                         h_acc, err_acc, rejected, truncated)
            rejected = False
    return ACTIVE, t, h_prop, -1


@jit
def _roots(count, pairs):
    """Return each piece's island label (its smallest index), union-find over the pairs."""
    parent = np.arange(count)
    for q in range(pairs.shape[0]):
        a = pairs[q, 0]
        while parent[a] != a:
            a = parent[a]
        b = pairs[q, 1]
        while parent[b] != b:
            b = parent[b]
        if a != b:
            parent[max(a, b)] = min(a, b)
    for i in range(count):  # parents have smaller indices: one pass flattens
        parent[i] = parent[parent[i]]
    return parent


def islands_of(count: int, pairs: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """
    Return the islands of ``count`` pieces linked by ``pairs`` (M, 2), i < j.

    Each island is (members, local pairs): the sorted piece indices, and its pairs as
    indices into members, shape (m, 2). Only islands of two or more pieces are returned,
    ordered by their smallest index.
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if not len(pairs):
        return []
    labels = _roots(count, pairs)
    sizes = np.bincount(labels, minlength=count)
    order = np.argsort(labels, kind='stable')  # members of an island stay sorted
    starts = np.concatenate([[0], np.cumsum(sizes)])
    local = np.empty(count, dtype=np.int64)
    pair_label = labels[pairs[:, 0]]
    pair_order = np.argsort(pair_label, kind='stable')
    pair_starts = np.concatenate([[0], np.cumsum(np.bincount(pair_label, minlength=count))])
    islands = []
    for root in np.flatnonzero(sizes > 1):
        members = order[starts[root]:starts[root + 1]]
        local[members] = np.arange(members.size)
        own = pairs[pair_order[pair_starts[root]:pair_starts[root + 1]]]
        islands.append((members, local[own]))
    return islands
