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
from pathlib import Path

import numpy as np

from .contact import interaction_row
from .coupling import (
    advance_coupled, COUPLING_STAT_WIDTH, CST_ACCEPTED, CST_FORCED, CST_REJECTED)
from .exact import advance_island, islands_of
from .integrator import (
    ACTIVE, advance_batch, advance_batch_owned, EXITED, FAILED, REASON_NOT_FINITE,
    REASON_STEP_UNDERFLOW, REASON_TOO_MANY_STEPS, STAT_ACCEPTED, STAT_REASON, STAT_REJECTED,
    STAT_WIDTH, STOPPED)
from .island import (
    advance_islands, IC_ACCEPTED, IC_REFINED, IC_STEPS, ISLAND_COUNTERS, ROS34PW2)
from .model import STATE_SIZE
from .neighbours import contact_pairs
from .params import (
    COUPLING_CHOICES, ModelParams, P_M, P_S0, product_row, PRODUCT_WIDTH, ProductParams,
    SolverParams)
from .rotation import rotate_z, RotationProfile
from .stop import StopFlag
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
    interaction_row: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Derive the kernel arrays."""
        machine = self.model.global_row()  # read-only
        atol = self.solver.atol_row()
        atol.setflags(write=False)
        object.__setattr__(self, 'global_row', machine)
        object.__setattr__(self, 'atol', atol)
        object.__setattr__(self, 'interaction_row', interaction_row(self.model))


@dataclass(frozen=True)
class SimState:
    """
    State of all particles at time t.

    t (s); angle (rad) the cone angle phi(t); y (N, 9) [x (m), w (m/s), P (N)] in cone axes;
    products (N, PRODUCT_WIDTH) product rows; ids (N,) int64 unique particle ids;
    step_size (N,) proposed next step sizes (s); next_id the id the next new particle gets;
    coupling_step (s) the proposed next coupling interval of pieces that touch (multirate
    coupling; 0: none yet, the solver's h_init); contact_ids (K, 2) int64 the pieces (ids,
    first < second, sorted) of every contact with a history, contact_history (K, 3) (m, cone
    axes) its tangential displacement (:mod:`.contact.tangential`).
    """

    t: float = 0.0
    angle: float = 0.0
    y: np.ndarray = field(default_factory=lambda: np.zeros((0, STATE_SIZE)))
    products: np.ndarray = field(default_factory=lambda: np.zeros((0, PRODUCT_WIDTH)))
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    step_size: np.ndarray = field(default_factory=lambda: np.zeros(0))
    next_id: int = 0
    coupling_step: float = 0.0
    contact_ids: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    contact_history: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

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

    @staticmethod
    def none() -> 'ExitEvents':
        """Return no exits (every array of length 0)."""
        return ExitEvents(ids=np.zeros(0, dtype=np.int64), t=np.zeros(0),
                          angle_deg=np.zeros(0), channel=np.zeros(0, dtype=np.int64),
                          position=np.zeros((0, 3)), velocity=np.zeros((0, 3)),
                          mass=np.zeros(0))


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
    contact): pieces linked by pairs within reach. contacts: pairs touching at the end of
    the interval (each with its history). coupling_intervals, coupling_rejected: the
    island coupling's accepted and rejected common steps, or the multirate coupling's
    intervals; coupling_forced: multirate intervals accepted at the shortest interval
    although their error estimate was above the tolerance (:mod:`coupling`); refined:
    pieces the island coupling refined alone in its accepted steps (:mod:`island`).
    """

    accepted: int
    rejected: int
    particles: int
    largest_island: int = 0
    contacts: int = 0
    coupling_intervals: int = 0
    coupling_rejected: int = 0
    coupling_forced: int = 0
    refined: int = 0


@dataclass(frozen=True)
class StepResult:
    """
    What :func:`advance` returns.

    stopped: a stop was requested (:class:`~.stop.StopFlag`) before the interval was done;
    the interval is dropped: state is the state it started from, with no exits, failures
    or steps.
    """

    state: SimState
    exits: ExitEvents
    failures: tuple[Failure, ...]
    stats: StepStats
    stopped: bool = False


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


