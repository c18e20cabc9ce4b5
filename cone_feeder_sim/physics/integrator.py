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
Adaptive integration of every particle over one interval, with exit location.

The pieces are independent in the paper's model, so each particle is advanced with its own
step size by :func:`advance_particle`; :func:`advance_batch` loops over the particles. The
step control (error norm, step-size proposal) is separate from the method
(:mod:`cone_feeder_sim.physics.rosenbrock`) and from the vector field
(:mod:`cone_feeder_sim.physics.model`).

The rotation input over the interval is a list of segments of constant angular
acceleration: seg_t (K+1,) breakpoints (s), seg_omega (K,) angular velocity at the start of
each segment (rad/s), seg_domega (K,) angular acceleration in it (rad/s^2). Steps never
cross a breakpoint.

A failed step is a result: the particle gets status FAILED and the others carry on. A stop
request (``stop`` (1,) int64 set to 1 from another thread, :mod:`.stop`) is read before
every step: the particle gets status STOPPED and the interval is left unfinished.
"""

import math

import numba
import numpy as np

from .model import STATE_SIZE
from .rosenbrock import add_load, ERROR_ORDER, prepare_step, rodas_step
from .stop import stop_requested

jit = numba.njit(cache=True, error_model='numpy', nogil=True)

ACTIVE = 0
EXITED = 1
FAILED = 2
STOPPED = 3  # a stop was requested (stop[0] != 0) before the interval was done

# failure reasons (stored in stats[:, STAT_REASON]; 0: none)
REASON_STEP_UNDERFLOW = 1
REASON_TOO_MANY_STEPS = 2
REASON_NOT_FINITE = 3

STAT_ACCEPTED = 0
STAT_REJECTED = 1
STAT_REASON = 2
STAT_WIDTH = 3

SAFETY = 0.9
FAC_MIN = 0.2
FAC_MAX = 6.0
BISECTION_STEPS = 60
#: the least error the predictive controller remembers of an accepted step (rodas.f: ERRACC)
ERROR_FLOOR = 1e-2


@jit
def error_norm(err, y0, y1, rtol, atol):
    """Return the RMS of err scaled by atol + rtol*max(|y0|, |y1|), component by component."""
    n = err.shape[0]
    acc = 0.0
    for i in range(n):
        sc = atol[i] + rtol * max(abs(y0[i]), abs(y1[i]))
        e = err[i] / sc
        acc += e * e
    return math.sqrt(acc / n)


@jit
def step_factor(err, order):
    """
    Return the factor for the next step size given the scaled error norm of this step.

    order: that of the embedded error estimate (the error is O(h^(order + 1))).
    """
    if err == 0.0:
        return FAC_MAX
    fac = SAFETY * err ** (-1.0 / (order + 1))
    return min(FAC_MAX, max(FAC_MIN, fac))


@jit
def proposal_after_rejection(h, err, repeated, order=ERROR_ORDER):
    """Return the next trial step (s) after a step of h (s) was rejected with error err."""
    if math.isfinite(err):
        h_prop = h * max(FAC_MIN, SAFETY * err ** (-1.0 / (order + 1)))
    else:
        h_prop = h * FAC_MIN
    if repeated:  # repeated rejection: the error model does not hold, cut hard
        h_prop = min(h_prop, h * FAC_MIN)
    return h_prop


@jit
def growth_after_acceptance(h, err, h_acc, err_acc, after_rejection, order):
    """
    Return the factor for the next step after an accepted step h (s) with error err.

    Predictive (Gustafsson) control: h_acc and err_acc are the previous accepted step and
    its error (h_acc 0: none yet); no growth right after a rejection.
    """
    grow = step_factor(err, order)
    if h_acc > 0.0 and err > 0.0:
        # also use the error trend of the last two accepted steps
        pred = SAFETY * (h / h_acc) * (err_acc / (err * err)) ** (1.0 / (order + 1))
        grow = min(grow, max(FAC_MIN, min(FAC_MAX, pred)))
    if after_rejection:
        grow = min(grow, 1.0)
    return grow


@jit
def after_acceptance(t, t_end, h, h_prop, h_max, err, h_acc, err_acc, after_rejection,
                     truncated, order=ERROR_ORDER):
    """
    Return (t, h_prop, h_acc, err_acc) after an accepted step h (s) from t with error err.

    A step truncated at the segment end t_end lands there and keeps the larger of the
    proposal it replaced and the grown step; the previous accepted step and error become
    this one's (the error floored at ERROR_FLOOR, as rodas.f has it).
    """
    grow = growth_after_acceptance(h, err, h_acc, err_acc, after_rejection, order)
    if truncated:
        return t_end, min(h_max, max(h_prop, h * grow)), h, max(err, ERROR_FLOOR)
    return t + h, min(h_max, h * grow), h, max(err, ERROR_FLOOR)


@jit
def hermite_position(theta, h, xa, wa, xb, wb, i):
    """Return component i of the cubic Hermite interpolant of positions at fraction theta."""
    t2 = theta * theta
    t3 = t2 * theta
    return ((2.0 * t3 - 3.0 * t2 + 1.0) * xa[i] + (t3 - 2.0 * t2 + theta) * h * wa[i]
            + (-2.0 * t3 + 3.0 * t2) * xb[i] + (t3 - t2) * h * wb[i])


@jit
def locate_exit(h, ya, yb, r_exit):
    """
    Return theta in (0, 1] where the radius of the interpolated path first reaches r_exit.

    ya, yb: states at the start and end of an accepted step, with radius(ya) < r_exit <=
    radius(yb). Positions are interpolated by the cubic Hermite polynomial through positions
    and velocities (dx/dt = w in cone axes), accurate to O(h^4); the root is bracketed.
    """
    xa = ya[0:3]
    wa = ya[3:6]
    xb = yb[0:3]
    wb = yb[3:6]
    lo = 0.0
    hi = 1.0
    r2 = r_exit * r_exit
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        px = hermite_position(mid, h, xa, wa, xb, wb, 0)
        py = hermite_position(mid, h, xa, wa, xb, wb, 1)
        if px * px + py * py >= r2:
            hi = mid
        else:
            lo = mid
    return hi


@jit
def advance_particle(y, product, machine, seg_t, seg_omega, seg_domega, r_exit, h_prop, rtol,
                     atol, h_min, h_max, h_kink, max_steps, stats, work, piv, k, y1, f0, load,
                     rate, stop):
    """
    Advance one particle through all segments, or until it exits or fails.

    y (9,) is updated in place (cone axes). h_prop is the proposed first step (s); after a
    jump of the angular acceleration (a kink of omega) the step restarts from at most
    h_kink, since the jump excites fast friction transients. No step is longer than h_max:
    a transition from sticking to slipping can start inside a long step without the
    embedded error estimate noticing it. Step sizes follow the
    predictive (Gustafsson) controller of Hairer and Wanner's RODAS. load (3,) (m/s^2) is an
    acceleration added to the field at seg_t[0], changing at rate (3,) (m/s^3) (zeros for
    a piece alone; the pair forces over a coupling interval, :mod:`coupling`).
    Returns (status, t_end_or_exit, h_prop): status ACTIVE when the interval was completed,
    EXITED with the exit time (y then holds the state at the exit), FAILED with the time
    reached (y holds the last accepted state; stats[STAT_REASON] tells why), or STOPPED with
    the time reached when stop[0] was set before a step.
    """
    n_seg = seg_omega.shape[0]
    steps = 0
    t = seg_t[0]
    load_now = np.empty(3)
    h_acc = 0.0  # last accepted step and its error, for the predictive controller
    err_acc = 1.0
    for s in range(n_seg):
        t_seg = seg_t[s]
        t_end = seg_t[s + 1]
        omega_s = seg_omega[s]
        domega = seg_domega[s]
        if s > 0 and domega != seg_domega[s - 1]:
            h_prop = min(h_prop, h_kink)
        fresh = True  # f0 and the Jacobian must be evaluated at the current y
        rejected = False
        while t < t_end:
            if stop_requested(stop):
                return STOPPED, t, h_prop
            remaining = t_end - t
            truncated = h_prop >= remaining
            h = remaining if truncated else h_prop
            omega0 = omega_s + domega * (t - t_seg)
            if fresh:
                prepare_step(y, omega0, domega, product, machine, work, k, f0)
                for a in range(3):
                    load_now[a] = load[a] + rate[a] * (t - seg_t[0])
                add_load(load_now, rate, 0.0, f0)
                for a in range(3):
                    k[7, 3 + a] += rate[a]
                fresh = False
            ok = rodas_step(y, f0, h, omega0, domega, product, machine, load_now, rate, work,
                            piv, k, y1)
            err = error_norm(k[5], y, y1, rtol, atol) if ok else np.inf
            steps += 1
            if steps > max_steps:
                stats[STAT_REASON] = REASON_TOO_MANY_STEPS
                return FAILED, t, h_prop
            if not (err <= 1.0):
                stats[STAT_REJECTED] += 1
                h_prop = proposal_after_rejection(h, err, rejected)
                rejected = True
                if h_prop < h_min:
                    stats[STAT_REASON] = (REASON_NOT_FINITE if not math.isfinite(err)
                                          else REASON_STEP_UNDERFLOW)
                    return FAILED, t, h_prop
                continue
            stats[STAT_ACCEPTED] += 1
            if y1[0] * y1[0] + y1[1] * y1[1] >= r_exit * r_exit:
                theta = locate_exit(h, y, y1, r_exit)
                h_exit = theta * h
                ok = rodas_step(y, f0, h_exit, omega0, domega, product, machine, load_now,
                                rate, work, piv, k, y1)
                if not ok:
                    stats[STAT_REASON] = REASON_NOT_FINITE
                    return FAILED, t, h_prop
                for i in range(y.shape[0]):
                    y[i] = y1[i]
                return EXITED, t + h_exit, h_prop
            for i in range(y.shape[0]):
                y[i] = y1[i]
            fresh = True
            t, h_prop, h_acc, err_acc = after_acceptance(t, t_end, h, h_prop, h_max, err,
                                                         h_acc, err_acc, rejected, truncated)
            rejected = False
    return ACTIVE, t, h_prop


def set_threads(count: int) -> int:
    """
    Set the threads that integrate pieces (0: every core numba found); return the count.

    Results do not depend on it. Raises ValueError beyond the cores numba found.
    """
    available = numba.config.NUMBA_NUM_THREADS
    if count < 0 or count > available:
        raise ValueError(f'threads must be 0 (all) or 1..{available}, got {count}')
    numba.set_num_threads(count or available)
    return numba.get_num_threads()


#: Pieces are integrated in this many independent groups (piece p in group p % GROUPS), each
#: with its own scratch arrays; the groups run on numba's threads with the GIL released (a ROS
#: executor keeps running beside a tick). The result of every piece depends on nothing but
#: its own data, so it is the same for any thread count.
GROUPS = 64


@numba.njit(cache=True, error_model='numpy', parallel=True, nogil=True)
def advance_batch(y, products, machine, seg_t, seg_omega, seg_domega, r_exit, h_prop, status,
                  t_event, rtol, atol, h_min, h_max, h_kink, max_steps, stats, stop):
    """
    Advance every ACTIVE particle over the interval seg_t[0]..seg_t[-1], on all threads.

    y (N, 9) cone-axes states, products (N, PRODUCT_WIDTH) product rows, machine the global
    row, h_prop (N,) proposed step sizes, status (N,) int64, t_event (N,) receives exit or
    failure times, atol (9,), stats (N, STAT_WIDTH) int64 counters, stop (1,) int64 the stop
    request (:mod:`.stop`). Arrays are updated in place. The thread count is numba's
    (``numba.set_num_threads``); results do not depend on it.
    """
    n = STATE_SIZE
    count = y.shape[0]
    groups = min(count, GROUPS)
    for g in numba.prange(groups):
        work = np.empty((2, n, n))
        piv = np.empty((2, 3), dtype=np.int64)
        k = np.empty((n, n))
        y1 = np.empty(n)
        f0 = np.empty(n)
        load = np.zeros(3)
        for p in range(g, count, groups):
            if status[p] != ACTIVE:
                continue
            st, t_ev, hp = advance_particle(y[p], products[p], machine, seg_t, seg_omega,
                                            seg_domega, r_exit, h_prop[p], rtol, atol, h_min,
                                            h_max, h_kink, max_steps, stats[p], work, piv, k,
                                            y1, f0, load, load, stop)
            status[p] = st
            t_event[p] = t_ev
            h_prop[p] = hp


@numba.njit(cache=True, error_model='numpy', parallel=True, nogil=True)
def advance_batch_owned(y, products, machine, owner, seg_t, seg_omega, seg_domega, seg_count,
                        r_exit, h_prop, status, t_event, rtol, atol, h_min, h_max, h_kink,
                        max_steps, stats, stop):
    """
    Advance the pieces of several feeders, each under its own rotation, in one call.

    As :func:`advance_batch`, with owner (N,) int64 the feeder of each piece and the
    segments of feeder f in row f: seg_t (F, S + 1), seg_omega and seg_domega (F, S),
    seg_count (F,) how many of the S are used. A piece gets exactly the computation it gets
    in :func:`advance_batch` with its feeder's segments, so the results are the same.
    """
    n = STATE_SIZE
    count = y.shape[0]
    groups = min(count, GROUPS)
    for g in numba.prange(groups):
        work = np.empty((2, n, n))
        piv = np.empty((2, 3), dtype=np.int64)
        k = np.empty((n, n))
        y1 = np.empty(n)
        f0 = np.empty(n)
        load = np.zeros(3)
        for p in range(g, count, groups):
            if status[p] != ACTIVE:
                continue
            o = owner[p]
            m = seg_count[o]
            st, t_ev, hp = advance_particle(y[p], products[p], machine, seg_t[o, :m + 1],
                                            seg_omega[o, :m], seg_domega[o, :m], r_exit,
                                            h_prop[p], rtol, atol, h_min, h_max, h_kink,
                                            max_steps, stats[p], work, piv, k, y1, f0, load,
                                            load, stop)
            status[p] = st
            t_event[p] = t_ev
            h_prop[p] = hp
