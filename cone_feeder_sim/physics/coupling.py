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

The soft pair law (:mod:`.contact`) is slow next to a piece's own friction dynamics: two
pieces of raw meat touch for 25-100 ms, while a piece's friction filter acts in 0.3 ms. So
every piece keeps its own adaptive RODAS4 steps, and the pair forces couple the pieces
over coupling intervals of length H, chosen by the contact time and by error control (an
explicit co-simulation with extrapolated coupling forces; Busch & Schweizer's
macro-step control). One interval [t, t + H]:

1. **Predict.** Each pair's force at t + H is the law evaluated at the pair's state
   extrapolated to t + H: positions by their velocities and accelerations (the secant of
   each piece's velocity over the last interval; zero at a tick's first), the history by
   the extrapolated tangential displacement. The law's own shape (Hertz's delta^3/2, the
   damping, the cap) is thus kept; only the pieces' paths are extrapolated.
2. **Each piece alone.** A pair's load is linear over the interval, from the value it had
   at the end of the last interval (a load never jumps: a jump rings the lightly damped
   friction filter of a sticking piece) to the prediction. Each piece integrates the
   interval with the sum of its pairs' loads (:func:`.integrator.advance_particle`): its
   own steps, step control, kinks and exit location, as when it is alone. The pieces run
   in parallel. The two pieces of a pair get exactly opposite loads, so their impulses are
   equal and opposite whatever steps they take: momentum to round-off.
3. **Correct.** The pair's history takes the pair's actual relative displacement over the
   interval (the integral of the tangential relative velocity, exactly), turned into the
   end's tangent plane and capped (:func:`.contact.history_update`); the pair's force at
   the end is the law at the pieces' actual states.
4. **Error control.** The impulse the load gave over the interval, H (L0 + L1) / 2, is
   held against the trapezoidal rule on the actual forces at both ends; the difference
   over a piece's mass is a velocity error, and H times it a position error. The interval
   is accepted where the largest is within ``coupling_tolerance`` (m), and the next one
   is sized for the error's order (O(H^4)). A rejected interval is a result: every piece
   goes back to the interval's start and it is tried again shorter.

**Intervals and the contact time.** No interval is longer than 1/omega of any touching
pair, omega = sqrt(S_n / m*) (its natural frequency at the current overlap), nor longer
than the time a pair that is still apart needs to touch at its closing speed (at least an
eighth of the interval tried): a collision of glass spheres (microseconds) is resolved as
a collision of raw meat (tens of milliseconds) is, only in shorter intervals.

Every pair within reach is coupled at every interval; nothing is cut.
"""

import math

import numba
import numpy as np

from .contact.law import force_between, moved_force, pair_constants
from .integrator import ACTIVE, advance_particle, GROUPS, STAT_REASON
from .model import STATE_SIZE
from .params import P_M
from .stop import stop_requested

__all__ = ['advance_coupled', 'COUPLING_STAT_WIDTH', 'CST_ACCEPTED', 'CST_FORCED',
           'CST_REJECTED']

jit = numba.njit(cache=True, error_model='numpy', nogil=True)
pjit = numba.njit(cache=True, error_model='numpy', nogil=True, parallel=True)

#: Step control of the coupling intervals (the position error is O(H^4)).
SAFETY = 0.9
FAC_MIN = 0.2
FAC_MAX = 4.0
ORDER = 4.0
#: Intervals shorter than this (s) are accepted whatever their estimate (counted as forced).
H_FLOOR = 1.0e-9
#: An interval never exceeds this many times 1/omega of a touching pair.
OMEGA_CAP = 1.0
#: A pair about to touch cuts the interval at its touch time, but not below this fraction
#: of the interval tried.
TOUCH_FRACTION = 0.125
TOUCH_CAP = True
#: Crowds of fewer pieces are advanced on one thread: starting a parallel region costs more
#: than it saves, and far more on a loaded machine (every interval starts one).
PARALLEL_PIECES = 16

# counters of one call (counters array, int64)
CST_ACCEPTED = 0   # coupling intervals accepted
CST_REJECTED = 1   # coupling intervals rejected (tried again shorter)
CST_FORCED = 2     # intervals accepted at H_FLOOR although their estimate was above tolerance
COUPLING_STAT_WIDTH = 3


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
def pair_forces(y, products, pairs, hist, status, inter, out):
    """Write each pair's force on its first piece (m, 3) (N); zero where a piece is gone."""
    for q in range(pairs.shape[0]):
        i = pairs[q, 0]
        j = pairs[q, 1]
        if status[i] != ACTIVE or status[j] != ACTIVE:
            out[q, 0] = out[q, 1] = out[q, 2] = 0.0
            continue
        f = force_between(y[i], y[j], hist[q, 0], hist[q, 1], hist[q, 2], products[i],
                          products[j], inter)
        out[q, 0] = f[0]
        out[q, 1] = f[1]
        out[q, 2] = f[2]