def as_points(name: str, values: object, count: int | None = None, *,
              finite: bool = True) -> np.ndarray:
    """
    Return values as a finite (M, 3) float64 array, or raise ScenarioError naming them.

    A single point of shape (3,) is accepted as (1, 3); count, if given, is the required M;
    ``finite=False`` lets non-finite points through (for a caller that screens them).
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
    bad = ~np.all(np.isfinite(arr), axis=1) if finite else np.zeros(0, dtype=np.bool_)
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


#: Pieces that touch may start pressed into each other by at most this fraction of the sum
#: of their radii (10 mm for two default pieces): deeper, the pair law throws them apart
#: with a force of newtons in microseconds, and a spawn of coincident pieces took a tick of
#: minutes. A start deeper in is refused (:func:`overlap_problems`).
MAX_START_OVERLAP = 0.2


def overlap_problems(positions: np.ndarray, products: np.ndarray, others: np.ndarray,
                     other_products: np.ndarray, other_ids: np.ndarray | None = None,
                     label: str = 'position') -> tuple[np.ndarray, list[str]]:
    """
    Check new pieces against each other and the pieces already there; vectorised.

    positions (M, 3), products (M, W) the new pieces (in order: a piece refused does not
    count against the later ones); others (K, 3), other_products (K, W) those on the cone
    (world frame, m). A new piece is refused when it is pressed into another by more than
    MAX_START_OVERLAP of their radii' sum. Returns the mask of the accepted ones and the
    reasons, naming the index (``label[i]``; the other piece by its id, or its index).
    """
    count = positions.shape[0]
    x = np.concatenate([others, positions]).reshape(-1, 3)
    radius = np.concatenate([other_products[:, P_S0], products[:, P_S0]])
    valid = np.ones(count, dtype=bool)
    reasons: list[str] = []
    if count == 0 or not np.all(np.isfinite(x)):
        return valid, reasons
    pairs = contact_pairs(x, (1.0 - MAX_START_OVERLAP) * radius)
    base = others.shape[0]
    pairs = pairs[pairs[:, 1] >= base]  # a new piece in each (the second: i < j)
    for i, j in pairs:
        if not valid[j - base] or (i >= base and not valid[i - base]):
            continue
        valid[j - base] = False
        depth = radius[i] + radius[j] - float(np.linalg.norm(x[i] - x[j]))
        other = (f'piece {int(other_ids[i])}' if other_ids is not None and i < base else
                 f'{label}[{i - base}]' if i >= base else f'piece {i}')
        reasons.append(f'{label}[{j - base}] {positions[j - base].tolist()} is pressed '
                       f'{1e3 * depth:.1f} mm into {other} (at most '
                       f'{1e3 * MAX_START_OVERLAP * (radius[i] + radius[j]):.1f} mm: pieces '
                       'that touch do not start inside each other)')
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
    """Return a new state without the particles whose ids are given (and their contacts)."""
    gone = np.asarray(ids, dtype=np.int64)
    keep = ~np.isin(state.ids, gone)
    kept = ~np.isin(state.contact_ids, gone).any(axis=1)
    return replace(state, y=state.y[keep], products=state.products[keep],
                   ids=state.ids[keep], step_size=state.step_size[keep],
                   contact_ids=state.contact_ids[kept],
                   contact_history=state.contact_history[kept])


def advance(state: SimState, params: SimParams, profile: RotationProfile,
            t1: float, stop: StopFlag | None = None) -> StepResult:
    """
    Advance every particle from state.t to t1 under the rotation profile.

    Pieces that cross the cone edge are located inside the step, reported in the result's
    exits and removed; pieces whose integration fails are reported and removed; the others
    carry on. The inputs are not modified. stop: read by the kernels before every step;
    once it is set the call returns within a step, the interval dropped (``stopped``).
    """
    seg_t, seg_omega, seg_domega = profile.segments(state.t, t1)
    work = _Work(state, stop)
    solver = params.solver
    interactions = params.model.interactions
    n = state.count
    if interactions.enabled and n > 1:
        _advance_with_contacts(state, params, profile, t1, work)
    elif n:
        advance_batch(work.y, state.products, params.global_row, seg_t, seg_omega, seg_domega,
                      params.model.r, work.step_size, work.status, work.t_event, solver.rtol,
                      params.atol, solver.h_min, solver.h_max, solver.h_init,
                      solver.max_steps, work.stats, work.stop)
    return _result(state, params, profile, t1, work)


def advance_many(states: Sequence[SimState], params: SimParams,
                 profiles: Sequence[RotationProfile], t1: Sequence[float],
                 stop: StopFlag | None = None) -> list[StepResult]:
    """
    Advance several independent feeders (same parameters, each its own rotation) at once.

    Without contact between pieces, the pieces of every feeder go to one compiled call
    (:func:`~cone_feeder_sim.physics.integrator.advance_batch_owned`) that spreads them over
    the cores; with contact each feeder is advanced by :func:`advance` in turn. Each result
    is what :func:`advance` gives for that feeder alone, bit for bit (stop: as there).
    """
    if not len(states) == len(profiles) == len(t1):
        raise ValueError(f'{len(states)} states, {len(profiles)} profiles and {len(t1)} ends')
    if params.model.interactions.enabled:
        return [advance(s, params, p, t, stop) for s, p, t in zip(states, profiles, t1)]
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
    works = [_Work(s, stop) for s in states]
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
                            solver.h_init, solver.max_steps, stats, works[0].stop)
        bounds = np.cumsum([0] + counts)
        for w, a, b in zip(works, bounds[:-1], bounds[1:]):
            w.y, w.step_size, w.status = y[a:b], step_size[a:b], status[a:b]
            w.t_event, w.stats = t_event[a:b], stats[a:b]
    return [_result(s, params, p, t, w) for s, p, t, w in zip(states, profiles, t1, works)]


#: The stop request of a call given none: never set.
_NEVER = StopFlag()


class _Work:
    """The arrays one advance updates in place: copies of a state's, and the counters."""

    def __init__(self, state: SimState, stop: StopFlag | None = None) -> None:
        n = state.count
        self.flag = stop
        self.stop = (stop or _NEVER).array
        self.y = state.y.copy()
        self.step_size = state.step_size.copy()
        self.status = np.full(n, ACTIVE, dtype=np.int64)
        self.t_event = np.zeros(n)
        self.stats = np.zeros((n, STAT_WIDTH), dtype=np.int64)
        self.counters = np.zeros(COUPLING_STAT_WIDTH, dtype=np.int64)
        self.refined = 0
        self.largest_island = 0
        self.coupling_step = state.coupling_step
        self.contact_ids = np.zeros((0, 2), dtype=np.int64)
        self.contact_history = np.zeros((0, 3))


