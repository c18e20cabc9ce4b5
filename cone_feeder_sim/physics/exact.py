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
The exact coupling of pieces that touch: an island and its contacts as one system (compiled).

The reference for :mod:`.coupling` (``interactions.coupling: exact``). An island (pieces
linked by pairs within reach, :func:`islands_of`) is integrated as one ODE whose state is
every piece's state (n, 9) followed by every pair's history (m, 3), with the same RODAS4
method, step control, kink handling and exit location as a single piece
(:mod:`.integrator`). Its field is every piece's own field (:func:`.model.rhs`), the pair
forces of :func:`.contact.contact_force`, equal and opposite, and the history's own
equation, the continuous form of the law's update:

    xi' = v_t - (xi . n') n                      while the spring holds (|S_t xi| < mu |F_n|)
    xi' = b - xi^ (xi^ . b - c')  if xi^ . b > c', with b the line above,
                                                 while it slides (|xi| = c = mu |F_n| / S_t)

so a sliding history follows its cap; n' = v_t / |d| turns the tangent plane with the
contact. At the end of every step a pair apart loses its history
(:func:`settle_histories`). Nothing is
split and nothing is cut: the error is the one the step control measures, whatever the
stiffness of the law; the cost is that of a dense system of 9 n + 3 m unknowns
(the pieces' own blocks are exact, the pairs' by forward differences).
"""

import math

import numba
import numpy as np

from .contact import contact_force
from .contact.law import force_between, I_MU
from .contact.tangential import rotate_and_cap, SLIDING_MARGIN
from .integrator import (
    ACTIVE, after_acceptance, error_norm, EXITED, FAILED, locate_exit,
    proposal_after_rejection, REASON_NOT_FINITE, REASON_STEP_UNDERFLOW, REASON_TOO_MANY_STEPS,
    STAT_ACCEPTED, STAT_REASON, STAT_REJECTED, STOPPED)
from .model import jacobian, rhs, rhs_omega_derivative, STATE_SIZE
from .params import P_M
from .rosenbrock import (
    A21, A31, A32, A41, A42, A43, A51, A52, A53, A54, C2, C21, C3, C31, C32, C4, C41, C42,
    C43, C51, C52, C53, C54, C61, C62, C63, C64, C65, D1, D2, D3, D4, GAMMA, lu_factor,
    lu_solve)
from .stop import stop_requested

__all__ = ['advance_island', 'history_rate', 'history_rate_of', 'islands_of']

jit = numba.njit(cache=True, error_model='numpy', nogil=True)

#: Time step (s) of the difference that gives the rate of a sliding contact's cap.
CAP_RATE_STEP = 1.0e-7
#: Relative step of the forward differences of the pair blocks of the Jacobian.
FD_STEP = 1.0e-7


@jit
def cap_level(d0, d1, d2, u0, u1, u2, pi, pj, inter):
    """Return mu |F_n| / S_t (m), the longest history the spring holds; inf if apart."""
    f = contact_force(d0, d1, d2, u0, u1, u2, 0.0, 0.0, 0.0, pi, pj, inter)
    if f[3] <= 0.0 or f[5] == 0.0:
        return np.inf
    return inter[I_MU] * abs(f[4]) / f[5]


@jit
def history_rate(d0, d1, d2, u0, u1, u2, a0, a1, a2, h0, h1, h2, pi, pj, inter):
    """Return xi' (3 floats) of a contact: d, u, a the pair's relative state and acceleration."""
    f = contact_force(d0, d1, d2, u0, u1, u2, h0, h1, h2, pi, pj, inter)
    return history_rate_of(f, d0, d1, d2, u0, u1, u2, a0, a1, a2, h0, h1, h2, pi, pj, inter)


@jit
def history_rate_of(f, d0, d1, d2, u0, u1, u2, a0, a1, a2, h0, h1, h2, pi, pj, inter):
    """:func:`history_rate` given the contact's :func:`.contact.contact_force` f."""
    dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if f[3] <= 0.0:
        return 0.0, 0.0, 0.0
    n0, n1, n2 = f[6], f[7], f[8]
    v_n = u0 * n0 + u1 * n1 + u2 * n2
    t0, t1, t2 = u0 - v_n * n0, u1 - v_n * n1, u2 - v_n * n2
    turn = (h0 * t0 + h1 * t1 + h2 * t2) / dist  # xi . n'
    b0, b1, b2 = t0 - turn * n0, t1 - turn * n1, t2 - turn * n2
    size = math.sqrt(h0 * h0 + h1 * h1 + h2 * h2)
    if f[5] * size < inter[I_MU] * abs(f[4]) * (1.0 - SLIDING_MARGIN):
        return b0, b1, b2
    if size == 0.0:  # nothing holds (mu = 0 or no normal force): no history to keep
        return 0.0, 0.0, 0.0
    e = CAP_RATE_STEP
    c0 = cap_level(d0, d1, d2, u0, u1, u2, pi, pj, inter)
    c1 = cap_level(d0 + e * u0, d1 + e * u1, d2 + e * u2, u0 + e * a0, u1 + e * a1,
                   u2 + e * a2, pi, pj, inter)
    rate = (c1 - c0) / e if math.isfinite(c1) else 0.0
    g0, g1, g2 = h0 / size, h1 / size, h2 / size
    grow = b0 * g0 + b1 * g1 + b2 * g2 - rate
    if grow <= 0.0:
        return b0, b1, b2
    return b0 - grow * g0, b1 - grow * g1, b2 - grow * g2


