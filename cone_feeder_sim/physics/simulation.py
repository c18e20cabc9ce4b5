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
Simulation state over many particles and the pure function that advances it.

:class:`SimState` holds the changing state as arrays over N particles; :class:`SimParams` holds
the immutable parameters (validated once). :func:`advance` is pure: it returns a new state
and the events of the interval, and never mutates its inputs. :class:`Simulator` is a small
mutable convenience wrapper used by the headless runner and the ROS node.

Positions and velocities at this interface are in the world frame (z up, origin at the
centre of the cone base); the integrator works in cone axes (see cone_feeder_sim.physics.model).
"""

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
import math

import numpy as np

from .band import band_order
from .coupling import (
    advance_coupled, COUPLING_STAT_WIDTH, CST_ACCEPTED, CST_FORCED, CST_REJECTED)
from .integrator import (
    ACTIVE, advance_batch, advance_batch_owned, EXITED, FAILED, REASON_NOT_FINITE,
    REASON_STEP_UNDERFLOW, REASON_TOO_MANY_STEPS, STAT_ACCEPTED, STAT_REASON, STAT_REJECTED,
    STAT_WIDTH)
from .islands import advance_island, islands_of
from .model import STATE_SIZE
from .neighbours import contact_pairs
from .params import (
    ModelParams, P_M, P_R_A, P_S0, P_SC_RATIO, product_row, PRODUCT_WIDTH, ProductParams,
    SolverParams)
from .rotation import rotate_z, RotationProfile
from ..errors import ScenarioError

FAILURE_REASONS = {
    REASON_STEP_UNDERFLOW: 'step size fell below h_min',
    REASON_TOO_MANY_STEPS: 'more than max_steps steps in one interval',
    REASON_NOT_FINITE: 'the state or its derivatives became non-finite',
}


@dataclass(frozen=True)
class SimParams:
    """Immutable parameters of a run, with the kernel arrays derived from them once."""

    model: ModelParams = ModelParams()
    solver: SolverParams = SolverParams()
    global_row: np.ndarray = field(init=False, repr=False)
    atol: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Derive the kernel arrays."""
        machine = self.model.global_row()
        atol = self.solver.atol_row()
        machine.setflags(write=False)
        atol.setflags(write=False)
        object.__setattr__(self, 'global_row', machine)
        object.__setattr__(self, 'atol', atol)


@dataclass(frozen=True)
class SimState:
    """
    State of all particles at time t.

    t (s); angle (rad) the cone angle phi(t); y (N, 9) [x (m), w (m/s), P (N)] in cone axes;
    products (N, PRODUCT_WIDTH) product rows; ids (N,) int64 unique particle ids;
    step_size (N,) proposed next step sizes (s); next_id the id the next new particle gets;
    coupling_step (s) the proposed next coupling interval of pieces that touch (multirate
    coupling; 0: none yet, the solver's h_init).
    """

    t: float = 0.0
    angle: float = 0.0
    y: np.ndarray = field(default_factory=lambda: np.zeros((0, STATE_SIZE)))
    products: np.ndarray = field(default_factory=lambda: np.zeros((0, PRODUCT_WIDTH)))
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    step_size: np.ndarray = field(default_factory=lambda: np.zeros(0))
    next_id: int = 0
    coupling_step: float = 0.0

    @property
    def count(self) -> int:
        """Return the number of particles on the cone."""
        return int(self.ids.shape[0])


@dataclass(frozen=True)
class ExitEvents:
    """
    Pieces that left the cone during an interval, one entry per piece.

    ids (M,); t (M,) exit times (s); angle_deg (M,) atan2(y, x) in [0, 360); channel (M,)
    1-based; position (M, 3) (m) and velocity (M, 3) (m/s) in the world frame at the exit;
    mass (M,) (kg).
    """

    ids: np.ndarray
    t: np.ndarray
    angle_deg: np.ndarray
    channel: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    mass: np.ndarray

    def __len__(self) -> int:
        """Return the number of exits."""
        return int(self.ids.shape[0])