def _result(state: SimState, params: SimParams, profile: RotationProfile, t1: float,
            work: _Work) -> StepResult:
    """Return the step's result: exits and failures located, the pieces that left removed."""
    if work.flag is not None and work.flag.is_set():
        return StepResult(state=state, exits=ExitEvents.none(), failures=(),
                          stats=StepStats(accepted=0, rejected=0, particles=state.count),
                          stopped=True)
    y, status, t_event, stats, counters = (work.y, work.status, work.t_event, work.stats,
                                           work.counters)
    keep = status == ACTIVE
    if keep.all():  # most intervals: every piece carries on (nothing to locate, no copies)
        exits, failures, keep = ExitEvents.none(), (), slice(None)
    else:
        exits = _exit_events(state, params, profile, y, status, t_event)
        failures = tuple(_failure(state, profile, y, i, float(t_event[i]),
                                  FAILURE_REASONS.get(int(stats[i, STAT_REASON]), 'unknown'))
                         for i in np.flatnonzero(status == FAILED))
    new_state = replace(state, t=float(t1), angle=state.angle + profile.integral(state.t, t1),
                        y=y[keep], products=state.products[keep], ids=state.ids[keep],
                        step_size=work.step_size[keep], coupling_step=work.coupling_step,
                        contact_ids=work.contact_ids, contact_history=work.contact_history)
    step_stats = StepStats(accepted=int(stats[:, STAT_ACCEPTED].sum()),
                           rejected=int(stats[:, STAT_REJECTED].sum()), particles=state.count,
                           largest_island=work.largest_island,
                           contacts=int(work.contact_ids.shape[0]),
                           coupling_intervals=int(counters[CST_ACCEPTED]),
                           coupling_rejected=int(counters[CST_REJECTED]),
                           coupling_forced=int(counters[CST_FORCED]), refined=work.refined)
    return StepResult(state=new_state, exits=exits, failures=failures, stats=step_stats)