@jit
def island_rhs(y, hist, products, pairs, inter, machine, omega, domega, out, hist_out):
    """Write the field: pieces (n, 9) into out, histories (m, 3) into hist_out."""
    n = y.shape[0]
    for p in range(n):
        rhs(y[p], products[p], machine, omega, domega, out[p])
    for q in range(pairs.shape[0]):
        i = pairs[q, 0]
        j = pairs[q, 1]
        f = force_between(y[i], y[j], hist[q, 0], hist[q, 1], hist[q, 2], products[i],
                          products[j], inter)
        mi = products[i, P_M]
        mj = products[j, P_M]
        for a in range(3):
            out[i, 3 + a] += f[a] / mi
            out[j, 3 + a] -= f[a] / mj
    for q in range(pairs.shape[0]):
        i = pairs[q, 0]
        j = pairs[q, 1]
        r = history_rate(y[i, 0] - y[j, 0], y[i, 1] - y[j, 1], y[i, 2] - y[j, 2],
                         y[i, 3] - y[j, 3], y[i, 4] - y[j, 4], y[i, 5] - y[j, 5],
                         out[i, 3] - out[j, 3], out[i, 4] - out[j, 4], out[i, 5] - out[j, 5],
                         hist[q, 0], hist[q, 1], hist[q, 2], products[i], products[j], inter)
        hist_out[q, 0] = r[0]
        hist_out[q, 1] = r[1]
        hist_out[q, 2] = r[2]


@jit
def island_jacobian(y, hist, products, pairs, inter, machine, omega, domega, f0, fh0, jac,
                    ys, hs, fs, fhs):
    """
    Write the island's Jacobian (N, N), N = 9 n + 3 m, into jac.

    The pieces' own blocks are exact (:func:`.model.jacobian`); the rest by forward
    differences of the whole field around (y, hist) with field (f0, fh0): for each column
    the field minus the pieces' own fields is differenced (ys, hs, fs, fhs scratch).
    """
    n = y.shape[0]
    m = hist.shape[0]
    size = STATE_SIZE * n + 3 * m
    for r in range(size):
        for c in range(size):
            jac[r, c] = 0.0
    own = np.empty((STATE_SIZE, STATE_SIZE))
    for p in range(n):
        jacobian(y[p], products[p], machine, omega, domega, own)
        o = STATE_SIZE * p
        for r in range(STATE_SIZE):
            for c in range(STATE_SIZE):
                jac[o + r, o + c] = own[r, c]
    if m == 0:
        return
    own_f = np.empty(STATE_SIZE)
    for c in range(size):
        ys[:] = y
        hs[:] = hist
        if c < STATE_SIZE * n:
            p = c // STATE_SIZE
            a = c % STATE_SIZE
            step = FD_STEP * max(abs(y[p, a]), 1e-3)
            ys[p, a] += step
        else:
            q = (c - STATE_SIZE * n) // 3
            a = (c - STATE_SIZE * n) % 3
            step = FD_STEP * max(abs(hist[q, a]), 1e-4)
            hs[q, a] += step
        island_rhs(ys, hs, products, pairs, inter, machine, omega, domega, fs, fhs)
        for p in range(n):
            o = STATE_SIZE * p
            for r in range(STATE_SIZE):
                jac[o + r, c] += (fs[p, r] - f0[p, r]) / step
        # the pieces' own fields: exact above, so take their difference out again
        if c < STATE_SIZE * n:
            p = c // STATE_SIZE
            rhs(ys[p], products[p], machine, omega, domega, own_f)
            o = STATE_SIZE * p
            rhs(y[p], products[p], machine, omega, domega, fs[p])
            for r in range(STATE_SIZE):
                jac[o + r, c] -= (own_f[r] - fs[p, r]) / step
        for q in range(m):
            o = STATE_SIZE * n + 3 * q
            for r in range(3):
                jac[o + r, c] = (fhs[q, r] - fh0[q, r]) / step