@jit
def predict(y, accel, products, pairs, hist, status, inter, h, out):
    """
    Write each pair's force at t + h, the law at the pair's extrapolated state (m, 3).

    Positions go by their velocities and accel (n, 3) (m/s^2), velocities by accel, the
    history by the extrapolated relative displacement (turned and capped at the end).
    """
    half = 0.5 * h * h
    for q in range(pairs.shape[0]):
        i = pairs[q, 0]
        j = pairs[q, 1]
        if status[i] != ACTIVE or status[j] != ACTIVE:
            out[q, 0] = out[q, 1] = out[q, 2] = 0.0
            continue
        a0 = accel[i, 0] - accel[j, 0]
        a1 = accel[i, 1] - accel[j, 1]
        a2 = accel[i, 2] - accel[j, 2]
        u0 = y[i, 3] - y[j, 3]
        u1 = y[i, 4] - y[j, 4]
        u2 = y[i, 5] - y[j, 5]
        e0 = u0 * h + a0 * half
        e1 = u1 * h + a1 * half
        e2 = u2 * h + a2 * half
        d0 = y[i, 0] - y[j, 0] + e0
        d1 = y[i, 1] - y[j, 1] + e1
        d2 = y[i, 2] - y[j, 2] + e2
        u0 += a0 * h
        u1 += a1 * h
        u2 += a2 * h
        f = moved_force(hist[q, 0], hist[q, 1], hist[q, 2], e0, e1, e2, d0, d1, d2, u0, u1,
                        u2, products[i], products[j], inter)
        out[q, 0] = f[3]
        out[q, 1] = f[4]
        out[q, 2] = f[5]


@jit
def correct(y0, y1, products, pairs, hist, status, inter, hist_out, out):
    """
    Write each pair's history and force at the interval's end from the states reached.

    y0, y1 (n, 9) the states at the start and the end; the relative displacement is the
    change of x_i - x_j. Pairs with a piece gone, or apart at the end, lose their history.
    """
    for q in range(pairs.shape[0]):
        i = pairs[q, 0]
        j = pairs[q, 1]
        if status[i] != ACTIVE or status[j] != ACTIVE:
            for a in range(3):
                hist_out[q, a] = 0.0
                out[q, a] = 0.0
            continue
        d0 = y1[i, 0] - y1[j, 0]
        d1 = y1[i, 1] - y1[j, 1]
        d2 = y1[i, 2] - y1[j, 2]
        u0 = y1[i, 3] - y1[j, 3]
        u1 = y1[i, 4] - y1[j, 4]
        u2 = y1[i, 5] - y1[j, 5]
        f = moved_force(hist[q, 0], hist[q, 1], hist[q, 2], d0 - (y0[i, 0] - y0[j, 0]),
                        d1 - (y0[i, 1] - y0[j, 1]), d2 - (y0[i, 2] - y0[j, 2]), d0, d1, d2,
                        u0, u1, u2, products[i], products[j], inter)
        for a in range(3):
            hist_out[q, a] = f[a]
            out[q, a] = f[3 + a]


@jit
def interval_cap(y, products, pairs, status, inter, h):
    """Return h cut to the contact time of the touching pairs and the touch of the others."""
    cap = h
    for q in range(pairs.shape[0]):
        i = pairs[q, 0]
        j = pairs[q, 1]
        if status[i] != ACTIVE or status[j] != ACTIVE:
            continue
        delta = force_between(y[i], y[j], 0.0, 0.0, 0.0, products[i], products[j], inter)[3]
        if delta > 0.0:
            r_star, m_star, y_star, _ = pair_constants(products[i], products[j])
            s_n = 2.0 * y_star * math.sqrt(r_star * delta)
            cap = min(cap, OMEGA_CAP * math.sqrt(m_star / s_n))
        else:
            d0 = y[i, 0] - y[j, 0]
            d1 = y[i, 1] - y[j, 1]
            d2 = y[i, 2] - y[j, 2]
            dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if dist == 0.0:
                continue
            closing = -((y[i, 3] - y[j, 3]) * d0 + (y[i, 4] - y[j, 4]) * d1
                        + (y[i, 5] - y[j, 5]) * d2) / dist
            if TOUCH_CAP and closing > 0.0 and -delta < closing * cap:
                cap = max(-delta / closing, TOUCH_FRACTION * cap)
    return cap