@dataclass(frozen=True)
class Failure:
    """
    A piece whose integration failed and which was removed.

    t (s) the time of the failure; reason: one of FAILURE_REASONS; position (m) and
    velocity (m/s) in the world frame at t (NaN where the state was no longer finite);
    mass (kg).
    """

    particle_id: int
    t: float
    reason: str
    position: tuple[float, float, float]
    velocity: tuple[float, float, float]
    mass: float


@dataclass(frozen=True)
class StepStats:
    """
    Solver statistics of one interval: accepted and rejected steps over all particles.

    largest_island: pieces in the largest contact island of the interval (0 without
    contact), before any cut. An island takes the steps its most demanding piece needs, so
    this is what makes a crowded interval expensive. pairs_left_out: pairs within reach
    that were left out because their island was larger than
    ``InteractionParams.max_island`` and was cut into parts (exact coupling only).
    coupling_intervals, coupling_rejected: the multirate coupling's accepted and rejected
    intervals; coupling_forced: intervals accepted at the shortest interval although their
    error estimate was above the tolerance (:mod:`coupling`).
    """

    accepted: int
    rejected: int
    particles: int
    largest_island: int = 0
    pairs_left_out: int = 0
    coupling_intervals: int = 0
    coupling_rejected: int = 0
    coupling_forced: int = 0


@dataclass(frozen=True)
class StepResult:
    """What :func:`advance` returns."""

    state: SimState
    exits: ExitEvents
    failures: tuple[Failure, ...]
    stats: StepStats


def world_from_cone(y: np.ndarray, angle: float, omega: float) -> tuple[np.ndarray, ...]:
    """
    Convert cone-axes states (N, 9) to world position, velocity and filter force.

    Returns q (N, 3) (m), qdot (N, 3) (m/s), Q_d (N, 3) (N): q = R(angle) x,
    qdot = R(angle)(w + omega z x x), Q_d = R(angle) P.
    """
    x = y[:, 0:3]
    w = y[:, 3:6].copy()
    w[:, 0] -= omega * x[:, 1]
    w[:, 1] += omega * x[:, 0]
    return rotate_z(x, angle), rotate_z(w, angle), rotate_z(y[:, 6:9], angle)


def cone_from_world(q: np.ndarray, qdot: np.ndarray, q_d: np.ndarray, angle: float,
                    omega: float) -> np.ndarray:
    """Inverse of :func:`world_from_cone`: return cone-axes states (N, 9)."""
    x = rotate_z(q, -angle)
    v = rotate_z(qdot, -angle)
    v[:, 0] += omega * x[:, 1]
    v[:, 1] -= omega * x[:, 0]
    return np.hstack([x, v, rotate_z(q_d, -angle)])