@jit
def pack(y, hist, flat):
    """Write pieces (n, 9) and histories (m, 3) into the flat state (N,)."""
    n = y.shape[0]
    for p in range(n):
        for a in range(STATE_SIZE):
            flat[STATE_SIZE * p + a] = y[p, a]
    o = STATE_SIZE * n
    for q in range(hist.shape[0]):
        for a in range(3):
            flat[o + 3 * q + a] = hist[q, a]


@jit
def unpack(flat, y, hist):
    """Read pieces and histories from the flat state (inverse of :func:`pack`)."""
    n = y.shape[0]
    for p in range(n):
        for a in range(STATE_SIZE):
            y[p, a] = flat[STATE_SIZE * p + a]
    o = STATE_SIZE * n
    for q in range(hist.shape[0]):
        for a in range(3):
            hist[q, a] = flat[o + 3 * q + a]


@jit
def field_flat(flat, y, hist, products, pairs, inter, machine, omega, domega, out, f2, fh2):
    """Write the field of the flat state into out (N,)."""
    unpack(flat, y, hist)
    island_rhs(y, hist, products, pairs, inter, machine, omega, domega, f2, fh2)
    pack(f2, fh2, out)


@jit
def island_step(flat0, f0, ft, h, omega0, domega, products, pairs, inter, machine, lu, piv, k,
                ys, f, y1, y, hist, f2, fh2):
    """
    Take one RODAS4 step of size h of the island's flat state; False if W is singular.

    lu holds the Jacobian on entry and W's factors after; k (6, N) the stages (row 5 the
    error estimate).
    """
    size = flat0.shape[0]
    alpha = 1.0 / (GAMMA * h)
    for r in range(size):
        for c in range(size):
            lu[r, c] = -lu[r, c]
        lu[r, r] += alpha
    if not lu_factor(lu, piv):
        return False
    for i in range(size):
        k[0, i] = f0[i] + h * D1 * ft[i]
    lu_solve(lu, piv, k[0])
    for i in range(size):
        ys[i] = flat0[i] + A21 * k[0, i]
    field_flat(ys, y, hist, products, pairs, inter, machine, omega0 + domega * C2 * h, domega,
               f, f2, fh2)
    for i in range(size):
        k[1, i] = f[i] + h * D2 * ft[i] + C21 * k[0, i] / h
    lu_solve(lu, piv, k[1])
    for i in range(size):
        ys[i] = flat0[i] + A31 * k[0, i] + A32 * k[1, i]
    field_flat(ys, y, hist, products, pairs, inter, machine, omega0 + domega * C3 * h, domega,
               f, f2, fh2)
    for i in range(size):
        k[2, i] = f[i] + h * D3 * ft[i] + (C31 * k[0, i] + C32 * k[1, i]) / h
    lu_solve(lu, piv, k[2])
    for i in range(size):
        ys[i] = flat0[i] + A41 * k[0, i] + A42 * k[1, i] + A43 * k[2, i]
    field_flat(ys, y, hist, products, pairs, inter, machine, omega0 + domega * C4 * h, domega,
               f, f2, fh2)
    for i in range(size):
        k[3, i] = f[i] + h * D4 * ft[i] + (C41 * k[0, i] + C42 * k[1, i] + C43 * k[2, i]) / h
    lu_solve(lu, piv, k[3])
    for i in range(size):
        ys[i] = flat0[i] + A51 * k[0, i] + A52 * k[1, i] + A53 * k[2, i] + A54 * k[3, i]
    omega1 = omega0 + domega * h
    field_flat(ys, y, hist, products, pairs, inter, machine, omega1, domega, f, f2, fh2)
    for i in range(size):
        k[4, i] = f[i] + (C51 * k[0, i] + C52 * k[1, i] + C53 * k[2, i] + C54 * k[3, i]) / h
    lu_solve(lu, piv, k[4])
    for i in range(size):
        ys[i] += k[4, i]
    field_flat(ys, y, hist, products, pairs, inter, machine, omega1, domega, f, f2, fh2)
    for i in range(size):
        k[5, i] = f[i] + (C61 * k[0, i] + C62 * k[1, i] + C63 * k[2, i] + C64 * k[3, i]
                          + C65 * k[4, i]) / h
    lu_solve(lu, piv, k[5])
    for i in range(size):
        y1[i] = ys[i] + k[5, i]
    return True