@jit
def piece_loads(products, start, pair, sign, begin, end, h, load, rate):
    """Sum each piece's pair loads (m/s^2): their value at the start, and their rate."""
    for p in range(load.shape[0]):
        mp = products[p, P_M]
        for a in range(3):
            b0 = 0.0
            b1 = 0.0
            for e in range(start[p], start[p + 1]):
                b0 += sign[e] * begin[pair[e], a]
                b1 += sign[e] * end[pair[e], a]
            load[p, a] = b0 / mp
            rate[p, a] = (b1 - b0) / (mp * h)


@jit
def impulse_error(products, status, start, pair, other, sign, begin, end, f_start, f_end, h):
    """
    Return the largest position error (m) of the interval over the ACTIVE pieces.

    A piece's velocity error is h/m sum ((L0 + L1) - (F(y0) + F(y1))) / 2 over its pairs
    whose other piece is still there; its position error is h times that.
    """
    worst = 0.0
    for p in range(status.shape[0]):
        if status[p] != ACTIVE:
            continue
        e0 = 0.0
        e1 = 0.0
        e2 = 0.0
        for e in range(start[p], start[p + 1]):
            if status[other[e]] != ACTIVE:
                continue
            q = pair[e]
            s = sign[e]
            e0 += s * (begin[q, 0] + end[q, 0] - f_start[q, 0] - f_end[q, 0])
            e1 += s * (begin[q, 1] + end[q, 1] - f_start[q, 1] - f_end[q, 1])
            e2 += s * (begin[q, 2] + end[q, 2] - f_start[q, 2] - f_end[q, 2])
        size = 0.5 * h * h / products[p, P_M] * math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        if not math.isfinite(size):
            return np.inf
        worst = max(worst, size)
    return worst


@jit
def advance_group(g, groups, y, products, machine, sub_t, sub_omega, sub_domega, r_exit, h_prop,
                  status, t_event, rtol, atol, h_min, h_max, h_kink, max_steps, stats, load,
                  rate, kink, stop):
    """Advance the ACTIVE pieces g, g + groups, ... over one interval with their loads."""
    n = STATE_SIZE
    work = np.empty((2, n, n))
    piv = np.empty((2, 3), dtype=np.int64)
    k = np.empty((n, n))
    y1 = np.empty(n)
    f0 = np.empty(n)
    for p in range(g, y.shape[0], groups):
        if status[p] != ACTIVE:
            continue
        hp = min(h_prop[p], h_kink) if kink else h_prop[p]
        st, t_ev, hp = advance_particle(y[p], products[p], machine, sub_t, sub_omega,
                                        sub_domega, r_exit, hp, rtol, atol, h_min, h_max,
                                        h_kink, max_steps, stats[p], work, piv, k, y1, f0,
                                        load[p], rate[p], stop)
        status[p] = st
        t_event[p] = t_ev
        h_prop[p] = hp


@pjit
def advance_pieces(y, products, machine, sub_t, sub_omega, sub_domega, r_exit, h_prop, status,
                   t_event, rtol, atol, h_min, h_max, h_kink, max_steps, stats, load, rate,
                   kink, stop):
    """
    Advance every ACTIVE piece over one interval on numba's threads (:func:`advance_group`).

    The only parallel region of an interval: pieces are independent inside it, so the result
    does not depend on the thread count.
    """
    groups = min(y.shape[0], GROUPS)
    for g in numba.prange(groups):
        advance_group(g, groups, y, products, machine, sub_t, sub_omega, sub_domega, r_exit,
                      h_prop, status, t_event, rtol, atol, h_min, h_max, h_kink, max_steps,
                      stats, load, rate, kink, stop)


