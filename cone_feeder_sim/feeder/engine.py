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
The live simulation without ROS: a cone drive, a product feed and inputs applied per tick.

:class:`FeederEngine` advances the physics core
(:func:`~cone_feeder_sim.physics.simulation.advance`) by a fixed simulated step ``dt`` on
every :meth:`FeederEngine.tick`. It owns

* the **cone drive**: the cone's angular velocity follows a target within
  ``max_angular_acceleration`` (rad/s^2); the target is clamped to
  ``[-max_angular_velocity, max_angular_velocity]`` (rad/s). The target is the open-loop
  pattern (segments ``(duration s, omega rad/s)``, looped, time measured from the start or
  the last reset) until the first rotation command; after that the last command, or 0 once
  ``cmd_timeout`` seconds of simulation time have passed without a command (0 = hold the
  last command for ever). The target is sampled at the start of each tick; within the tick
  omega ramps linearly at the acceleration limit and is held once the target is reached,
  so the tick's :class:`~cone_feeder_sim.physics.rotation.RotationProfile` has a kink inside the
  tick when the target is reached mid-tick.
* the **product feed** (:mod:`~cone_feeder_sim.feeder.feed`): Poisson arrivals drawn once
  per tick (the count per tick is Poisson(rate * dt)) from one ``numpy.random.Generator``
  seeded with ``seed``, so the feed is reproducible.
* the **inputs** (rotation commands, spawn requests, resets and reconfigurations): they
  are validated when submitted (invalid ones raise a
  :class:`~cone_feeder_sim.errors.ConeFeederError` subclass and are not queued; the engine
  carries on), queued, and applied at the start of the next tick in arrival order. Every
  :class:`TickResult` lists the inputs it applied, so a run is reproduced exactly from its
  :class:`EngineConfig` and the pairs (tick index, input): see :meth:`FeederEngine.submit`.

Time is ``tick_index * dt`` exactly (no accumulated rounding). A reset does not turn time
back (stamps stay monotonic) and particle ids keep counting (ids are unique over a run):
it removes every piece, zeroes the channel masses, stops the cone (omega = 0, angle = 0,
the one place where the acceleration limit is not applied), restarts the open-loop
pattern, forgets the rotation commands, re-seeds the feed generator and places the initial
pieces again. The drive and feed parameters in force (after reconfigurations) are kept.