@jit
def block_error(err, y0, y1, rtol, atol, n, m):
    """Return the largest scaled RMS error of a piece (9) or a history (3)."""
    worst = 0.0
    for p in range(n):
        o = STATE_SIZE * p
        worst = max(worst, error_norm(err[o:o + STATE_SIZE], y0[o:o + STATE_SIZE],
                                      y1[o:o + STATE_SIZE], rtol, atol[o:o + STATE_SIZE]))
    base = STATE_SIZE * n
    for q in range(m):
        o = base + 3 * q
        worst = max(worst, error_norm(err[o:o + 3], y0[o:o + 3], y1[o:o + 3], rtol,
                                      atol[o:o + 3]))
    return worst


@jit
def settle_histories(flat, products, pairs, inter, n):
    """
    Settle the histories of the flat state after a step: a pair apart loses its history.

    The others are turned into their tangent plane (round-off leaves a trace of the normal
    there). They are not cut to their caps: the history's own equation keeps a sliding one
    on it, and cutting after every step of a method that steps across the stick-slip switch
    changed the answer (measured: an oblique collision's tangential speed 2x off a DEM
    integration of the same law at 1 us steps; without the cut, within 0.3 %).
    """
    base = STATE_SIZE * n
    for q in range(pairs.shape[0]):
        i = STATE_SIZE * pairs[q, 0]
        j = STATE_SIZE * pairs[q, 1]
        o = base + 3 * q
        f = contact_force(flat[i] - flat[j], flat[i + 1] - flat[j + 1],
                          flat[i + 2] - flat[j + 2], flat[i + 3] - flat[j + 3],
                          flat[i + 4] - flat[j + 4], flat[i + 5] - flat[j + 5], 0.0, 0.0, 0.0,
                          products[pairs[q, 0]], products[pairs[q, 1]], inter)
        if f[3] <= 0.0:
            for a in range(3):
                flat[o + a] = 0.0
            continue
        h0, h1, h2 = rotate_and_cap(flat[o], flat[o + 1], flat[o + 2], f[6], f[7], f[8], f[5],
                                    np.inf)
        flat[o] = h0
        flat[o + 1] = h1
        flat[o + 2] = h2