#: The reach of a piece is widened by this margin (m) beyond its contact radius s0 and how
#: far it can move in the interval, so that no contact is missed for a tick.
REACH_MARGIN = 1.0e-3


def contact_reach(products: np.ndarray) -> np.ndarray:
    """
    Return each piece's contact reach (m), shape (N,), from its product rows (N, W).

    Two pieces touch where their centres are closer than the sum of their radii s0 (for
    contact a piece is a sphere of radius s0).
    """
    return products[:, P_S0].copy()


def _pairs_within_reach(state: SimState, params: SimParams, t1: float,
                        y: np.ndarray) -> np.ndarray:
    """
    Return the pairs (M, 2), local indices i < j, that can touch over state.t .. t1.

    The reach is widened by how far the pieces can move in the interval: their speed
    relative to the cone, and a fall from rest, with REACH_MARGIN.
    """
    dt = t1 - state.t
    speed = np.linalg.norm(y[:, 3:6], axis=1)
    reach = (contact_reach(state.products) + 1.1 * (speed * dt + 0.5 * params.model.g * dt * dt)
             + REACH_MARGIN)
    return contact_pairs(y[:, 0:3], reach)


def _pair_keys(ids: np.ndarray) -> np.ndarray:
    """Return one int64 key per pair of ids (K, 2), first < second: first * 2^32 + second."""
    return (ids[:, 0].astype(np.int64) << 32) | ids[:, 1].astype(np.int64)


def _histories(state: SimState, pairs: np.ndarray) -> np.ndarray:
    """Return the history (M, 3) of each pair (local indices): the state's, or zeros."""
    hist = np.zeros((pairs.shape[0], 3))
    if not state.contact_ids.shape[0] or not pairs.shape[0]:
        return hist
    known = _pair_keys(state.contact_ids)
    wanted = _pair_keys(state.ids[pairs])
    at = np.searchsorted(known, wanted)
    at = np.minimum(at, known.size - 1)
    found = known[at] == wanted
    hist[found] = state.contact_history[at[found]]
    return hist


def _keep_contacts(state: SimState, pairs: np.ndarray, hist: np.ndarray, status: np.ndarray,
                   work: '_Work') -> None:
    """Keep the histories of the pairs still touching, by ids, sorted, in ``work``."""
    alive = (status[pairs[:, 0]] == ACTIVE) & (status[pairs[:, 1]] == ACTIVE)
    touching = alive & np.any(hist != 0.0, axis=1)
    ids = state.ids[pairs[touching]].reshape(-1, 2)
    order = np.argsort(_pair_keys(ids), kind='stable')
    work.contact_ids = np.ascontiguousarray(ids[order])
    work.contact_history = np.ascontiguousarray(hist[touching][order])


def _advance_alone(single: np.ndarray, state: SimState, params: SimParams,
                   segments: tuple[np.ndarray, np.ndarray, np.ndarray], y: np.ndarray,
                   step_size: np.ndarray, status: np.ndarray, t_event: np.ndarray,
                   stats: np.ndarray, stop: np.ndarray) -> None:
    """Advance the pieces ``single`` (indices) alone over the segments, arrays in place."""
    if not single.size:
        return
    solver = params.solver
    ys, hs, st, te = (y[single], step_size[single], status[single], t_event[single])
    ss = stats[single]
    advance_batch(ys, state.products[single], params.global_row, *segments, params.model.r,
                  hs, st, te, solver.rtol, params.atol, solver.h_min, solver.h_max,
                  solver.h_init, solver.max_steps, ss, stop)
    y[single], step_size[single], status[single], t_event[single] = ys, hs, st, te
    stats[single] = ss