No wall clock is read here: timing belongs to the caller (the ROS node).
"""

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
import math
import threading
from typing import Any

import numpy as np

from .feed import check_feed_fits, draw_feed, FEED_LIMITS, FeedParams
from ..errors import ConeFeederError, InputError, ParameterError, ScenarioError, Stopped
from ..physics.params import (
    check_integer, check_number, Limit, ModelParams, P_M, product_row, PRODUCT_WIDTH,
    ProductParams, SolverParams)
from ..physics.rotation import RotationProfile
from ..physics.simulation import (
    add_particles, advance, advance_many, as_points, check_positions, ExitEvents, Failure,
    overlap_problems, position_problems, SimParams, SimState, StepResult, StepStats, warm_up,
    world_from_cone)
from ..physics.stop import StopFlag
from ..weigher.combination import warm_up as warm_up_weigher
from ..weigher.machine import check_machine, Pack, Weigher, WeigherParams, WeigherStats

__all__ = [
    'ChannelFeed',
    'DriveParams',
    'EngineConfig',
    'EngineInput',
    'FeedParams',
    'FeederEngine',
    'PieceSpec',
    'Refusal',
    'SpawnOffer',
    'Reconfigure',
    'ResetRequest',
    'RotationCommand',
    'SpawnRequest',
    'TickResult',
    'pattern_from_flat',
    'tick_many',
]

#: Allowed ranges of the engine's own settings (the model's are in cone_feeder_sim.physics.params).
ENGINE_LIMITS: dict[str, Limit] = {
    'dt': Limit(0.0, 1.0, 's', lo_open=True),
    'max_angular_velocity': Limit(0.0, 100.0, 'rad/s', lo_open=True),
    'max_angular_acceleration': Limit(0.0, 1.0e4, 'rad/s^2', lo_open=True),
    'cmd_timeout': Limit(0.0, 1.0e6, 's'),
    'pattern_duration': Limit(0.0, 1.0e6, 's', lo_open=True),
    'pattern_omega': Limit(-100.0, 100.0, 'rad/s'),
    'spawn_max_height': Limit(0.0, 100.0, 'm', lo_open=True),
    **FEED_LIMITS,
}

#: Segment boundaries of the open-loop pattern closer than this (s) count as reached.
PATTERN_TOLERANCE = 1.0e-9

#: Largest number of pieces one spawn request may hold.
MAX_SPAWN = 100_000
#: Largest number of inputs waiting for the next tick; more are refused.
MAX_PENDING_INPUTS = 1000


def pattern_from_flat(values: Sequence[float]) -> tuple[tuple[float, float], ...]:
    """
    Return pattern segments from a flat list [duration_1, omega_1, duration_2, ...].

    ROS parameters cannot hold nested lists, so the node stores the pattern flat. An empty
    list is an empty pattern (the cone rests until the first command).
    """
    flat = list(values)
    if len(flat) % 2:
        raise ParameterError(
            f'the open-loop pattern must be pairs [duration s, omega rad/s, ...]; got '
            f'{len(flat)} numbers')
    return tuple((flat[i], flat[i + 1]) for i in range(0, len(flat), 2))


@dataclass(frozen=True)
class DriveParams:
    """
    The cone drive: limits, command timeout and the open-loop pattern.

    max_angular_velocity (rad/s) clamps the target; max_angular_acceleration (rad/s^2) limits
    how fast omega follows it; cmd_timeout (s of simulation time, 0 = hold) stops the cone
    when commands stop; pattern: segments (duration s, omega rad/s), looped, the target until
    the first command (empty: rest).
    """

    max_angular_velocity: float = 10.47
    max_angular_acceleration: float = 20.0
    cmd_timeout: float = 0.5
    pattern: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        """Validate every field; errors name the field."""
        for key in ('max_angular_velocity', 'max_angular_acceleration', 'cmd_timeout'):
            object.__setattr__(self, key, check_number(key, getattr(self, key),
                                                       ENGINE_LIMITS[key]))
        segments = []
        for i, segment in enumerate(self.pattern):
            if isinstance(segment, (str, bytes)) or len(segment) != 2:
                raise ParameterError(
                    f'pattern[{i}] must be a pair (duration s, omega rad/s), got {segment!r}')
            duration = check_number(f'pattern[{i}] duration', segment[0],
                                    ENGINE_LIMITS['pattern_duration'])
            omega = check_number(f'pattern[{i}] omega', segment[1],
                                 ENGINE_LIMITS['pattern_omega'])
            segments.append((duration, omega))
        object.__setattr__(self, 'pattern', tuple(segments))

    @property
    def period(self) -> float:
        """Return the duration of one loop of the pattern (s); 0 for an empty pattern."""
        return float(sum(d for d, _ in self.pattern))

    def pattern_omega(self, t: float) -> float:
        """
        Return the pattern's omega (rad/s) at time t (s) after the pattern started.

        A segment boundary closer than 1 ns counts as reached, so that boundaries which are
        multiples of the tick fall on the tick despite rounding.
        """
        if not self.pattern:
            return 0.0
        phase = math.fmod(max(t, 0.0) + PATTERN_TOLERANCE, self.period)
        for duration, omega in self.pattern:
            if phase < duration:
                return omega
            phase -= duration
        return self.pattern[-1][1]


@dataclass(frozen=True, eq=False)
class PieceSpec:
    """A piece placed at the start and after every reset: world position (m), product."""

    position: tuple[float, float, float]
    velocity: tuple[float, float, float] | None = None
    product: ProductParams | None = None


@dataclass(frozen=True, eq=False)
class EngineConfig:
    """
    Everything a run depends on besides its inputs.

    dt (s) the simulated time per tick; seed of the feed generator; initial_pieces placed at
    t = 0 and after every reset (velocity None: lying on the resting cone); weigher: the
    multihead weigher below the cone, or None (it starts empty at t = 0 and at every
    reset).
    """

    model: ModelParams = ModelParams()
    solver: SolverParams = SolverParams()
    dt: float = 0.02
    drive: DriveParams = DriveParams()
    feed: FeedParams = FeedParams()
    initial_pieces: tuple[PieceSpec, ...] = ()
    seed: int = 0
    spawn_max_height: float = 1.0
    weigher: WeigherParams | None = None

    def __post_init__(self) -> None:
        """Validate dt, the seed, the feed annulus and the initial pieces."""
        object.__setattr__(self, 'dt', check_number('dt', self.dt, ENGINE_LIMITS['dt']))
        object.__setattr__(self, 'seed', check_integer('seed', self.seed,
                                                       ENGINE_LIMITS['seed']))
        check_feed_fits(self.model, self.feed)
        if self.weigher is not None:  # one head per channel, a combination it can choose
            check_machine(self.weigher, self.model.channels.count)
        object.__setattr__(self, 'spawn_max_height', check_number(
            'spawn.max_height', self.spawn_max_height, ENGINE_LIMITS['spawn_max_height']))
        object.__setattr__(self, 'initial_pieces', tuple(self.initial_pieces))
        if len(self.initial_pieces) > self.feed.max_pieces:
            raise ScenarioError(f'{len(self.initial_pieces)} initial pieces exceed '
                                f'feed.max_pieces = {self.feed.max_pieces}')
        for i, piece in enumerate(self.initial_pieces):
            try:
                check_positions(self.model, as_points('position', piece.position, 1),
                                self.spawn_max_height)
                if piece.velocity is not None:
                    as_points('velocity', piece.velocity, 1)
            except ScenarioError as exc:
                raise ScenarioError(f'initial piece {i}: {exc}') from exc


@dataclass(frozen=True)
class RotationCommand:
    """Set the cone's target angular velocity (rad/s, > 0 counter-clockwise from above)."""

    omega: float