@jit
def advance_island(y, hist, products, pairs, inter, machine, seg_t, seg_omega, seg_domega,
                   r_exit, h_prop, rtol, atol, h_min, h_max, h_kink, max_steps, stats, stop):
    """
    Advance an island through the segments, or until one of its pieces exits, or it fails.

    y (n, 9) cone-axes states and hist (m, 3) the histories of its pairs (m, 2) (local
    indices), updated in place; inter the law's row; atol (9,); stats (STAT_WIDTH,) int64
    counters of the island. The step control is that of
    :func:`integrator.advance_particle`. Returns (status, t, h_prop, piece): ACTIVE with the
    end time; EXITED with the exit time of ``piece`` (y, hist then hold the state at that
    time); FAILED with the time reached; STOPPED with the time reached when stop[0] (1,)
    int64 was set before a step (:mod:`.stop`).
    """
    n = y.shape[0]
    m = pairs.shape[0]
    size = STATE_SIZE * n + 3 * m
    flat = np.empty(size)
    pack(y, hist, flat)
    lu = np.empty((size, size))
    jac = np.empty((size, size))
    piv = np.empty(size, dtype=np.int64)
    k = np.empty((6, size))
    ys = np.empty(size)
    f = np.empty(size)
    f0 = np.empty(size)
    ft = np.empty(size)
    y1 = np.empty(size)
    yw = np.empty((n, STATE_SIZE))
    hw = np.empty((m, 3))
    f2 = np.empty((n, STATE_SIZE))
    fh2 = np.empty((m, 3))
    ys2 = np.empty((n, STATE_SIZE))
    hs2 = np.empty((m, 3))
    fs2 = np.empty((n, STATE_SIZE))
    fhs2 = np.empty((m, 3))
    ft2 = np.empty(STATE_SIZE)
    atol_flat = np.empty(size)
    for i in range(STATE_SIZE * n):
        atol_flat[i] = atol[i % STATE_SIZE]
    for i in range(STATE_SIZE * n, size):
        atol_flat[i] = atol[0]
    n_seg = seg_omega.shape[0]
    steps = 0
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
            if stop_requested(stop):
                unpack(flat, y, hist)
                return STOPPED, t, h_prop, -1
            remaining = t_end - t
            truncated = h_prop >= remaining
            h = remaining if truncated else h_prop
            omega0 = omega_s + domega * (t - t_seg)
            if fresh:
                field_flat(flat, yw, hw, products, pairs, inter, machine, omega0, domega, f0,
                           f2, fh2)
                island_jacobian(yw, hw, products, pairs, inter, machine, omega0, domega, f2,
                                fh2, jac, ys2, hs2, fs2, fhs2)
                for i in range(size):
                    ft[i] = 0.0
                for p in range(n):
                    rhs_omega_derivative(yw[p], omega0, ft2)
                    for a in range(STATE_SIZE):
                        ft[STATE_SIZE * p + a] = domega * ft2[a]
                fresh = False
            lu[:] = jac
            ok = island_step(flat, f0, ft, h, omega0, domega, products, pairs, inter, machine,
                             lu, piv, k, ys, f, y1, yw, hw, f2, fh2)
            err = block_error(k[5], flat, y1, rtol, atol_flat, n, m) if ok else np.inf
            steps += 1
            if steps > max_steps:
                stats[STAT_REASON] = REASON_TOO_MANY_STEPS
                unpack(flat, y, hist)
                return FAILED, t, h_prop, -1
            if not (err <= 1.0):
                stats[STAT_REJECTED] += 1
                h_prop = proposal_after_rejection(h, err, rejected)
                rejected = True
                if h_prop < h_min:
                    stats[STAT_REASON] = (REASON_NOT_FINITE if not math.isfinite(err)
                                          else REASON_STEP_UNDERFLOW)
                    unpack(flat, y, hist)
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
                lu[:] = jac
                ok = island_step(flat, f0, ft, h_exit, omega0, domega, products, pairs, inter,
                                 machine, lu, piv, k, ys, f, y1, yw, hw, f2, fh2)
                if not ok:
                    stats[STAT_REASON] = REASON_NOT_FINITE
                    unpack(flat, y, hist)
                    return FAILED, t, h_prop, -1
                settle_histories(y1, products, pairs, inter, n)
                unpack(y1, y, hist)
                return EXITED, t + h_exit, h_prop, first
            for i in range(size):
                flat[i] = y1[i]
            settle_histories(flat, products, pairs, inter, n)
            fresh = True
            t, h_prop, h_acc, err_acc = after_acceptance(t, t_end, h, h_prop, h_max, err,
                                                         h_acc, err_acc, rejected, truncated)
            rejected = False
    unpack(flat, y, hist)
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


Island = tuple[np.ndarray, np.ndarray, np.ndarray]


def islands_of(count: int, pairs: np.ndarray) -> list[Island]:
    """
    Return the islands of ``count`` pieces linked by ``pairs`` (M, 2), i < j.

    Each island is (members, local pairs, pair indices): the sorted piece indices, its
    pairs as indices into members (m, 2), and those pairs' rows in ``pairs`` (m,). Only
    islands of two or more pieces are returned, ordered by their smallest index.
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
        rows = pair_order[pair_starts[root]:pair_starts[root + 1]]
        islands.append((members, local[pairs[rows]], rows))
    return islands