def _advance_with_contacts(state: SimState, params: SimParams, profile: RotationProfile,
                           t1: float, work: '_Work') -> None:
    """
    Advance with contact between pieces: every pair within reach, with its history.

    Pieces in no pair are advanced alone, as without contact. The others by the multirate
    coupling (:mod:`coupling`: all of them together, every pair) or, with
    ``coupling: exact``, island by island as one system each (:mod:`exact`). The histories
    of the pairs still touching at the end go into ``work`` (by ids), with the largest
    island and the proposed next coupling interval. Arrays of ``work`` updated in place.
    """
    y, step_size, status, t_event, stats = (work.y, work.step_size, work.status,
                                            work.t_event, work.stats)
    pairs = _pairs_within_reach(state, params, t1, y)
    hist = _histories(state, pairs)
    islands = islands_of(state.count, pairs)
    work.largest_island = max((len(members) for members, _, _ in islands), default=0)
    segments = profile.segments(state.t, t1)
    coupled = np.zeros(state.count, dtype=bool)
    coupled[pairs.reshape(-1)] = True
    _advance_alone(np.flatnonzero(~coupled), state, params, segments, y, step_size, status,
                   t_event, stats, work.stop)
    if not pairs.shape[0]:
        return
    coupling = params.model.interactions.coupling
    if coupling == 'island':
        _advance_islands(state, params, segments, islands, hist, work)
    elif coupling == 'multirate':
        work.coupling_step = _advance_multirate(state, params, segments, pairs, hist, coupled,
                                                work)
    else:
        for members, local, rows in islands:
            island_hist = np.ascontiguousarray(hist[rows])
            _advance_exact_island(state, params, profile, t1, members, local, island_hist,
                                  work)
            hist[rows] = island_hist
    _keep_contacts(state, pairs, hist, status, work)


#: The method of the island coupling's common steps (benchmarks/island_method.py swaps it).
ISLAND_METHOD = ROS34PW2


def _advance_islands(state: SimState, params: SimParams,
                     segments: tuple[np.ndarray, np.ndarray, np.ndarray],
                     islands: list, hist: np.ndarray, work: '_Work') -> None:
    """Advance the islands by :func:`island.advance_islands` (ROS34PW2), arrays in place."""
    solver = params.solver
    members = np.concatenate([m for m, _, _ in islands]).astype(np.int64)
    member_start = np.cumsum([0] + [len(m) for m, _, _ in islands]).astype(np.int64)
    lpairs = np.ascontiguousarray(np.concatenate([p for _, p, _ in islands]), dtype=np.int64)
    rows = np.concatenate([r for _, _, r in islands])
    pair_start = np.cumsum([0] + [len(r) for _, _, r in islands]).astype(np.int64)
    island_hist = np.ascontiguousarray(hist[rows])
    counters = np.zeros((len(islands), ISLAND_COUNTERS), dtype=np.int64)
    method = ISLAND_METHOD
    advance_islands(work.y, island_hist, members, member_start, lpairs, pair_start,
                    state.products, params.interaction_row, params.global_row, *segments,
                    params.model.r, work.step_size, work.status, work.t_event, solver.rtol,
                    params.atol, solver.h_min, solver.h_max, solver.h_init, solver.max_steps,
                    work.stats, work.stop, method.a, method.c, method.times, method.d,
                    method.m, method.e, method.gamma, method.order, counters)
    hist[rows] = island_hist
    totals = counters.sum(axis=0)
    work.counters[CST_ACCEPTED] += totals[IC_ACCEPTED]
    work.counters[CST_REJECTED] += totals[IC_STEPS] - totals[IC_ACCEPTED]
    work.refined += int(totals[IC_REFINED])