@dataclass(frozen=True, eq=False)
class SpawnRequest:
    """
    Add pieces: world positions (M, 3) (m), velocities (M, 3) (m/s) or None, products.

    velocities None: the pieces move with the cone surface (carried); zeros: dropped.
    products None: the default product for every piece.
    """

    positions: np.ndarray
    velocities: np.ndarray | None = None
    products: tuple[ProductParams, ...] | None = None


@dataclass(frozen=True)
class ResetRequest:
    """Start over: see the module documentation for what a reset keeps."""


@dataclass(frozen=True)
class Reconfigure:
    """Replace the drive and/or feed parameters (None keeps the current ones)."""

    drive: DriveParams | None = None
    feed: FeedParams | None = None


@dataclass(frozen=True)
class ChannelFeed:
    """Set the weigher's dosing channels' feed amplitudes, (channels,) in [0, 2]; 0 stops."""

    amplitude: tuple[float, ...]


EngineInput = RotationCommand | SpawnRequest | ResetRequest | Reconfigure | ChannelFeed


@dataclass(frozen=True)
class Refusal:
    """Input the engine refused while applying it: kind of input, how many pieces, why."""

    kind: str
    count: int
    reason: str


@dataclass(frozen=True)
class SpawnOffer:
    """
    What :meth:`FeederEngine.offer_spawn` did with a spawn of ``total`` positions.

    invalid: the positions refused one by one (their count, why); excess: the valid ones
    beyond feed.max_pieces; queue: the rest, refused by a full input queue (each None when
    nothing was refused so).
    """

    total: int
    invalid: Refusal | None = None
    excess: Refusal | None = None
    queue: Refusal | None = None

    @property
    def refusals(self) -> tuple[Refusal, ...]:
        """Return the refusals, in the order above."""
        return tuple(r for r in (self.invalid, self.excess, self.queue) if r is not None)


@dataclass(frozen=True, eq=False)
class TickResult:
    """
    Everything one tick produced (all that the ROS node publishes for it).

    index: the tick's index (0 for the first); t0, t (s): start and end of the tick;
    angle (rad, cumulative) and omega (rad/s) of the cone at t; target_omega (rad/s) the
    clamped target used in this tick; mode: 'pattern', 'command' or 'timeout';
    ids (N,), positions (N, 3) (m), velocities (N, 3) (m/s), masses (N,) (kg) of the pieces
    on the cone at t, world frame; exits and failures during the tick; stats of the solver;
    channel_mass (channel_count,) cumulative kg per channel (index 0 = channel 1) at t;
    applied: the inputs applied at t0, in order; spawned_ids: ids added at t0 (requests and
    feed); feed_ids: the subset added by the feed; reset: whether a reset was applied;
    refusals: pieces of applied spawns refused (the cone held feed.max_pieces); mass_in,
    failed_mass (kg): cumulative mass placed on the cone and removed by failed integration
    since the start or the last reset, so that mass_in = masses.sum() +
    channel_mass.sum() + failed_mass to round-off. With a weigher: packs made in the tick
    and hoppers (heads,) the weigh hoppers' readings at t (kg, 0 = not weighed yet),
    weigher_stats its statistics since the start or the last reset; the
    exits of the tick are on its troughs (its balance is :attr:`FeederEngine.weigher`).
    """

    index: int
    t0: float
    t: float
    angle: float
    omega: float
    target_omega: float
    mode: str
    ids: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    masses: np.ndarray
    exits: ExitEvents
    failures: tuple[Failure, ...]
    stats: StepStats
    channel_mass: np.ndarray
    applied: tuple[EngineInput, ...] = ()
    spawned_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    feed_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    reset: bool = False
    refusals: tuple[Refusal, ...] = ()
    mass_in: float = 0.0
    failed_mass: float = 0.0
    packs: tuple[Pack, ...] = ()
    hoppers: np.ndarray | None = None
    weigher_stats: WeigherStats | None = None

    @property
    def count(self) -> int:
        """Return the number of pieces on the cone at t."""
        return int(self.ids.shape[0])