def as_points(name: str, values: object, count: int | None = None) -> np.ndarray:
    """
    Return values as a finite (M, 3) float64 array, or raise ScenarioError naming them.

    A single point of shape (3,) is accepted as (1, 3); count, if given, is the required M.
    """
    try:
        arr = np.array(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ScenarioError(f'{name} must be numbers of shape (M, 3): {exc}') from exc
    if arr.ndim == 1 and arr.shape[0] == 3:
        arr = arr.reshape(1, 3)
    if arr.ndim != 2 or arr.shape[1] != 3 or (count is not None and arr.shape[0] != count):
        want = f'({count}, 3)' if count is not None else '(M, 3)'
        raise ScenarioError(f'{name} must have shape {want}, got {arr.shape}')
    bad = ~np.all(np.isfinite(arr), axis=1)
    if np.any(bad):
        i = int(np.argmax(bad))
        raise ScenarioError(f'{name}[{i}] is not finite: {arr[i].tolist()}')
    return arr


def position_problems(model: ModelParams, positions: np.ndarray,
                      max_height: float = math.inf) -> tuple[np.ndarray, list[str]]:
    """
    Check start positions (M, 3) (m), vectorised; return the mask of valid ones and why not.

    A position is refused when it is not finite, outside the cone (rho >= r), with the
    centre below the cone surface, or above ``max_height`` (m). The reasons name the index
    of each refused position, in order.
    """
    with np.errstate(invalid='ignore'):
        finite = np.all(np.isfinite(positions), axis=1)
        rho = np.hypot(positions[:, 0], positions[:, 1])
        surface = model.h * (1.0 - rho / model.r)
        outside = finite & (rho >= model.r)
        below = finite & ~outside & (positions[:, 2] < surface)
        above = finite & ~outside & ~below & (positions[:, 2] > max_height)
    valid = finite & ~outside & ~below & ~above
    reasons = []
    for i in np.flatnonzero(~valid):
        where = f'position[{i}] {positions[i].tolist()}'
        if not finite[i]:
            reasons.append(f'{where} is not finite')
        elif outside[i]:
            reasons.append(f'{where} is outside the cone: radius {rho[i]:.4f} m >= r = '
                           f'{model.r:.4f} m')
        elif below[i]:
            reasons.append(f'{where} is below the cone surface (z = {surface[i]:.4f} m '
                           'there)')
        else:
            reasons.append(f'{where} is above the highest start {max_height:g} m')
    return valid, reasons


def check_positions(model: ModelParams, positions: np.ndarray,
                    max_height: float = math.inf) -> None:
    """Refuse positions outside the cone, below its surface or above max_height (m)."""
    valid, reasons = position_problems(model, positions, max_height)
    if reasons:
        raise ScenarioError(reasons[0])


def add_particles(state: SimState, params: SimParams, positions: object,
                  velocities: object | None = None,
                  products: Sequence[ProductParams] | None = None,
                  omega: float = 0.0) -> tuple[SimState, np.ndarray]:
    """
    Return a new state with particles added at time state.t, and their ids.

    positions (M, 3) (m) world frame; velocities (M, 3) (m/s) world frame or None for
    pieces lying on the feeder and moving with it (qdot = omega z x q); products: one
    ProductParams per piece or None for the default product of params.model; omega (rad/s)
    the cone's angular velocity at state.t. The filter force starts at zero.
    """
    q = as_points('position', positions)
    count = q.shape[0]
    check_positions(params.model, q)
    if velocities is None:
        qdot = np.zeros_like(q)
        qdot[:, 0] = -omega * q[:, 1]
        qdot[:, 1] = omega * q[:, 0]
    else:
        qdot = as_points('velocity', velocities, count)
    if products is None:
        rows = np.tile(product_row(params.model.product), (count, 1))
    else:
        if len(products) != count:
            raise ScenarioError(f'{len(products)} products given for {count} positions')
        rows = np.array([product_row(p) for p in products]).reshape(count, PRODUCT_WIDTH)
    y_new = cone_from_world(q, qdot, np.zeros_like(q), state.angle, omega)
    ids = np.arange(state.next_id, state.next_id + count, dtype=np.int64)
    new = replace(
        state,
        y=np.vstack([state.y, y_new]),
        products=np.vstack([state.products, rows]),
        ids=np.concatenate([state.ids, ids]),
        step_size=np.concatenate([state.step_size, np.full(count, params.solver.h_init)]),
        next_id=state.next_id + count)
    return new, ids


def remove_particles(state: SimState, ids: object) -> SimState:
    """Return a new state without the particles whose ids are given."""
    keep = ~np.isin(state.ids, np.asarray(ids, dtype=np.int64))
    return replace(state, y=state.y[keep], products=state.products[keep],
                   ids=state.ids[keep], step_size=state.step_size[keep])


def advance(state: SimState, params: SimParams, profile: RotationProfile,
            t1: float) -> StepResult:
    """
    Advance every particle from state.t to t1 under the rotation profile.

    Pieces that cross the cone edge are located inside the step, reported in the result's
    exits and removed; pieces whose integration fails are reported and removed; the others
    carry on. The inputs are not modified.
    """
    seg_t, seg_omega, seg_domega = profile.segments(state.t, t1)
    work = _Work(state)
    solver = params.solver
    interactions = params.model.interactions
    n = state.count
    if interactions.enabled and n > 1 and interactions.coupling == 'multirate':
        work.largest_island, work.coupling_step = _advance_multirate(
            state, params, profile, t1, work.y, work.step_size, work.status, work.t_event,
            work.stats, work.counters)
    elif interactions.enabled and n > 1:
        work.largest_island, work.left_out = _advance_with_contacts(
            state, params, profile, t1, work.y, work.step_size, work.status, work.t_event,
            work.stats)
    elif n:
        advance_batch(work.y, state.products, params.global_row, seg_t, seg_omega, seg_domega,
                      params.model.r, work.step_size, work.status, work.t_event, solver.rtol,
                      params.atol, solver.h_min, solver.h_max, solver.h_init,
                      solver.max_steps, work.stats)
    return _result(state, params, profile, t1, work)


def advance_many(states: Sequence[SimState], params: SimParams,
                 profiles: Sequence[RotationProfile], t1: Sequence[float]) -> list[StepResult]:
    """
    Advance several independent feeders (same parameters, each its own rotation) at once.

    Without contact between pieces, the pieces of every feeder go to one compiled call
    (:func:`~cone_feeder_sim.physics.integrator.advance_batch_owned`) that spreads them over
    the cores; with contact each feeder is advanced by :func:`advance` in turn. Each result
    is what :func:`advance` gives for that feeder alone, bit for bit.
    """
    if not len(states) == len(profiles) == len(t1):
        raise ValueError(f'{len(states)} states, {len(profiles)} profiles and {len(t1)} ends')
    if params.model.interactions.enabled:
        return [advance(s, params, p, t) for s, p, t in zip(states, profiles, t1)]
    segments = [p.segments(s.t, t) for s, p, t in zip(states, profiles, t1)]
    width = max(len(omega) for _, omega, _ in segments)
    seg_t = np.zeros((len(states), width + 1))
    seg_omega = np.zeros((len(states), width))
    seg_domega = np.zeros((len(states), width))
    seg_count = np.zeros(len(states), dtype=np.int64)
    for f, (times, omega, domega) in enumerate(segments):
        seg_count[f] = len(omega)
        seg_t[f, :len(times)] = times
        seg_omega[f, :len(omega)] = omega
        seg_domega[f, :len(domega)] = domega
    works = [_Work(s) for s in states]
    counts = [s.count for s in states]
    if sum(counts):
        solver = params.solver
        owner = np.repeat(np.arange(len(states), dtype=np.int64), counts)
        y = np.concatenate([w.y for w in works])
        step_size = np.concatenate([w.step_size for w in works])
        status = np.concatenate([w.status for w in works])
        t_event = np.concatenate([w.t_event for w in works])
        stats = np.concatenate([w.stats for w in works])
        products = np.concatenate([s.products for s in states])
        advance_batch_owned(y, products, params.global_row, owner, seg_t, seg_omega,
                            seg_domega, seg_count, params.model.r, step_size, status, t_event,
                            solver.rtol, params.atol, solver.h_min, solver.h_max,
                            solver.h_init, solver.max_steps, stats)
        bounds = np.cumsum([0] + counts)
        for w, a, b in zip(works, bounds[:-1], bounds[1:]):
            w.y, w.step_size, w.status = y[a:b], step_size[a:b], status[a:b]
            w.t_event, w.stats = t_event[a:b], stats[a:b]
    return [_result(s, params, p, t, w) for s, p, t, w in zip(states, profiles, t1, works)]


class _Work:
    """The arrays one advance updates in place: copies of a state's, and the counters."""

    def __init__(self, state: SimState) -> None:
        n = state.count
        self.y = state.y.copy()
        self.step_size = state.step_size.copy()
        self.status = np.full(n, ACTIVE, dtype=np.int64)
        self.t_event = np.zeros(n)
        self.stats = np.zeros((n, STAT_WIDTH), dtype=np.int64)
        self.counters = np.zeros(COUPLING_STAT_WIDTH, dtype=np.int64)
        self.largest_island = 0
        self.left_out = 0
        self.coupling_step = state.coupling_step


def _result(state: SimState, params: SimParams, profile: RotationProfile, t1: float,
            work: _Work) -> StepResult:
    """Return the step's result: exits and failures located, the pieces that left removed."""
    y, status, t_event, stats, counters = (work.y, work.status, work.t_event, work.stats,
                                           work.counters)
    exits = _exit_events(state, params, profile, y, status, t_event)
    failures = tuple(_failure(state, profile, y, i, float(t_event[i]),
                              FAILURE_REASONS.get(int(stats[i, STAT_REASON]), 'unknown'))
                     for i in np.flatnonzero(status == FAILED))
    keep = status == ACTIVE
    new_state = replace(state, t=float(t1), angle=state.angle + profile.integral(state.t, t1),
                        y=y[keep], products=state.products[keep], ids=state.ids[keep],
                        step_size=work.step_size[keep], coupling_step=work.coupling_step)
    step_stats = StepStats(accepted=int(stats[:, STAT_ACCEPTED].sum()),
                           rejected=int(stats[:, STAT_REJECTED].sum()), particles=state.count,
                           largest_island=work.largest_island, pairs_left_out=work.left_out,
                           coupling_intervals=int(counters[CST_ACCEPTED]),
                           coupling_rejected=int(counters[CST_REJECTED]),
                           coupling_forced=int(counters[CST_FORCED]))
    return StepResult(state=new_state, exits=exits, failures=failures, stats=step_stats)


#: The pair force is below this fraction of r_f beyond the contact reach (activation 1e-6).
CONTACT_CUTOFF_ACTIVATION = 1.0e-6


def contact_reach(products: np.ndarray) -> np.ndarray:
    """
    Return each piece's contact reach (m), shape (N,), from its product rows (N, W).

    Two like pieces interact within the sum of their reaches: the centre distance where
    the pair's activation falls to CONTACT_CUTOFF_ACTIVATION; beyond it the pair force is
    below 1e-6 r_f and the pair is left out.
    """
    s0 = products[:, P_S0]
    s_c = s0 * products[:, P_SC_RATIO]
    tail = np.arctanh(1.0 - 2.0 * CONTACT_CUTOFF_ACTIVATION) / (
        2.0 * np.arctanh(products[:, P_R_A]))
    return 0.5 * (s0 + s_c) + tail * (s0 - s_c)


def _pairs_within_reach(state: SimState, params: SimParams, t1: float,
                        y: np.ndarray) -> np.ndarray:
    """
    Return the pairs (M, 2) within reach over the interval state.t .. t1.

    The reach is widened by how far the pieces can move in the interval: their speed
    relative to the cone, and a fall from rest.
    """
    dt = t1 - state.t
    speed = np.linalg.norm(y[:, 3:6], axis=1)
    reach = (contact_reach(state.products) + speed * dt
             + 0.5 * params.model.g * dt * dt)
    return contact_pairs(y[:, 0:3], reach)


def _advance_alone(single: np.ndarray, state: SimState, params: SimParams,
                   segments: tuple[np.ndarray, np.ndarray, np.ndarray], y: np.ndarray,
                   step_size: np.ndarray, status: np.ndarray, t_event: np.ndarray,
                   stats: np.ndarray) -> None:
    """Advance the pieces ``single`` (indices) alone over the segments, arrays in place."""
    if not single.size:
        return
    solver = params.solver
    ys, hs, st, te = (y[single], step_size[single], status[single], t_event[single])
    ss = stats[single]
    advance_batch(ys, state.products[single], params.global_row, *segments, params.model.r,
                  hs, st, te, solver.rtol, params.atol, solver.h_min, solver.h_max,
                  solver.h_init, solver.max_steps, ss)
    y[single], step_size[single], status[single], t_event[single] = ys, hs, st, te
    stats[single] = ss


def _advance_multirate(state: SimState, params: SimParams, profile: RotationProfile,
                       t1: float, y: np.ndarray, step_size: np.ndarray, status: np.ndarray,
                       t_event: np.ndarray, stats: np.ndarray,
                       counters: np.ndarray) -> tuple[int, float]:
    """
    Advance with piece-piece contact by multirate coupling (:mod:`coupling`).

    Pieces in no pair are advanced alone, as without contact; all pieces in pairs are
    coupled, every pair within reach, whatever the size of the crowd. Returns the largest
    contact island (pieces) and the proposed next coupling interval (s). Arguments as in
    :func:`advance`'s arrays, updated in place; counters (COUPLING_STAT_WIDTH,).
    """
    solver = params.solver
    machine = params.global_row
    pairs = _pairs_within_reach(state, params, t1, y)
    islands = islands_of(state.count, pairs)
    largest = max((len(members) for members, _ in islands), default=0)
    seg_t, seg_omega, seg_domega = profile.segments(state.t, t1)
    coupled = np.zeros(state.count, dtype=bool)
    coupled[pairs.reshape(-1)] = True
    _advance_alone(np.flatnonzero(~coupled), state, params, (seg_t, seg_omega, seg_domega), y,
                   step_size, status, t_event, stats)
    h_coupling = state.coupling_step or solver.h_init
    members = np.flatnonzero(coupled)
    if not members.size:
        return largest, h_coupling
    local = np.empty(state.count, dtype=np.int64)
    local[members] = np.arange(members.size)
    ys, hs, st, te = (np.ascontiguousarray(y[members]), step_size[members], status[members],
                      t_event[members])
    ss = np.ascontiguousarray(stats[members])
    interactions = params.model.interactions
    h_coupling = advance_coupled(
        ys, np.ascontiguousarray(state.products[members]), local[pairs], machine, seg_t,
        seg_omega, seg_domega, params.model.r, hs, st, te, solver.rtol, params.atol,
        solver.h_min, solver.h_max, solver.h_init, solver.max_steps, ss, interactions.pull_off,
        h_coupling, interactions.coupling_tolerance, counters)
    y[members], step_size[members], status[members], t_event[members] = ys, hs, st, te
    stats[members] = ss
    return largest, float(h_coupling)


def _advance_with_contacts(state: SimState, params: SimParams, profile: RotationProfile,
                           t1: float, y: np.ndarray, step_size: np.ndarray,
                           status: np.ndarray, t_event: np.ndarray,
                           stats: np.ndarray) -> tuple[int, int]:
    """
    Advance with piece-piece contact, exactly: contact islands integrated as one system.

    Returns the number of pieces in the largest island and the pairs left out (islands
    larger than ``max_island`` are cut by :func:`cut_island`).

    The pairs are those within reach at the start of the interval, the reach widened by how
    far the pieces can move in it (their speed relative to the cone, and a fall from rest).
    A piece that leaves an island at the rim is taken out, and the rest of the island goes
    on from the exit time. Arguments as in :func:`advance`'s arrays, updated in place.
    """
    solver = params.solver
    machine = params.global_row
    pairs = _pairs_within_reach(state, params, t1, y)
    islands = islands_of(state.count, pairs)
    largest = max((len(members) for members, _ in islands), default=0)
    limit = params.model.interactions.max_island
    left_out = 0
    if largest > limit:
        kept = []
        for members, local in islands:
            if len(members) <= limit:
                kept.append((members, local))
                continue
            parts, dropped = cut_island(members, local, limit)
            kept += parts
            left_out += dropped
        islands = kept
    alone = np.ones(state.count, dtype=bool)
    for members, _ in islands:
        alone[members] = False
    _advance_alone(np.flatnonzero(alone), state, params, profile.segments(state.t, t1), y,
                   step_size, status, t_event, stats)
    pull_off = params.model.interactions.pull_off
    for members, local in islands:
        t_start = state.t
        h = float(step_size[members].min())
        while members.size:
            seg = profile.segments(t_start, t1)
            ys = np.ascontiguousarray(y[members])
            counters = np.zeros(stats.shape[1], dtype=np.int64)
            pos, width = band_order(members.size, local)
            code, t_reached, h, first = advance_island(
                ys, np.ascontiguousarray(state.products[members]), local, pos, 3 * width + 2,
                machine, seg[0], seg[1], seg[2], params.model.r, h, solver.rtol, params.atol,
                solver.h_min, solver.h_max, solver.h_init, solver.max_steps, pull_off,
                counters)
            y[members] = ys
            # every member took the island's steps (its cost is per piece as well)
            stats[members, STAT_ACCEPTED] += counters[STAT_ACCEPTED]
            stats[members, STAT_REJECTED] += counters[STAT_REJECTED]
            if code == ACTIVE:
                step_size[members] = h
                break
            if code == EXITED:
                gone = members[first]
                status[gone] = EXITED
                t_event[gone] = t_reached
                t_start = t_reached
                members = np.delete(members, first)
                local = local[(local != first).all(axis=1)]
                local = local - (local > first)
                continue
            status[members] = FAILED
            t_event[members] = t_reached
            stats[members, STAT_REASON] = counters[STAT_REASON]
            break
    return largest, left_out


def cut_island(members: np.ndarray, local: np.ndarray,
               limit: int) -> tuple[list[tuple[np.ndarray, np.ndarray]], int]:
    """
    Cut an island into parts of at most ``limit`` pieces; return them and the pairs cut.

    members (n,) piece indices, local (m, 2) its pairs as indices into members. The parts
    are runs of the island's band order (:func:`band.band_order`), so touching pieces
    mostly stay together; each part is (members, local pairs) like an island, its members
    sorted. A part of one piece has no pairs.
    """
    pos, _ = band_order(members.size, local)
    order = np.argsort(pos)
    part_of = np.empty(members.size, dtype=np.int64)
    part_of[order] = np.arange(members.size) // limit
    inside = part_of[local[:, 0]] == part_of[local[:, 1]]
    parts = []
    where = np.empty(members.size, dtype=np.int64)
    for part in range(int(part_of.max()) + 1):
        chosen = np.flatnonzero(part_of == part)
        where[chosen] = np.arange(chosen.size)
        own = local[inside & (part_of[local[:, 0]] == part)]
        parts.append((members[chosen], where[own]))
    return parts, int((~inside).sum())


def _failure(state: SimState, profile: RotationProfile, y: np.ndarray, i: int, t: float,
             reason: str) -> Failure:
    """Return the failure of piece i at time t, in the world frame."""
    angle = state.angle + profile.integral(state.t, t)
    with np.errstate(invalid='ignore', over='ignore'):
        q, qdot, _ = world_from_cone(y[i:i + 1], angle, profile.omega(t))
    return Failure(particle_id=int(state.ids[i]), t=t, reason=reason,
                   position=tuple(float(v) for v in q[0]),
                   velocity=tuple(float(v) for v in qdot[0]),
                   mass=float(state.products[i, P_M]))


def _exit_events(state: SimState, params: SimParams, profile: RotationProfile, y: np.ndarray,
                 status: np.ndarray, t_event: np.ndarray) -> ExitEvents:
    idx = np.flatnonzero(status == EXITED)
    if not idx.size:  # most intervals: nothing to locate (the same empty arrays, sooner)
        return ExitEvents(ids=state.ids[idx], t=t_event[idx], angle_deg=np.zeros(0),
                          channel=np.zeros(0, dtype=np.int64), position=np.zeros((0, 3)),
                          velocity=np.zeros((0, 3)), mass=np.zeros(0))
    positions = np.zeros((idx.size, 3))
    velocities = np.zeros((idx.size, 3))
    for j, i in enumerate(idx):
        t_exit = float(t_event[i])
        angle = state.angle + profile.integral(state.t, t_exit)
        q, qdot, _ = world_from_cone(y[i:i + 1], angle, profile.omega(t_exit))
        positions[j] = q[0]
        velocities[j] = qdot[0]
    angle_deg = np.mod(np.degrees(np.arctan2(positions[:, 1], positions[:, 0])), 360.0)
    angle_deg = np.where(angle_deg >= 360.0, 0.0, angle_deg)
    return ExitEvents(ids=state.ids[idx].copy(), t=t_event[idx].copy(), angle_deg=angle_deg,
                      channel=params.model.channels.channel_of(angle_deg),
                      position=positions, velocity=velocities,
                      mass=state.products[idx, P_M].copy())


class Simulator:
    """
    Mutable convenience wrapper: a params, a rotation profile and the current state.

    Used by the headless runner and the ROS node; all physics goes through :func:`advance`.
    """

    def __init__(self, params: SimParams, profile: RotationProfile, t0: float = 0.0) -> None:
        """Start an empty simulation at t0 with the cone angle phi(t0) of the profile."""
        self.params = params
        self.profile = profile
        self.state = SimState(t=float(t0), angle=profile.angle(t0))

    @property
    def t(self) -> float:
        """Return the simulation time (s)."""
        return self.state.t

    def omega(self) -> float:
        """Return the cone angular velocity now (rad/s)."""
        return self.profile.omega(self.state.t)

    def add(self, positions: object, velocities: object | None = None,
            products: Sequence[ProductParams] | None = None) -> np.ndarray:
        """Add particles now; return their ids. See :func:`add_particles`."""
        self.state, ids = add_particles(self.state, self.params, positions, velocities,
                                        products, omega=self.omega())
        return ids

    def advance_to(self, t1: float) -> StepResult:
        """Advance to t1 and keep the new state; return the step's result."""
        result = advance(self.state, self.params, self.profile, t1)
        self.state = result.state
        return result

    def world(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return world position (N, 3), velocity (N, 3) and filter force (N, 3) now."""
        return world_from_cone(self.state.y, self.state.angle, self.omega())


def cone_surface_height(model: ModelParams, x: float, y: float) -> float:
    """Return the height of the cone surface above (x, y) (m), eq. (27) without regularising."""
    return model.h * (1.0 - math.hypot(x, y) / model.r)


def resting_height(model: ModelParams, product: ProductParams, x: float, y: float) -> float:
    """
    Return z (m) at which a piece at (x, y) rests on the stationary cone.

    At rest the normal force balances the normal part of gravity: R_a(s) r_f / 2 = N with
    N = m g cos^2(tilt) (e_Fc is not normalised, |e_Fc| = 1/cos(tilt)), which gives the gap
    s = r_c + artanh(1 - 2 N / r_f) / r_t above the surface.
    """
    cos_t = math.cos(math.radians(model.cone_tilt))
    normal = product.m * model.g * cos_t * cos_t
    r_a_rest = normal / (0.5 * product.r_f)
    if not 0.0 < r_a_rest < 1.0:
        raise ScenarioError(
            f'a piece of mass {product.m} kg cannot rest on the cone with r_f = {product.r_f} N')
    gap = product.r_c + math.atanh(1.0 - 2.0 * r_a_rest) / product.r_t
    return cone_surface_height(model, x, y) + gap


def warm_up() -> None:
    """
    Compile (or load from numba's cache) the integration kernel now, not inside a tick.

    Runs a tiny integration of one piece with the default parameters, then of two touching
    pieces with interactions on (the contact kernels): the kernel's
    signature depends on the kinds of arrays, which are the same for every run (SimParams
    makes the same read-only rows whatever the values), so this loads exactly the kernel a
    run calls, and cannot fail on a run's own parameters. A first call after an install
    compiles (about 10 s on the development machine); later ones load the cache in well
    under a second.
    """
    params = SimParams()
    model = params.model
    x = 0.5 * model.r
    start = (x, 0.0, resting_height(model, model.product, x, 0.0))
    state, _ = add_particles(SimState(), params, [start], None, None, omega=0.0)
    advance(state, params, RotationProfile.constant(1.0), 1.0e-3)
    advance_many([state], params, [RotationProfile.constant(1.0)], [1.0e-3])  # batched
    # the contact kernels (neighbour search, multirate coupling, islands) with two touching
    # pieces
    other = (x + 0.04, 0.0, resting_height(model, model.product, x + 0.04, 0.0))
    for coupling in ('multirate', 'exact'):
        touching = replace(model, interactions=replace(model.interactions, enabled=True,
                                                       coupling=coupling))
        params = SimParams(model=touching, solver=params.solver)
        state, _ = add_particles(SimState(), params, [start, other], None, None, omega=0.0)
        advance(state, params, RotationProfile.constant(1.0), 1.0e-3)