def _advance_multirate(state: SimState, params: SimParams,
                       segments: tuple[np.ndarray, np.ndarray, np.ndarray], pairs: np.ndarray,
                       hist: np.ndarray, coupled: np.ndarray, work: '_Work') -> float:
    """Advance the pieces in pairs by :func:`coupling.advance_coupled`; return the next H."""
    solver = params.solver
    members = np.flatnonzero(coupled)
    local = np.empty(state.count, dtype=np.int64)
    local[members] = np.arange(members.size)
    y, step_size, status, t_event, stats = (work.y, work.step_size, work.status,
                                            work.t_event, work.stats)
    ys, hs, st, te = (np.ascontiguousarray(y[members]), step_size[members], status[members],
                      t_event[members])
    ss = np.ascontiguousarray(stats[members])
    interactions = params.model.interactions
    h_coupling = advance_coupled(
        ys, np.ascontiguousarray(state.products[members]), local[pairs], hist,
        params.interaction_row, params.global_row, *segments, params.model.r, hs, st, te,
        solver.rtol, params.atol, solver.h_min, solver.h_max, solver.h_init, solver.max_steps,
        ss, work.coupling_step or solver.h_init, interactions.coupling_tolerance,
        work.counters, work.stop)
    y[members], step_size[members], status[members], t_event[members] = ys, hs, st, te
    stats[members] = ss
    return float(h_coupling)