def drive_profile(t0: float, t1: float, omega0: float, target: float,
                  max_acceleration: float) -> RotationProfile:
    """
    Return omega over [t0, t1]: a ramp at max_acceleration towards target, then held.

    The ramp reaches the target at t0 + |target - omega0| / max_acceleration; when that is
    inside the tick the profile has a kink there, otherwise omega moves by
    max_acceleration * (t1 - t0) towards the target.
    """
    diff = target - omega0
    dt = t1 - t0
    if diff == 0.0:
        return RotationProfile(np.array([t0, t1]), np.array([omega0, omega0]))
    tau = abs(diff) / max_acceleration
    if tau >= dt:
        omega1 = omega0 + math.copysign(max_acceleration * dt, diff)
        return RotationProfile(np.array([t0, t1]), np.array([omega0, omega1]))
    t_reach = t0 + tau
    if t_reach <= t0:
        # the step is below the resolution of t0: take it at once (|diff| ~ a * ulp(t0))
        return RotationProfile(np.array([t0, t1]), np.array([target, target]))
    if t_reach >= t1:
        return RotationProfile(np.array([t0, t1]), np.array([omega0, target]))
    return RotationProfile(np.array([t0, t_reach, t1]), np.array([omega0, target, target]))


class FeederEngine:
    """
    The cone feeder as a live simulation: call :meth:`tick` once per fixed step.

    Deterministic: the same config and the same inputs submitted before the same ticks give
    bit-identical results. Inputs may be submitted from any thread, also while a tick runs on
    another (they wait for the next tick); :meth:`tick` runs on one thread at a time.
    """

    def __init__(self, config: EngineConfig) -> None:
        """Start at t = 0 with the cone at rest and the initial pieces placed."""
        self._config = config
        self._sim_params = SimParams(model=config.model, solver=config.solver)
        self._drive = config.drive
        self._feed = config.feed
        self._pending: list[EngineInput] = []
        self._pending_lock = threading.Lock()
        self._refusals: list[Refusal] = []
        self._index = 0
        self._state = SimState()
        self._channel_mass = np.zeros(config.model.channels.count)
        self._observers: list[TickObserver] = []
        self._stop = StopFlag()
        warm_up(config.model)  # its kernels are loaded now, never inside a tick
        if config.weigher is not None:
            warm_up_weigher()
        self._start(0.0)

    def _start(self, t: float) -> None:
        """Put the run in its initial condition at time t (keep ids counting)."""
        self._state = replace(self._state, t=t, angle=0.0, y=self._state.y[:0],
                              products=self._state.products[:0], ids=self._state.ids[:0],
                              step_size=self._state.step_size[:0])
        self._omega = 0.0
        self._pattern_start = t
        self._commanded = False
        self._command = 0.0
        self._command_time = t
        self._channel_mass[:] = 0.0
        self._failed_mass = 0.0
        self._rng = np.random.default_rng(self._config.seed)
        self._weigher = (Weigher(self._config.weigher, self._config.model.channels.count, t)
                         if self._config.weigher is not None else None)
        for piece in self._config.initial_pieces:
            self._state, _ = add_particles(
                self._state, self._sim_params, [piece.position],
                None if piece.velocity is None else [piece.velocity],
                None if piece.product is None else [piece.product], omega=self._omega)
        self._mass_in = float(self._state.products[:, P_M].sum())

    # ------------------------------------------------------------------ properties

    @property
    def config(self) -> EngineConfig:
        """Return the configuration the engine was built with (drive/feed: initial ones)."""
        return self._config

    @property
    def weigher(self) -> Weigher | None:
        """Return the weigher below the cone (its state after the last tick), or None."""
        return self._weigher

    @property
    def drive(self) -> DriveParams:
        """Return the drive parameters in force."""
        return self._drive

    @property
    def feed(self) -> FeedParams:
        """Return the feed parameters in force."""
        return self._feed

    @property
    def model(self) -> ModelParams:
        """Return the model parameters."""
        return self._config.model

    @property
    def dt(self) -> float:
        """Return the simulated time per tick (s)."""
        return self._config.dt

    @property
    def tick_index(self) -> int:
        """Return the index of the next tick (the number of ticks done so far)."""
        return self._index

    @property
    def t(self) -> float:
        """Return the simulation time (s)."""
        return self._state.t

    @property
    def angle(self) -> float:
        """Return the cone's angle in rad, cumulative since the start or the last reset."""
        return self._state.angle

    @property
    def omega(self) -> float:
        """Return the cone's angular velocity now (rad/s)."""
        return self._omega

    @property
    def state(self) -> SimState:
        """Return the immutable particle state."""
        return self._state

    @property
    def piece_count(self) -> int:
        """Return the number of pieces on the cone."""
        return self._state.count

    @property
    def channel_mass(self) -> np.ndarray:
        """Return a copy of the cumulative mass per channel (kg), index 0 = channel 1."""
        return self._channel_mass.copy()

    @property
    def pending(self) -> tuple[EngineInput, ...]:
        """Return the inputs waiting for the next tick, in arrival order."""
        return tuple(self._pending)

    # ------------------------------------------------------------------ inputs

    def submit(self, item: EngineInput) -> None:
        """
        Validate an input and queue it for the start of the next tick.

        Raises ParameterError or ScenarioError (and queues nothing) for invalid input.
        """
        if isinstance(item, RotationCommand):
            if isinstance(item.omega, bool) or not isinstance(item.omega,
                                                              (int, float, np.floating)):
                raise ParameterError(f'rotation command must be a number (rad/s), got '
                                     f'{item.omega!r}')
            if not math.isfinite(item.omega):
                raise ParameterError(f'rotation command must be finite, got {item.omega!r}')
            item = RotationCommand(float(item.omega))
        elif isinstance(item, SpawnRequest):
            item = self._checked_spawn(item)
        elif isinstance(item, Reconfigure):
            if item.feed is not None:
                check_feed_fits(self._config.model, item.feed)
        elif isinstance(item, ChannelFeed):
            item = self._checked_feed(item)
        elif not isinstance(item, ResetRequest):
            raise ParameterError(f'unknown engine input {item!r}')
        with self._pending_lock:
            if len(self._pending) >= MAX_PENDING_INPUTS:
                raise InputError(f'{type(item).__name__} refused: {MAX_PENDING_INPUTS} inputs '
                                 'are already waiting for the next tick')
            self._pending.append(item)

    def _checked_feed(self, item: ChannelFeed) -> ChannelFeed:
        if self._config.weigher is None:
            raise InputError('channel feed refused: the engine has no weigher (weigher off)')
        count = self._config.model.channels.count
        try:
            values = tuple(float(v) for v in item.amplitude)
        except (TypeError, ValueError) as exc:
            raise ParameterError(f'channel feed amplitudes must be numbers: {exc}') from None
        if len(values) != count:
            raise ParameterError(f'channel feed needs {count} amplitudes (one per channel), '
                                 f'got {len(values)}')
        if not all(math.isfinite(v) and 0.0 <= v <= 2.0 for v in values):
            raise ParameterError(f'channel feed amplitudes must be in [0, 2], got {values}')
        return ChannelFeed(values)

    def _checked_spawn(self, item: SpawnRequest) -> SpawnRequest:
        positions = as_points('spawn position', item.positions, None)
        count = positions.shape[0]
        if count == 0:
            raise ScenarioError('a spawn request needs at least one position')
        if count > MAX_SPAWN:
            raise ScenarioError(f'a spawn request may hold at most {MAX_SPAWN} pieces, got '
                                f'{count}')
        check_positions(self._config.model, positions, self._config.spawn_max_height)
        velocities = (None if item.velocities is None
                      else as_points('spawn velocity', item.velocities, count))
        products = None
        if item.products is not None:
            products = tuple(item.products)
            if len(products) != count:
                raise ScenarioError(f'{len(products)} products given for {count} positions')
            for product in products:
                if not isinstance(product, ProductParams):
                    raise ScenarioError(f'products must be ProductParams, got {product!r}')
        positions.setflags(write=False)
        if velocities is not None:
            velocities.setflags(write=False)
        return SpawnRequest(positions, velocities, products)

    def command(self, omega: float) -> float:
        """
        Queue a rotation command in rad/s; refuse a non-finite value.

        Returns the target it sets under the drive's speed limit in force now (omega clamped
        to ``[-max_angular_velocity, max_angular_velocity]``), so that a caller can say
        when a command was clamped; the tick applies the limit in force then.
        """
        self.submit(RotationCommand(omega))
        limit = self._drive.max_angular_velocity
        return min(max(float(omega), -limit), limit)

    def offer_spawn(self, positions: Any, velocities: Any = None) -> 'SpawnOffer':
        """
        Queue the valid part of a spawn at world positions (M, 3) (m); say what was refused.

        Where :meth:`spawn` refuses a whole request for one bad position, this refuses
        positions one by one: not finite, outside the cone, below its surface or above
        ``spawn_max_height`` (the reason names their indices, at most five), then those
        beyond ``feed.max_pieces`` (no cone holds them). What no longer fits when the spawn is
        applied is refused then, in the tick's refusals. velocities (M, 3) (m/s) or None
        (carried). A full input queue refuses the rest.
        """
        positions = as_points('spawn position', positions, finite=False)
        total = positions.shape[0]
        if velocities is not None:
            velocities = as_points('spawn velocity', velocities, total)
        invalid = excess = queue = None
        valid, problems = position_problems(self._config.model, positions,
                                            self._config.spawn_max_height)
        if problems:
            invalid = Refusal('spawn', len(problems), '; '.join(problems[:5])
                              + (' ...' if len(problems) > 5 else ''))
        positions = positions[valid]
        velocities = None if velocities is None else velocities[valid]
        limit = self._feed.max_pieces
        if positions.shape[0] > limit:
            count = positions.shape[0] - limit
            excess = Refusal('spawn', count, f'{count} of {total} poses beyond feed.max_pieces '
                             f'= {limit} pieces on the cone')
            positions = positions[:limit]
            velocities = None if velocities is None else velocities[:limit]
        if positions.shape[0]:
            try:
                self.spawn(positions, velocities)
            except ConeFeederError as exc:
                queue = Refusal('spawn', positions.shape[0], str(exc))
        return SpawnOffer(total, invalid, excess, queue)

    def spawn(self, positions: Any, velocities: Any = None,
              products: Sequence[ProductParams] | None = None) -> None:
        """Queue pieces at world positions (M, 3); refuse positions outside the cone."""
        self.submit(SpawnRequest(positions, velocities,
                                 None if products is None else tuple(products)))

    def reset(self) -> None:
        """Queue a reset."""
        self.submit(ResetRequest())

    def reconfigure(self, drive: DriveParams | None = None,
                    feed: FeedParams | None = None) -> None:
        """Queue new drive and/or feed parameters."""
        self.submit(Reconfigure(drive=drive, feed=feed))

    def check_reconfigure(self, feed: FeedParams | None = None) -> None:
        """
        Raise what :meth:`reconfigure` would raise now, queueing nothing.

        For a caller that must accept or refuse a change before it submits it (the node's
        parameter callbacks): a feed that does not fit the cone, a full input queue.
        """
        if feed is not None:
            check_feed_fits(self._config.model, feed)
        if len(self._pending) >= MAX_PENDING_INPUTS:
            raise InputError(f'{MAX_PENDING_INPUTS} inputs are already waiting for the next '
                             'tick')

    # ------------------------------------------------------------------ the tick

    def _apply(self, item: EngineInput, t0: float) -> np.ndarray:
        """Apply one input at t0; return the ids it added."""
        if isinstance(item, RotationCommand):
            self._commanded = True
            self._command = item.omega
            self._command_time = t0
        elif isinstance(item, SpawnRequest):
            item = self._bounded(item)
            if item is not None and self._config.model.interactions.enabled:
                item = self._apart(item)
            if item is None:
                return np.zeros(0, dtype=np.int64)
            self._state, ids = add_particles(self._state, self._sim_params, item.positions,
                                             item.velocities, item.products,
                                             omega=self._omega)
            self._mass_in += float(self._state.products[-ids.shape[0]:, P_M].sum())
            return ids
        elif isinstance(item, ResetRequest):
            self._start(t0)
        elif isinstance(item, Reconfigure):
            self._drive = item.drive if item.drive is not None else self._drive
            self._feed = item.feed if item.feed is not None else self._feed
        elif isinstance(item, ChannelFeed) and self._weigher is not None:
            self._weigher.set_amplitude(item.amplitude)
        return np.zeros(0, dtype=np.int64)

    def _bounded(self, item: SpawnRequest) -> SpawnRequest | None:
        """Return the part of a spawn that fits under feed.max_pieces; refuse the rest."""
        count = item.positions.shape[0]
        room = max(0, self._feed.max_pieces - self._state.count)
        if count <= room:
            return item
        self._refusals.append(Refusal(
            'spawn', count - room, f'{count - room} of {count} pieces refused: the cone holds '
            f'{self._state.count} pieces, feed.max_pieces = {self._feed.max_pieces}'))
        if room == 0:
            return None
        return SpawnRequest(item.positions[:room],
                            None if item.velocities is None else item.velocities[:room],
                            None if item.products is None else item.products[:room])

    def _apart(self, item: SpawnRequest) -> SpawnRequest | None:
        """Return the part of a spawn whose pieces start apart enough; refuse the rest."""
        model = self._config.model
        products = item.products or [model.product] * item.positions.shape[0]
        rows = np.array([product_row(p) for p in products]).reshape(-1, PRODUCT_WIDTH)
        here, _, _ = world_from_cone(self._state.y, self._state.angle, self._omega)
        valid, reasons = overlap_problems(item.positions, rows, here, self._state.products,
                                          self._state.ids)
        if not reasons:
            return item
        self._refusals.append(Refusal('spawn', len(reasons), '; '.join(reasons[:5])
                                      + (' ...' if len(reasons) > 5 else '')))
        if not valid.any():
            return None
        return SpawnRequest(item.positions[valid],
                            None if item.velocities is None else item.velocities[valid],
                            None if item.products is None else tuple(
                                p for p, keep in zip(item.products, valid) if keep))

    def _feed_pieces(self) -> np.ndarray:
        """Drop this tick's feed pieces (:func:`~.feed.draw_feed`); return their ids."""
        room = max(0, self._feed.max_pieces - self._state.count)
        drop = draw_feed(self._rng, self._feed, self._config.model, self._config.dt, room)
        if drop is None:
            return np.zeros(0, dtype=np.int64)
        self._state, ids = add_particles(self._state, self._sim_params, drop.positions,
                                         np.zeros_like(drop.positions), drop.products,
                                         omega=self._omega)
        self._mass_in += float(drop.masses.sum())
        return ids

    def _target(self, t0: float) -> tuple[float, str]:
        """Return the clamped target omega for the tick starting at t0, and the mode."""
        drive = self._drive
        if not self._commanded:
            target, mode = drive.pattern_omega(t0 - self._pattern_start), 'pattern'
        elif drive.cmd_timeout > 0.0 and t0 - self._command_time >= drive.cmd_timeout:
            target, mode = 0.0, 'timeout'
        else:
            target, mode = self._command, 'command'
        limit = drive.max_angular_velocity
        return min(max(target, -limit), limit), mode

    def observe(self, callback: 'TickObserver') -> None:
        """Call callback(engine, result) after every tick (on the ticking thread)."""
        self._observers.append(callback)

    def unobserve(self, callback: 'TickObserver') -> None:
        """Stop calling callback after ticks (no error if it was not observing)."""
        if callback in self._observers:
            self._observers.remove(callback)

    def request_stop(self) -> None:
        """
        Stop the tick under way within a step of its integration, and every later one.

        Callable from any thread (a node shutting down while its worker ticks). The tick
        under way, and every tick after, raises :class:`~cone_feeder_sim.errors.Stopped`
        instead of returning: the engine is done (its inputs of that tick were applied).
        """
        self._stop.request()

    def tick(self) -> TickResult:
        """Apply the queued inputs, drop the feed, advance by dt and return the result."""
        if self._stop.is_set():
            raise Stopped(f'the engine was stopped at t = {self.t:g} s')
        plan = self._begin_tick()
        step = advance(self._state, self._sim_params, plan.profile, plan.t1, self._stop)
        if step.stopped:
            raise Stopped(f'the tick from t = {plan.t0:g} s was stopped and dropped')
        return self._end_tick(plan, step)

    def _begin_tick(self) -> '_TickPlan':
        """Apply the queued inputs and the feed at the tick's start; return the tick's plan."""
        dt = self._config.dt
        index = self._index
        t0 = index * dt
        t1 = (index + 1) * dt
        with self._pending_lock:
            applied = tuple(self._pending)
            self._pending.clear()
        self._refusals = []
        spawned = []
        was_reset = False
        for item in applied:
            spawned.append(self._apply(item, t0))
            was_reset = was_reset or isinstance(item, ResetRequest)
        feed_ids = self._feed_pieces()
        spawned.append(feed_ids)
        target, mode = self._target(t0)
        profile = drive_profile(t0, t1, self._omega, target,
                                self._drive.max_angular_acceleration)
        # the state's time is t0 already (ticks are contiguous); make it exact
        self._state = replace(self._state, t=t0)
        return _TickPlan(index, t0, t1, applied, np.concatenate(spawned), feed_ids, was_reset,
                         target, mode, profile)

    def _end_tick(self, plan: '_TickPlan', step: StepResult) -> TickResult:
        """Take the advanced state, account for exits and the weigher; return the result."""
        self._state = step.state
        self._omega = plan.profile.omega(plan.t1)
        self._index = plan.index + 1
        exits = step.exits
        if len(exits):
            np.add.at(self._channel_mass, exits.channel - 1, exits.mass)
        self._failed_mass += sum(failure.mass for failure in step.failures)
        packs: tuple[Pack, ...] = ()
        hoppers = weigher_stats = None
        if self._weigher is not None:
            self._weigher.receive(exits.channel, exits.mass, exits.t)
            packs = tuple(self._weigher.advance(plan.t1))
            hoppers = self._weigher.hopper_readings()
            weigher_stats = self._weigher.stats()
        q, qdot, _ = world_from_cone(self._state.y, self._state.angle, self._omega)
        result = TickResult(
            index=plan.index, t0=plan.t0, t=plan.t1, angle=self._state.angle,
            omega=self._omega, target_omega=plan.target, mode=plan.mode,
            ids=self._state.ids.copy(), positions=q, velocities=qdot,
            masses=self._state.products[:, P_M].copy(), exits=exits, failures=step.failures,
            stats=step.stats, channel_mass=self._channel_mass.copy(), applied=plan.applied,
            spawned_ids=plan.spawned_ids, feed_ids=plan.feed_ids, reset=plan.reset,
            refusals=tuple(self._refusals), mass_in=self._mass_in,
            failed_mass=self._failed_mass, packs=packs, hoppers=hoppers,
            weigher_stats=weigher_stats)
        for callback in tuple(self._observers):
            callback(self, result)
        return result