@jit
def advance_coupled(y, products, pairs, hist, inter, machine, seg_t, seg_omega, seg_domega,
                    r_exit, h_prop, status, t_event, rtol, atol, h_min, h_max, h_kink,
                    max_steps, stats, h_coupling, tolerance, counters, stop):
    """
    Advance pieces that touch over seg_t[0]..seg_t[-1] by multirate coupling; return H.

    y (n, 9) cone-axes states, products (n, W), pairs (m, 2) int64 local indices i < j,
    hist (m, 3) their histories (m, cone axes), inter the law's row; h_prop (n,), status
    (n,), t_event (n,), stats (n, STAT_WIDTH) as in :func:`integrator.advance_batch`; all
    updated in place. h_coupling (s) the proposed first coupling interval; tolerance (m)
    the largest position error one interval may give a piece; counters
    (COUPLING_STAT_WIDTH,) int64. Pieces that exit or fail inside an interval leave the
    coupling at their time, their pairs (and histories) with them. stop (1,) int64: when
    set (:mod:`.stop`), the call returns at the next step of a piece, the interval unfinished.
    Returns the proposed next coupling interval (s).
    """
    n = y.shape[0]
    m = pairs.shape[0]
    start, pair, other, sign = adjacency(n, pairs)
    f_start = np.empty((m, 3))
    f_end = np.empty((m, 3))
    begin = np.empty((m, 3))
    end = np.empty((m, 3))
    hist_end = np.empty((m, 3))
    load = np.empty((n, 3))
    rate = np.empty((n, 3))
    accel = np.zeros((n, 3))
    y_save = np.empty_like(y)
    h_save = np.empty_like(h_prop)
    status_save = np.empty_like(status)
    event_save = np.empty_like(t_event)
    reason_save = np.empty(n, dtype=np.int64)
    n_seg = seg_omega.shape[0]
    sub_t = np.empty(n_seg + 1)
    sub_omega = np.empty(n_seg)
    sub_domega = np.empty(n_seg)
    t = seg_t[0]
    t1 = seg_t[n_seg]
    h = h_coupling
    pair_forces(y, products, pairs, hist, status, inter, f_start)
    begin[:] = f_start  # the loads start from the pair forces, and stay continuous
    rejected = False
    while t < t1:
        if stop_requested(stop):
            return h
        remaining = t1 - t
        hc = interval_cap(y, products, pairs, status, inter, min(h, remaining))
        hc = max(hc, min(H_FLOOR, remaining))
        truncated = hc >= remaining
        t_end = t1 if truncated else t + hc
        s = segment_index(seg_t, t)
        kink = s > 0 and t == seg_t[s] and seg_domega[s] != seg_domega[s - 1]
        predict(y, accel, products, pairs, hist, status, inter, hc, end)
        piece_loads(products, start, pair, sign, begin, end, hc, load, rate)
        y_save[:] = y
        h_save[:] = h_prop
        status_save[:] = status
        event_save[:] = t_event
        for p in range(n):
            reason_save[p] = stats[p, STAT_REASON]
        c = sub_segments(seg_t, seg_omega, seg_domega, t, t_end, sub_t, sub_omega, sub_domega)
        if n >= PARALLEL_PIECES:
            advance_pieces(y, products, machine, sub_t[:c + 1], sub_omega[:c],
                           sub_domega[:c], r_exit, h_prop, status, t_event, rtol, atol, h_min,
                           h_max, h_kink, max_steps, stats, load, rate, kink, stop)
        else:
            advance_group(0, 1, y, products, machine, sub_t[:c + 1], sub_omega[:c],
                          sub_domega[:c], r_exit, h_prop, status, t_event, rtol, atol, h_min,
                          h_max, h_kink, max_steps, stats, load, rate, kink, stop)
        if stop_requested(stop):
            return h
        correct(y_save, y, products, pairs, hist, status, inter, hist_end, f_end)
        err = impulse_error(products, status, start, pair, other, sign, begin, end, f_start,
                            f_end, hc)
        ratio = err / tolerance
        if not (ratio <= 1.0) and hc > H_FLOOR:
            counters[CST_REJECTED] += 1
            y[:] = y_save
            h_prop[:] = h_save
            status[:] = status_save
            t_event[:] = event_save
            for p in range(n):
                stats[p, STAT_REASON] = reason_save[p]
            fac = SAFETY * ratio ** (-1.0 / ORDER) if math.isfinite(ratio) else FAC_MIN
            h = max(hc * min(FAC_MIN if rejected else 1.0, max(FAC_MIN, fac)), H_FLOOR)
            rejected = True
            continue
        if not (ratio <= 1.0):
            counters[CST_FORCED] += 1
        counters[CST_ACCEPTED] += 1
        grow = FAC_MAX if ratio == 0.0 else min(
            FAC_MAX, max(FAC_MIN, SAFETY * ratio ** (-1.0 / ORDER)))
        if rejected:
            grow = min(grow, 1.0)
        h_next = min(h_max, hc * grow)
        h = max(h, h_next) if truncated else h_next
        h = min(h, h_max)
        rejected = False
        inv = 1.0 / (t_end - t)
        for p in range(n):
            for a in range(3):
                accel[p, a] = (y[p, 3 + a] - y_save[p, 3 + a]) * inv
        t = t_end
        f_start[:] = f_end
        begin[:] = end
        hist[:] = hist_end
    return h