def _advance_exact_island(state: SimState, params: SimParams, profile: RotationProfile,
                          t1: float, members: np.ndarray, local: np.ndarray,
                          hist: np.ndarray, work: '_Work') -> None:
    """
    Advance one island as one system (:func:`exact.advance_island`), arrays in place.

    A piece that reaches the rim is taken out at its exit time, with its pairs, and the rest
    of the island goes on from there. hist (m, 3) the island's histories, in place (a pair
    whose piece left gets zeros).
    """
    solver = params.solver
    y, step_size, status, t_event, stats = (work.y, work.step_size, work.status,
                                            work.t_event, work.stats)
    t_start = state.t
    h = float(step_size[members].min())
    rows = np.arange(local.shape[0])
    while members.size:
        seg = profile.segments(t_start, t1)
        ys = np.ascontiguousarray(y[members])
        hs = np.ascontiguousarray(hist[rows])
        counters = np.zeros(stats.shape[1], dtype=np.int64)
        code, t_reached, h, first = advance_island(
            ys, hs, np.ascontiguousarray(state.products[members]), local,
            params.interaction_row, params.global_row, seg[0], seg[1], seg[2], params.model.r,
            h, solver.rtol, params.atol, solver.h_min, solver.h_max, solver.h_init,
            solver.max_steps, counters, work.stop)
        y[members] = ys
        hist[rows] = hs
        # every member took the island's steps (its cost is per piece as well)
        stats[members, STAT_ACCEPTED] += counters[STAT_ACCEPTED]
        stats[members, STAT_REJECTED] += counters[STAT_REJECTED]
        if code == ACTIVE or code == STOPPED:
            step_size[members] = h
            return
        if code == EXITED:
            gone = members[first]
            status[gone] = EXITED
            t_event[gone] = t_reached
            t_start = t_reached
            members = np.delete(members, first)
            with_it = (local == first).any(axis=1)
            hist[rows[with_it]] = 0.0
            rows = rows[~with_it]
            local = local[~with_it]
            local = local - (local > first)
            continue
        status[members] = FAILED
        t_event[members] = t_reached
        stats[members, STAT_REASON] = counters[STAT_REASON]
        hist[rows] = 0.0
        return


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
    if not idx.size:
        return ExitEvents.none()
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

    def __init__(self, params: SimParams, profile: RotationProfile, t0: float = 0.0,
                 stop: StopFlag | None = None) -> None:
        """Start an empty simulation at t0 with the cone angle phi(t0) of the profile."""
        self.params = params
        self.profile = profile
        self.state = SimState(t=float(t0), angle=profile.angle(t0))
        #: read by the kernels: set it (from any thread) to stop advance_to within a step
        self.stop = stop if stop is not None else StopFlag()

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
        """Advance to t1 and keep the new state; return the step's result (see stopped)."""
        result = advance(self.state, self.params, self.profile, t1, self.stop)
        self.state = result.state
        return result

    def world(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return world position (N, 3), velocity (N, 3) and filter force (N, 3) now."""
        return world_from_cone(self.state.y, self.state.angle, self.omega())

    def positions(self) -> np.ndarray:
        """Return where the pieces are now (N, 3) (m, world frame): the first of :meth:`world`."""
        return rotate_z(self.state.y[:, 0:3], self.state.angle)


def cone_surface_height(model: ModelParams, x: float, y: float) -> float:
    """Return the height of the cone surface above (x, y) (m), eq. (27) without regularising."""
    return model.h * (1.0 - math.hypot(x, y) / model.r)


def resting_mass_limit(model: ModelParams, product: ProductParams) -> float:
    """
    Return the mass (kg) a piece of product stays below to rest on the cone.

    At rest R_a r_f / 2 = m g cos^2(tilt) with R_a < 1 (:func:`resting_height`): the limit is
    r_f / (2 g cos^2(tilt)).
    """
    cos_t = math.cos(math.radians(model.cone_tilt))
    return 0.5 * product.r_f / (model.g * cos_t * cos_t)


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


#: The kernels :func:`warm_up` loaded in this process: 'piece', 'batched', coupling names.
_LOADED: set[str] = set()


def warm_up(model: ModelParams | None = None, batched: bool = False) -> None:
    """
    Compile (or load from numba's cache) the integration kernels now, not inside a tick.

    Runs a tiny integration of one piece with the default parameters, then of two touching
    pieces with interactions on (the contact kernels): the kernel's signature depends on the
    kinds of arrays, which are the same for every run (SimParams makes the same read-only
    rows whatever the values), so this loads exactly the kernels a run calls, and cannot
    fail on a run's own parameters. With ``model``, only what a run of that model calls: a
    piece alone, and the coupling of its interactions where they are on (a first start with
    an empty cache then compiles neither the other coupling nor the batched kernel of the
    RL vector environment, unless ``batched``: :func:`advance_many`, which the RL vector
    environment loads when it is built). Without, every kernel (``cone-feeder-sim compile``,
    which the install runs). A first call after an install compiles (tens of seconds); later ones
    load the cache in well under a second; a kernel already loaded in this process is not
    run again (every engine an RL environment builds at a reset calls this).
    """
    params = SimParams()
    base = params.model
    x = 0.5 * base.r
    start = (x, 0.0, resting_height(base, base.product, x, 0.0))
    if 'piece' not in _LOADED or ((model is None or batched) and 'batched' not in _LOADED):
        state, _ = add_particles(SimState(), params, [start], None, None, omega=0.0)
        advance(state, params, RotationProfile.constant(1.0), 1.0e-3)
        _LOADED.add('piece')
        if model is None or batched:
            advance_many([state], params, [RotationProfile.constant(1.0)], [1.0e-3])
            _LOADED.add('batched')
    couplings: tuple[str, ...] = COUPLING_CHOICES
    if model is not None:
        couplings = (model.interactions.coupling,) if model.interactions.enabled else ()
    couplings = tuple(c for c in couplings if c not in _LOADED)
    # the contact kernels (neighbour search, each coupling) with two touching pieces
    other = (x + 0.045, 0.0, resting_height(base, base.product, x + 0.045, 0.0))
    for coupling in couplings:
        touching = replace(base, interactions=replace(base.interactions, enabled=True,
                                                      coupling=coupling))
        params = SimParams(model=touching, solver=params.solver)
        state, _ = add_particles(SimState(), params, [start, other], None, None, omega=0.0)
        advance(state, params, RotationProfile.constant(1.0), 1.0e-3)
        _LOADED.add(coupling)


def kernel_cache_note(seconds: float, hint: bool = True) -> str:
    """
    Return one line on the integration kernel: loaded from numba's cache or compiled, where.

    seconds: how long loading took. Where the package's folder cannot be written (an install
    owned by root) numba keeps its cache in the user's cache directory instead (or in
    ``NUMBA_CACHE_DIR``); the line says so, and (``hint``) how to fill the cache once.
    """
    stats = advance_batch.stats
    loaded = bool(stats.cache_hits) and not stats.cache_misses
    path = Path(str(stats.cache_path)).resolve()
    note = (f'numba kernels {"loaded from the cache" if loaded else "compiled"} in '
            f'{seconds:.1f} s (cache: {path}')
    if not path.is_relative_to(Path(__file__).resolve().parent.parent):
        note += ", outside the package's folder: the user's cache directory or NUMBA_CACHE_DIR"
    note += ')'
    if hint and not loaded:
        note += '; run `cone-feeder-sim compile` once after installing, so no start compiles'
    return note