@dataclass(frozen=True, eq=False)
class _TickPlan:
    """What a tick's start decided: its index and times (s), inputs, feed, drive profile."""

    index: int
    t0: float
    t1: float
    applied: tuple[EngineInput, ...]
    spawned_ids: np.ndarray
    feed_ids: np.ndarray
    reset: bool
    target: float
    mode: str
    profile: RotationProfile


#: Called after every tick of an engine it observes, with the engine and the tick's result.
TickObserver = Callable[[FeederEngine, TickResult], None]


def tick_many(engines: Sequence[FeederEngine]) -> list[TickResult]:
    """
    Tick several engines of the same model and solver at once; return their results.

    Without contact between pieces their pieces are integrated in one compiled call over the
    cores (:func:`~cone_feeder_sim.physics.simulation.advance_many`); each result equals
    what the engine's own :meth:`FeederEngine.tick` gives, bit for bit.
    """
    if not engines:
        return []
    params = engines[0]._sim_params
    for engine in engines[1:]:
        if (engine.config.model != engines[0].config.model
                or engine.config.solver != engines[0].config.solver):
            raise ParameterError('tick_many needs engines of the same model and solver')
    plans = [engine._begin_tick() for engine in engines]
    steps = advance_many([engine._state for engine in engines], params,
                         [plan.profile for plan in plans], [plan.t1 for plan in plans])
    return [engine._end_tick(plan, step) for engine, plan, step in zip(engines, plans, steps)]
