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
The twin's estimator: an ensemble of simulations kept in step with detections.

Each of M members is a state of the physics core (:class:`~..physics.simulation.SimState`),
all with the same pieces (the same ids), each with its own product parameters d and mu_C
(one value each for the product on the cone: the augmented state). The forecast is the
physics core's own :func:`~..physics.simulation.advance_many` (the engine's integrator, all
members in one compiled call), under the cone speed measured so far. At a frame of
detections the estimator

1. associates the detections with its pieces (:mod:`.association`: the ensemble's mean and
   spread of each piece's position plus the detection noise, a chi-square gate, the
   optimal assignment);
2. analyses the ensemble (:mod:`.enkf`) against the assigned detections: each piece's
   position, velocity and filter force in x, y (cone axes, :data:`ANALYSED`; a piece riding
   with the cone in every member: its position alone) and log d and mu_C, through the
   covariances the ensemble carries, so that the parameters are re-identified on line;
3. adds a piece for each detection left over (a birth: resting on the cone where it was
   seen, spread by the detection noise over the members) and drops pieces not seen for
   ``death_after`` s, and one of two pieces within the gate of each other that were not
   both seen (deaths: :meth:`Twin._merge`), and pieces that left the cone in most members
   (exits).

A piece born from one detection is tentative (a false detection is one too) until it was
seen in ``confirm`` frames; a tentative piece not seen for ``tentative_after`` s dies. Only
confirmed pieces are in :meth:`Twin.pieces` and in the forecasts (the M-of-N confirmation
of multi-target tracking).

Detections are world-frame positions; the cone axes turn with the cone by the angle all
members share, so a detection is turned into cone axes before the analysis (the noise is
isotropic in x, y, so its covariance does not change).
"""

import bisect
from collections import Counter
import copy
from dataclasses import dataclass, replace
import math
from typing import Any

import numpy as np

from .association import associate, GATE_CHI2
from .enkf import analyse
from .particles import resample_parameters
from ..errors import Stopped
from ..formats.pointcloud import NO_TRACK
from ..physics.params import P_M, PRODUCT_LIMITS, product_row, ProductParams
from ..physics.rotation import rotate_z, RotationProfile
from ..physics.simulation import (
    add_particles, advance_many, remove_particles, resting_height, resting_mass_limit,
    SimParams, SimState, StepResult, world_from_cone)
from ..physics.stop import StopFlag

__all__ = ['CALIBRATED_PARTICLES', 'Exit', 'EXIT_LAG', 'EXIT_MATCH', 'Frame', 'MASS_PRIOR',
           'MISSED_FRAME', 'parameter_note', 'RIM_GATE', 'STILL', 'TUNING', 'Twin',
           'TwinSettings', 'weighed_values', 'window_log_likelihood']

#: The ranges the members' parameters are held in: log d (d in N*s/m) and mu_C.
LOG_D_RANGE = (math.log(1.0), math.log(1.0e4))
MU_C_RANGE = (0.05, 5.0)
#: The components of a piece's state (9: x, w, P, cone axes) an analysis updates: x, y, their
#: velocities and the friction filter's force in x, y. Height, its velocity and P_z are left
#: to the model (the height follows x, y on the cone's surface): updated through the
#: ensemble's sampled correlations with x, y, they took the pieces off the surface, d and
#: mu_C drifting to what made such states fit (benchmarks/twin_sticking.py, 40 s where every
#: piece sticks: largest height error 555 m, P 59 N, d 39 +- 1 for a truth of 225; now
#: 0.2 mm, 0.01 N, d 239 +- 70).
ANALYSED = np.array([0, 1, 3, 4, 6, 7])
#: The fewest values of d and mu_C a window weighs whose spread was measured to hold
#: (benchmarks/twin_identify.py, doc/twin.md): each member weighing its own, 32 members had all
#: 16 cases within 3 spreads, 8 members 5 cases beyond, 4 members 7 (one 22.6 spreads off);
#: 32 values with 4 members 0 of 48 cases, with 8 members 2 of 48 (seeds 1-3).
CALIBRATED_PARTICLES = 32
#: A piece moving slower than this relative to the cone (m/s) rides with it. One that rides
#: in every member has its position alone analysed (:meth:`Twin._analyse`); a forecast takes
#: riders out after its probe (:mod:`.forecast`).
STILL = 1.0e-3
#: A frame takes the measured exits (a channel's sensors) up to this long (s) before its
#: stamp (:meth:`Twin.measured_exit`): a sensor's report may come as late as a camera's
#: frame, and which frame takes an exit is then set by the stamps alone, not by the order
#: they arrived in (a replay gives the same estimates).
EXIT_LAG = 0.1
#: A measured exit is the exit the twin itself let happen in the same channel or a
#: neighbour within this many seconds of it (:meth:`Twin.update`) ...
EXIT_MATCH = 0.2
#: ... else the piece the camera did not see in the frame, nearest the channel's stretch of
#: rim and within this distance of it (m), leaves the twin at once.
RIM_GATE = 0.05
#: The product's mean piece mass, which the pieces without a camera's mass have, starts
#: at the scenario's product mass, worth this many weighed pieces; each measured exit with a
#: mass (a load cell's step) adds its own (:attr:`Twin.piece_mass`).
MASS_PRIOR = 5.0


@dataclass(frozen=True)
class TwinSettings:
    """
    The estimator's settings.

    members: ensemble size M; sigma: the detections' noise (m, each of x, y); d and
    d_spread: the prior of d (N*s/m) and its relative spread (log scale); mu_C and
    mu_C_spread: its prior and spread; drift: the parameters' random walk per second
    (relative for d, absolute for mu_C; with a window, its end drawn as the window starts
    and followed frame by frame), so that they stay identifiable when the product changes;
    inflation: the members' deviations from their mean (the pieces' states only) are
    multiplied by this before each analysis (multiplicative inflation, Anderson &
    Anderson 1999: a finite ensemble underestimates its spread); death_after: a piece
    not seen for this long (s) is dropped; seed: the ensemble's and the perturbations' seed;
    loosen: the solver's tolerances (relative and absolute) are multiplied by this for the
    members: a twin corrected by detections with millimetres of noise needs no micrometre
    accuracy (at 10, the default 1e-6 m in position becomes 1e-5 m; measured in doc/twin.md);
    window: d and mu_C are weighed once per window of this many seconds, against every
    detection of the window at once (a particle step: a second ensemble, one member per
    member with its parameters at the window's start, runs over the window alongside the
    twin's, without analyses), instead of frame by frame; 0: frame by frame, by the
    Kalman update with the pieces' states (overconfident: doc/twin.md); confirm: the
    frames in which a new piece must be seen before it counts (1: at once); particles:
    with a window, the particle step weighs this many values of d and mu_C (at least
    members; the members run with the first of them, a random choice after each step), so
    that their spread holds whatever the members (doc/twin.md: 4 or 8 members weighing
    their own values were over-confident); smoother_pieces: each weighs the window's
    detections of at most this many pieces, those sliding fastest at the window's start
    (the others ride with the cone and tell little of d and mu_C), so that its cost is
    (particles + members) x smoother_pieces whatever the pieces on the cone;
    tentative_after: a piece not yet confirmed and not seen for this long (s) is dropped;
    localize_below: the analysis is localized by piece (:mod:`.enkf`) when the ensemble has
    fewer members than this. Measured on benchmarks/twin_forecast_scores.py (30 s, seed 1):
    at 4 members localization is needed (the most likely channel 0.25 s before the exit
    right for 69 of 89 pieces, 45 without; channel-mass error over 1 s 0.316 against 0.528
    kg; at 8 members and 28 pieces NIS 1.7 times its degrees of freedom without), at 16 it
    costs (0.5 s before the exit 42 of 79 against 52; seed 2: 37 against 47): the pieces'
    errors are truly correlated through the product's d and mu_C that every member shares,
    which 16 members estimate and localization cuts.
    """

    members: int = 8
    sigma: float = 0.002
    d: float = 225.0
    d_spread: float = 0.5
    mu_C: float = 0.85
    mu_C_spread: float = 0.05
    drift: float = 0.05
    inflation: float = 1.1
    death_after: float = 1.0
    seed: int = 0
    loosen: float = 10.0
    window: float = 0.5
    confirm: int = 2
    tentative_after: float = 0.1
    localize_below: int = 16
    particles: int = 32
    smoother_pieces: int = 6


#: The settings besides members, sigma, seed, d and mu_C (a twin file's keys and twin_node's
#: parameters of the same names): their lower bounds; an int bound: an integer setting.
TUNING = {'d_spread': 0.0, 'mu_C_spread': 0.0, 'drift': 0.0, 'inflation': 1.0,
          'death_after': 0.0, 'loosen': 1.0, 'window': 0.0, 'confirm': 1,
          'tentative_after': 0.0, 'localize_below': 0, 'particles': 2, 'smoother_pieces': 1}


@dataclass(frozen=True)
class Exit:
    """An exit the twin saw: the piece, t (s), the channel (1-based), the mass (kg)."""

    piece: int
    t: float
    channel: int
    mass: float


@dataclass(frozen=True)
class Frame:
    """
    What one frame of detections did.

    t (s); associated, births, deaths, exits: counts (exits: pieces the predictions since
    the frame before found gone from most members, or at a measured exit; left: those of them
    confirmed, :class:`Exit`); nis: the analysis's normalised innovation squared and
    observed: its degrees of freedom (2 per associated piece); measured: the measured exits
    the frame took, and explained: those of them that were an exit of the twin's or took a
    piece off the cone (the others matched no piece).
    """

    t: float
    associated: int
    births: int
    deaths: int
    exits: int
    nis: float
    observed: int
    left: tuple[Exit, ...] = ()
    measured: int = 0
    explained: int = 0


def loosened(params: SimParams, factor: float) -> SimParams:
    """Return params with the solver's relative and absolute tolerances times factor."""
    solver = params.solver
    return replace(params, solver=replace(
        solver, rtol=solver.rtol * factor, atol_position=solver.atol_position * factor,
        atol_velocity=solver.atol_velocity * factor, atol_force=solver.atol_force * factor))


def weighed_values(settings: TwinSettings) -> int:
    """Return how many values of d and mu_C the twin holds: particles (at least members)."""
    return max(settings.particles, settings.members) if settings.window > 0.0 else settings.members


def parameter_note(settings: TwinSettings) -> str:
    """Return what a run with these settings should say of its d and mu_C ('' if nothing)."""
    if settings.window <= 0.0:
        return ('with window 0 (d and mu_C analysed frame by frame) their spread is '
                'over-confident: their estimates are a trend (doc/twin.md)')
    values = weighed_values(settings)
    if values >= CALIBRATED_PARTICLES:
        return ''
    return (f'with {values} values of d and mu_C (particles) their spread is over-confident: '
            f'their estimates are a trend (a spread that holds from {CALIBRATED_PARTICLES}, '
            'doc/twin.md)')


def window_log_likelihood(residuals: np.ndarray, anomalies: np.ndarray, ids: np.ndarray,
                          sigma: float) -> np.ndarray:
    """
    Return each value's log-likelihood (P,) of a window's detections (up to a constant).

    residuals (P, k): the smoother's predictions from the members' mean start minus the
    detections (m), each column one axis of one detection of the piece ``ids`` (k,);
    anomalies (M, k): the same columns predicted from each member's own start (with the
    values' mean d and mu_C), minus their mean (m); sigma: the detections' noise (m). The
    mean start's error moves a piece's predictions together, as the members' starts move
    theirs: per piece, the residuals' covariance is sigma^2 I + A'A / (M - 1), A its
    columns of ``anomalies``, inverted by Woodbury (rank M): r'S^-1 r = |r|^2 / sigma^2 -
    (A r)' ((M - 1) sigma^2 I + A A')^-1 (A r) / sigma^2. Counted as evidence frame after
    frame instead, the mean's error made 4 or 8 members' d and mu_C over-confident
    (doc/twin.md).
    """
    s2 = sigma ** 2
    members = anomalies.shape[0]
    quadratic = np.sum(residuals ** 2, axis=1) / s2
    for piece in np.unique(ids):
        columns = ids == piece
        a = anomalies[:, columns]  # (M, n)
        projected = residuals[:, columns] @ a.T  # (P, M)
        gram = (members - 1) * s2 * np.eye(members) + a @ a.T
        quadratic -= np.sum(projected * np.linalg.solve(gram, projected.T).T, axis=1) / s2
    return -0.5 * quadratic


#: The log-likelihood, for a value of d and mu_C, of a frame in which no detection is
#: associated with a piece that the twin follows and the value's smoother copy holds on the
#: cone: a camera that misses a piece in one frame of ten. (A copy whose piece left, in the
#: same frame: 0.) Without it only a piece that left too early was evidence, and not one
#: that stayed too long: the weights leaned to values that keep pieces on the cone
#: (benchmarks/twin_forecast_scores.py, seeds 1-3: channel-mass error over 1 s 0.287, 0.291,
#: 0.288 kg; with it 0.277, 0.275, 0.276).
MISSED_FRAME = math.log(0.1)

#: The values of d and mu_C at one time: log d (P,) and mu_C (P,).
Walk = tuple[np.ndarray, np.ndarray]


class Twin:
    """An ensemble of simulations that follows detected pieces (see the module)."""

    def __init__(self, params: SimParams, settings: TwinSettings = TwinSettings(),
                 t0: float = 0.0, stop: StopFlag | None = None) -> None:
        """
        Start with no pieces at t0 (s).

        stop: a request the members' integration reads between its steps; once it is set,
        the computation under way raises Stopped within a step (a node's shutdown).
        """
        if settings.confirm < 1:
            raise ValueError(f'confirm must be at least 1, got {settings.confirm}')
        if settings.members < 2:
            raise ValueError(f'members must be at least 2, got {settings.members}')
        if settings.particles < 2 or settings.smoother_pieces < 1:
            raise ValueError(f'particles must be at least 2 and smoother_pieces at least 1, '
                             f'got {settings.particles} and {settings.smoother_pieces}')
        if not settings.sigma > 0.0:
            raise ValueError(f'sigma must be positive, got {settings.sigma}')
        if not settings.loosen >= 1.0:
            raise ValueError(f'loosen must be at least 1, got {settings.loosen}')
        self.params, self.settings = loosened(params, settings.loosen), settings
        #: the mass (kg) every piece's stays below: above it a piece cannot rest on the cone,
        #: or the model takes no such product
        self.heaviest = min(PRODUCT_LIMITS['m'].hi,
                            resting_mass_limit(self.params.model, self.params.model.product))
        #: the members' params without the pair law: the smoother's (see _start_window)
        model = self.params.model
        self._alone = replace(self.params, model=replace(
            model, interactions=replace(model.interactions, enabled=False)))
        self.stop = stop or StopFlag()
        self.rng = np.random.default_rng(settings.seed)
        m = settings.members
        #: d's and mu_C's values (P,): log d and mu_C; member k runs with the k-th
        p = weighed_values(settings)
        self.log_d = math.log(settings.d) + settings.d_spread * self.rng.standard_normal(p)
        self.mu_c = settings.mu_C + settings.mu_C_spread * self.rng.standard_normal(p)
        self.states = [SimState(t=t0) for _ in range(m)]
        self.times, self.omegas = [t0], [0.0]
        self._profile = RotationProfile(np.array(self.times), np.array(self.omegas))
        #: each piece's camera mass (kg; NaN: none, the mean piece mass: :attr:`masses`)
        self._camera_mass: dict[int, float] = {}
        self.last_seen: dict[int, float] = {}
        #: the frames each piece was seen in, up to settings.confirm (confirmed there)
        self.hits: dict[int, int] = {}
        #: the camera's track id last associated with each piece (where frames carry them)
        self.tracks: dict[int, int] = {}
        #: the pieces the predictions since the last frame dropped as gone, and the exits
        #: among them the twin saw (confirmed pieces)
        self._exits: list[int] = []
        self._left: list[Exit] = []
        #: where and when members let each piece on the cone go: (t (s), channel) each
        self._leaving: dict[int, list[tuple[float, int]]] = {}
        #: the exits the members let happen in the last second, not yet matched with a
        #: measured one: (t (s), channel) each; the measured exits no frame took yet: (t
        #: (s), channel, mass (kg; NaN: not weighed)) each
        self._recent_exits: list[tuple[float, int]] = []
        self.pending_exits: list[tuple[float, int, float]] = []
        #: the measured exits' masses taken so far: how many, their sum (kg)
        self._weighed = (0, 0.0)
        self._drifted = t0
        #: the window: its start (s); the smoother's members (None: nothing to weigh), run
        #: alongside the twin's: one state holding Q = P + M copies of each piece (id * Q +
        #: k: the k-th value's, then each member's start); their predictions of the
        #: window's detections so far, (P, k) per frame, and those detections (k,) (m, x and
        #: y of each piece)
        self._window_t0 = t0
        self._smoother: list[SimState] | None = None
        #: the parameters' random walk over the window: (log d, mu_C) at its start and end
        #: (P,) each; None: a step each frame (no window yet, or window 0)
        self._walk: Walk | None = None  # where the window's random walk ends
        self._predicted: list[np.ndarray] = []
        self._observed: list[np.ndarray] = []
        #: the piece of each of those detections' columns (k,) per frame, and the columns
        #: predicted from each member's start (M, k), minus their mean (m)
        self._observed_ids: list[np.ndarray] = []
        self._anomalies: list[np.ndarray] = []
        #: where the smoother's copies of pieces left the cone this window, or their
        #: integration failed: (index of the smoother's state, id in it) -> world x, y (2,)
        #: (m) there
        self._departed: dict[tuple[int, int], np.ndarray] = {}
        #: the pieces the window's smoother holds (ids), and the values' log-likelihood
        #: (P,) of the frames that did not see one of them (:data:`MISSED_FRAME`)
        self._window_pieces = np.zeros(0, dtype=np.int64)
        self._missed = np.zeros(0)

    def snapshot(self) -> 'Twin':
        """Return a copy that goes on apart from this twin (its random numbers included)."""
        other = copy.copy(self)
        other.states = list(self.states)
        other.log_d, other.mu_c = self.log_d.copy(), self.mu_c.copy()
        other.rng = copy.deepcopy(self.rng)
        other.times, other.omegas = list(self.times), list(self.omegas)
        other._camera_mass, other.last_seen = dict(self._camera_mass), dict(self.last_seen)
        other.hits, other.tracks = dict(self.hits), dict(self.tracks)
        other._exits, other._left = list(self._exits), list(self._left)
        other._recent_exits = list(self._recent_exits)
        other._leaving = {i: list(e) for i, e in self._leaving.items()}
        other.pending_exits = list(self.pending_exits)
        other._smoother = None if self._smoother is None else list(self._smoother)
        other._predicted, other._observed = list(self._predicted), list(self._observed)
        other._observed_ids, other._anomalies = list(self._observed_ids), list(self._anomalies)
        other._departed = dict(self._departed)
        other._missed = self._missed.copy()
        return other

    @property
    def t(self) -> float:
        """Return the twin's time (s)."""
        return self.states[0].t

    def profile(self) -> RotationProfile:
        """Return the cone speed measured so far (held after the last measurement)."""
        return self._profile

    def cone_speed(self, t: float, omega: float) -> None:
        """
        Take a measured cone speed (rad/s) at t (s), not before the last one.

        Measurements before the last one at or before the twin's time are forgotten: the
        members never go back, so the profile keeps only what they still need.
        """
        if not math.isfinite(omega) or t < self.times[-1]:
            raise ValueError(f'cone speed {omega} at t = {t} s: not finite or out of order')
        if t == self.times[-1]:
            self.omegas[-1] = float(omega)
        else:
            self.times.append(float(t))
            self.omegas.append(float(omega))
        # from the window's start, as when the window ran again at its end (the angle is
        # summed from the table's first time, so where it starts sets the last bits)
        keep = min(self.t, self._window_t0)
        first = max(int(np.searchsorted(self.times, keep, side='right')) - 1, 0)
        del self.times[:first], self.omegas[:first]
        self._profile = RotationProfile(np.array(self.times), np.array(self.omegas))

    def advance(self, states: list[SimState], t1: float,
                profile: RotationProfile | None = None,
                params: SimParams | None = None) -> list[StepResult]:
        """
        Advance members' states to t1 (s) under profile (default: the measured cone speed).

        params: default the members'. Raises Stopped when :attr:`stop` was requested
        meanwhile (the interval is dropped).
        """
        m = len(states)
        results = advance_many(states, params or self.params, [profile or self._profile] * m,
                               [t1] * m, self.stop)
        if any(r.stopped for r in results):
            raise Stopped('the twin was asked to stop')
        return results

    def predict(self, t1: float) -> None:
        """
        Advance every member to t1 (s); pieces that left in most members are dropped.

        Each confirmed piece dropped so is an exit the twin saw (:attr:`Frame.left`): the
        members' median exit time (over this prediction and those before), the channel
        most of them give, the piece's mass.
        """
        m = len(self.states)
        smoother = self._smoother or []
        if smoother and self.params.model.interactions.enabled:  # the smoother's without it
            results = self.advance(self.states, t1) + self.advance(smoother, t1,
                                                                   params=self._alone)
        else:
            results = self.advance(self.states + smoother, t1)  # one compiled call for both
        if smoother:
            self._smoother = [r.state for r in results[m:]]
            for k, r in enumerate(results[m:]):
                for i, xy in zip(r.exits.ids.tolist(), r.exits.position[:, :2]):
                    self._departed[(k, i)] = xy
                for failure in r.failures:  # where it failed, or was last if not finite
                    xy = np.array(failure.position[:2], dtype=float)
                    if not np.all(np.isfinite(xy)):
                        xy = self._world(smoother[k], np.array([failure.particle_id]),
                                         0.0)[0, :2]
                    self._departed[(k, failure.particle_id)] = xy
            results = results[:m]
        self.states = [r.state for r in results]
        seen = self._leaving
        for r in results:
            for i, t, c in zip(r.exits.ids.tolist(), r.exits.t.tolist(),
                               r.exits.channel.tolist()):
                seen.setdefault(i, []).append((t, c))
        # gone from most members, in this prediction or over several (an exit or a failed
        # integration each); the rest of the members drop it too
        held = Counter(np.concatenate([s.ids for s in self.states]).tolist())
        dropped = [i for i in self.last_seen if 2 * (m - held.get(i, 0)) > m]
        self._exits += dropped
        for i in dropped:
            if i not in seen:
                continue
            # the lower median: one member's time (members' exits can be a prediction
            # apart, and a mean or a midpoint of two would be a time none gave)
            times, channels = zip(*seen[i])
            when = float(sorted(times)[(len(times) - 1) // 2])
            channel = int(np.bincount(channels).argmax())
            self._recent_exits.append((when, channel))
            if self.hits.get(i, 0) >= self.settings.confirm:
                self._left.append(Exit(piece=i, t=when, channel=channel, mass=self._mass(i)))
        self._drop(dropped)

    def pieces(self, tentative: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Return the pieces every member holds: ids (n,), mean world x, y (n, 2) (m), spread.

        spread: (n, 2, 2) the members' covariance of x, y (m^2). tentative: also the pieces
        not yet confirmed (see the module).
        """
        ids = self._common()
        if not tentative:
            confirm = self.settings.confirm
            ids = ids[[self.hits.get(int(i), 0) >= confirm for i in ids.tolist()]]
        if not len(ids):
            return ids, np.zeros((0, 2)), np.zeros((0, 2, 2))
        omega = self._profile.omega(self.t)
        xy = np.stack([self._world(s, ids, omega)[:, :2] for s in self.states])  # (M, n, 2)
        anomalies = xy - xy.mean(axis=0)
        covariance = np.einsum('mni,mnj->nij', anomalies, anomalies) / (len(xy) - 1)
        return ids, xy.mean(axis=0), covariance

    def parameters(self) -> dict[str, tuple[float, float]]:
        """Return the product's d and mu_C: (estimate, spread) each, over the P values."""
        d = np.exp(self.log_d)
        return {'d': (float(d.mean()), float(d.std(ddof=1))),
                'mu_C': (float(self.mu_c.mean()), float(self.mu_c.std(ddof=1)))}

    @property
    def masses(self) -> dict[int, float]:
        """
        Return each piece's mass (kg) as the forecasts count it: the camera's, else the mean.

        The mean piece mass (:attr:`piece_mass`) follows the load cells' weighed exits, for
        the pieces on the cone as for those to come; the members integrate each piece with
        the mass it was born with.
        """
        return {i: self._mass(i) for i in self._camera_mass}

    def _mass(self, i: int) -> float:
        """Return piece i's mass (kg): see :attr:`masses`."""
        mass = self._camera_mass[i]
        return self.piece_mass if math.isnan(mass) else mass

    @property
    def _mean_mass(self) -> set[int]:
        """Return the pieces without a camera's mass (they have :attr:`piece_mass`)."""
        return {i for i, m in self._camera_mass.items() if math.isnan(m)}

    @property
    def piece_mass(self) -> float:
        """
        Return the product's mean piece mass (kg): the mass of the pieces without a camera's.

        The scenario's product mass, worth :data:`MASS_PRIOR` pieces, and the masses of the
        measured exits taken so far (load cells), averaged.
        """
        count, total = self._weighed
        return (MASS_PRIOR * self.params.model.product.m + total) / (MASS_PRIOR + count)

    def measured_exit(self, t: float, channel: int, mass: float = math.nan) -> None:
        """
        Take an exit a channel's sensor measured: t (s), channel (1-based), mass (kg).

        mass: the piece's, a load cell's step (NaN: not weighed). The first frame stamped
        at least :data:`EXIT_LAG` s after it takes it (see :meth:`update`). Raises
        ValueError for a time that is not finite or that a frame already passed
        (:class:`.live.Follower` goes back for it), a channel not in the layout, or a mass
        that is neither NaN nor in (0, :attr:`heaviest`).
        """
        channel, mass = self.exit_channel(channel), self.exit_mass(mass)
        if not math.isfinite(t) or t <= self.t - EXIT_LAG:
            raise ValueError(f'measured exit at t = {t} s: not finite, or older than the '
                             f'frames the twin took ({self.t} s, less {EXIT_LAG} s)')
        self.pend_exit(t, channel, mass)

    def pend_exit(self, t: float, channel: int, mass: float = math.nan) -> None:
        """Add a checked exit to those waiting, in time order (at any time: see Follower)."""
        bisect.insort(self.pending_exits, (float(t), int(channel), float(mass)))

    def exit_mass(self, mass: Any) -> float:
        """Return mass (kg) as a float; raise ValueError unless it is NaN or in (0, heaviest)."""
        if isinstance(mass, bool) or not isinstance(mass, (int, float, np.integer,
                                                           np.floating)) or not (
                math.isnan(mass) or 0.0 < mass < self.heaviest):
            raise ValueError(f'measured exit: mass {mass!r} is not a number of kg in (0, '
                             f'{self.heaviest:.4g}) (a heavier piece cannot rest on the '
                             f'cone) or NaN (not weighed)')
        return float(mass)

    def check_masses(self, masses: np.ndarray | None) -> None:
        """Raise ValueError if a detection's mass (kg; NaN: not given) is heaviest or more."""
        if masses is None:
            return
        given = np.asarray(masses, dtype=float)
        given = given[~np.isnan(given)]
        if len(given) and not given.max() < self.heaviest:
            raise ValueError(f"a detection's mass of {given.max():.4g} kg is not below "
                             f'{self.heaviest:.4g} kg (a heavier piece cannot rest on the '
                             f'cone)')

    def exit_channel(self, channel: Any) -> int:
        """Return channel as an int; raise ValueError if it is not one of the layout's."""
        count = self.params.model.channels.count
        if isinstance(channel, bool) or not isinstance(channel, (int, np.integer)) or not (
                1 <= channel <= count):
            raise ValueError(f'measured exit: channel {channel!r} is not one of 1..{count}')
        return int(channel)

    def update(self, t: float, detections: np.ndarray, masses: np.ndarray | None = None,
               track_ids: np.ndarray | None = None) -> Frame:
        """
        Take a frame of detections at t (s): predict to t, associate, analyse, births.

        detections: (k, 2 or 3) world-frame positions (m; z is not used); masses: (k,) (kg;
        NaN: not given), or None: the product's mean mass; track_ids: (k,) the camera's
        track ids (NO_TRACK: not given), or None: none given. The association is by position
        alone; each piece keeps the track id of the last detection with one associated with
        it (:attr:`tracks`).

        The frame takes the measured exits (:meth:`measured_exit`) up to t - :data:`EXIT_LAG`.
        One that an exit of the twin's (members' median time, their channel) within
        :data:`EXIT_MATCH` s and one channel explains changes nothing; else the piece that
        no detection of the frame was associated with and that is nearest the channel's
        stretch of rim, within :data:`RIM_GATE`, leaves the twin at the measured time
        (:attr:`Frame.left`), instead of dying ``death_after`` s later while the forecasts
        still count it. Each weighed exit's mass joins the mean piece mass that the pieces
        without a camera's mass have (:attr:`piece_mass`), whichever piece it was.
        """
        detections = np.asarray(detections, dtype=float).reshape(-1, detections.shape[-1])
        if not np.isfinite(detections).all():
            raise ValueError('a detection is not finite')
        self.check_masses(masses)
        if t < self.t:  # a late frame: live.Follower goes back to a snapshot for it
            raise ValueError(f'detections at t = {t} s are older than the twin ({self.t} s)')
        if t > self.t:
            self.predict(t)
        exits, seen_leaving = len(self._exits), tuple(self._left)
        self._exits, self._left = [], []
        self._drift(t)
        ids, mean, spread = self.pieces(tentative=True)
        sigma = self.settings.sigma
        noise = np.eye(2) * sigma ** 2
        match = associate(mean, spread + noise, detections[:, :2])
        nis, observed = 0.0, 0
        if len(match.pairs):
            nis, observed = self._analyse(ids, match.pairs, detections[:, :2])
            for piece, seen in match.pairs:
                i = int(ids[piece])
                if track_ids is not None and track_ids[seen] != NO_TRACK:
                    self.tracks[i] = int(track_ids[seen])
                self.last_seen[i] = t
                self.hits[i] = min(self.hits.get(i, 0) + 1, self.settings.confirm)
        self._window_frame(t, ids[match.pairs[:, 0]], detections[match.pairs[:, 1], :2], ids)
        unseen = ~np.isin(ids, ids[match.pairs[:, 0]])
        measured, taken, left, explained = self._measured_exits(t, ids[unseen], mean[unseen])
        exits += len(taken)
        seen_leaving += tuple(left)
        # a detection left over is a birth, unless it is within 3 sigma of the rim (a piece
        # leaving, or a false detection there: no member could hold it on the cone)
        rim = self.params.model.r - 3.0 * sigma
        spare = match.unassigned
        born = spare[np.hypot(detections[spare, 0], detections[spare, 1]) < rim]
        if len(born):
            weights = None if masses is None else np.asarray(masses, dtype=float)[born]
            first = self.states[0].next_id
            self._birth(detections[born, :2], weights, t)
            if track_ids is not None:
                self.tracks.update((first + n, int(track_ids[k])) for n, k in enumerate(born)
                                   if track_ids[k] != NO_TRACK)
        confirm, settings = self.settings.confirm, self.settings
        # every piece the twin knows, not only those every member holds: one that some
        # members let go is in no output and no association, and dies unseen
        dead = [i for i in self.last_seen
                if t - self.last_seen[i] > (settings.death_after
                                            if self.hits.get(i, 0) >= confirm
                                            else settings.tentative_after)]
        self._drop(dead)
        dead += self._merge(t)
        if self.settings.window > 0.0 and t - self._window_t0 >= self.settings.window - 1e-9:
            self._smooth()
            self._start_window(t)
        return Frame(t=t, associated=len(match.pairs), births=len(born), deaths=len(dead),
                     exits=exits, nis=nis, observed=observed, left=seen_leaving,
                     measured=measured, explained=explained)

    def open_loop_exits(self) -> tuple[Exit, ...]:
        """
        Take the measured exits due at the twin's time without a frame (the camera is off).

        As :meth:`update` does, but any piece may be the one that left (no detection says
        which are still there). Returns the exits the twin saw among the pieces taken off.
        """
        if self.pending_exits and self.pending_exits[0][0] <= self.t - EXIT_LAG:
            ids, mean, _ = self.pieces(tentative=True)
        else:  # nothing due: no piece to look at
            ids, mean = np.zeros(0, dtype=np.int64), np.zeros((0, 2))
        _, _, left, _ = self._measured_exits(self.t, ids, mean)
        return tuple(left)

    def _measured_exits(self, t: float, ids: np.ndarray,
                        xy: np.ndarray) -> tuple[int, list[int], list[Exit], int]:
        """
        Take the measured exits due at t (s); return what they did.

        ids (n,) and xy (n, 2) (m, world): the pieces that may have left (no detection of
        the frame was associated with them), and where the members' mean has them (see
        :meth:`update`). Returns how many exits were taken, the pieces they took off (ids),
        the exits the twin saw among them (confirmed pieces) and how many measured exits an
        exit of the twin's or a piece explained.
        """
        due = [e for e in self.pending_exits if e[0] <= t - EXIT_LAG]
        self.pending_exits = self.pending_exits[len(due):]
        weighed = [mass for _, _, mass in due if not math.isnan(mass)]
        if weighed:
            count, total = self._weighed
            self._weighed = (count + len(weighed), total + math.fsum(weighed))
        explained = 0
        layout, radius = self.params.model.channels, self.params.model.r
        taken: list[int] = []
        left: list[Exit] = []
        free = np.ones(len(ids), dtype=bool)
        angle = np.arctan2(xy[:, 1], xy[:, 0])
        width = math.radians(layout.width)
        for when, channel, mass in due:
            near = [k for k, (te, c) in enumerate(self._recent_exits)
                    if abs(te - when) <= EXIT_MATCH
                    and min((c - channel) % layout.count, (channel - c) % layout.count) <= 1]
            if near:
                self._recent_exits.pop(min(near, key=lambda k: abs(
                    self._recent_exits[k][0] - when)))
                explained += 1
                continue
            if not free.any():
                continue
            start, end = np.radians(layout.sector_edges(channel))
            offset = np.mod(angle - start, 2.0 * np.pi)  # from the sector's start, ccw
            # the nearest point of the channel's stretch of rim: inside it, at the piece's
            # angle, else at the nearer edge
            nearest = np.where(offset <= width, angle,
                               np.where(offset - width < 2.0 * np.pi - offset, end, start))
            distance = np.hypot(xy[:, 0] - radius * np.cos(nearest),
                                xy[:, 1] - radius * np.sin(nearest))
            distance[~free] = np.inf
            k = int(np.argmin(distance))
            if distance[k] > RIM_GATE:
                continue
            free[k] = False
            i = int(ids[k])
            taken.append(i)
            if self.hits.get(i, 0) >= self.settings.confirm:
                left.append(Exit(piece=i, t=float(when), channel=channel,
                                 mass=self._mass(i) if math.isnan(mass) else mass))
            explained += 1
        self._drop(taken)
        # the exits still to come are after t - EXIT_LAG: none can match an older one of
        # the twin's (pruned after the matching: a frame after a long gap matches its own)
        self._recent_exits = [e for e in self._recent_exits
                              if e[0] >= t - EXIT_LAG - EXIT_MATCH]
        return len(due), taken, left, explained

    def _merge(self, t: float) -> list[int]:
        """
        Drop one of two pieces within the gate of each other, not both seen at t.

        The one seen in fewer frames goes (a tentative piece), else the one not seen at t,
        else the younger. Return the dropped.

        Two of the twin's pieces where the camera sees one (a piece the gate missed for a
        frame is born again) would take its detections in turn, and neither would die. Two
        pieces that both took a detection are two pieces, however close (pieces touching
        on the cone: measured on 30 pieces without contact, where a tenth of them overlap,
        dropping the younger of any close pair bore 70 pieces a second again). A confirmed
        piece the camera missed next to a false detection is kept (the hard plant of
        test_twin_live.py lost one so).
        """
        ids, mean, spread = self.pieces(tentative=True)
        noise = 2.0 * self.settings.sigma ** 2 * np.eye(2)
        dropped: list[int] = []
        apart = np.hypot(*(mean[:, None, :] - mean[None, :, :]).transpose(2, 0, 1))
        near = np.argwhere(np.triu(apart < 10.0 * self.settings.sigma + 1e-3, k=1))
        for a, b in near:  # a cheap prefilter, then the gate (pairs in id order: a < b)
            d = mean[b] - mean[a]
            i, j = int(ids[a]), int(ids[b])
            seen_i, seen_j = self.last_seen.get(i) == t, self.last_seen.get(j) == t
            if (i in dropped or j in dropped or (seen_i and seen_j)
                    or d @ np.linalg.solve(spread[a] + spread[b] + noise, d) >= GATE_CHI2):
                continue
            rank_i = (self.hits.get(i, 0), seen_i, -i)  # the lower rank goes (i < j: older)
            rank_j = (self.hits.get(j, 0), seen_j, -j)
            dropped.append(i if rank_i < rank_j else j)
        self._drop(dropped)
        return dropped

    def _common(self) -> np.ndarray:
        ids = self.states[0].ids
        for s in self.states[1:]:
            if not np.array_equal(s.ids, ids):  # the members mostly hold the same pieces
                ids = ids[np.isin(ids, s.ids)]
        return ids

    def _apart(self, state: SimState, ids: np.ndarray, reach: float) -> np.ndarray:
        """Return whether each piece ids (n,) has no other piece of state within reach (m)."""
        xy = state.y[:, :2]
        rows = self._rows(state, ids)
        distance = np.hypot(*(xy[rows, None, :] - xy[None, :, :]).transpose(2, 0, 1))
        distance[np.arange(len(rows)), rows] = np.inf
        return np.all(distance > reach, axis=1)

    def _rows(self, state: SimState, ids: np.ndarray) -> np.ndarray:
        if np.array_equal(state.ids, ids):
            return np.arange(len(ids), dtype=np.int64)
        order = {int(i): k for k, i in enumerate(state.ids)}
        return np.array([order[int(i)] for i in ids], dtype=np.int64)

    def _world(self, state: SimState, ids: np.ndarray, omega: float) -> np.ndarray:
        q, _, _ = world_from_cone(state.y[self._rows(state, ids)], state.angle, omega)
        return q

    def _analyse(self, ids: np.ndarray, pairs: np.ndarray, xy: np.ndarray) -> tuple[float, int]:
        """
        Analyse the members against the pairs' detections; return NIS and its dof.

        Only :data:`ANALYSED` of each piece's state are updated; each piece keeps its height
        above the cone's surface where its x, y moved, and the change of its velocity and
        filter force in x, y gets the z part that keeps it along the surface (as
        :mod:`..fit.shooting` places pieces). A piece that rides with the cone in every
        member (:data:`STILL`) keeps its velocity and filter force: where it sticks, their
        sampled correlations with its position are noise, and updating them set off the
        friction law's stiff transients in the next prediction (doc/twin.md, "A piece that
        rides with the cone").
        """
        n, per = len(ids), len(ANALYSED)
        width = per * n
        rows = [self._rows(s, ids) for s in self.states]
        ensemble = np.stack([np.concatenate([s.y[r][:, ANALYSED].ravel(), [ld, mu]])
                             for s, r, ld, mu in zip(self.states, rows, self.log_d, self.mu_c)])
        centre = ensemble[:, :width].mean(axis=0)  # the pieces' states; the parameters drift
        ensemble[:, :width] = centre + self.settings.inflation * (ensemble[:, :width] - centre)
        angle = self.states[0].angle
        seen = rotate_z(np.column_stack([xy[pairs[:, 1]], np.zeros(len(pairs))]), -angle)
        columns = np.concatenate([per * pairs[:, 0], per * pairs[:, 0] + 1])  # x, y: first
        values = np.concatenate([seen[:, 0], seen[:, 1]])
        sigma = np.full(len(columns), self.settings.sigma)
        groups = (np.concatenate([np.repeat(np.arange(n), per), [-1, -1]])
                  if len(self.states) < self.settings.localize_below else None)
        result = analyse(ensemble, columns, values, sigma, self.rng, groups)
        if self.settings.window <= 0.0:  # else the smoother analyses them, once a window
            self.log_d = np.clip(result.ensemble[:, width], *LOG_D_RANGE)
            self.mu_c = np.clip(result.ensemble[:, width + 1], *MU_C_RANGE)
        slope = self.params.model.h / self.params.model.r
        riding = np.all([np.linalg.norm(s.y[r, 3:6], axis=1) < STILL
                         for s, r in zip(self.states, rows)], axis=0)
        states = []
        for s, r, row in zip(self.states, rows, result.ensemble):
            y = s.y.copy()
            before = y[r].copy()
            y[r[:, None], ANALYSED] = row[:width].reshape(n, per)
            y[r[riding], 3:9] = before[riding, 3:9]
            change = y[r] - before
            x, rho = y[r, 0:2], np.maximum(np.hypot(y[r, 0], y[r, 1]), 1e-9)
            # along the surface: z follows rho, w_z and P_z their x, y parts' radial change
            y[r, 2] -= slope * (rho - np.hypot(before[:, 0], before[:, 1]))
            y[r, 5] -= slope * np.sum(x * change[:, 3:5], axis=1) / rho
            y[r, 8] -= slope * np.sum(x * change[:, 6:8], axis=1) / rho
            states.append(replace(s, y=y))
        self.states = [self._with_products(s, k) for k, s in enumerate(states)]
        return result.nis, result.observed

    def _smooth(self) -> None:
        """
        Weigh d and mu_C against the window's detections at once (:mod:`.particles`).

        The smoother's members ran over the window alongside the twin's, without analyses,
        each with one of the values (:meth:`_start_window`); the likelihood of the
        window's detections given its predictions weighs them, and the values are resampled,
        jittered and put in a random order: the members take the first of them. The frames
        that missed a piece some copies kept add theirs (:data:`MISSED_FRAME`); a window
        without either keeps its values as they are.
        Measured against the frame-by-frame Kalman update of the parameters (window 0) and
        a linear ensemble smoother over the window (tried, not kept): doc/twin.md.
        """
        log_likelihood = self._missed.copy()  # (P,), or (0,) before the first window
        if self._predicted:
            g, y = np.concatenate(self._predicted, axis=1), np.concatenate(self._observed)
            log_likelihood += window_log_likelihood(
                g - y, np.concatenate(self._anomalies, axis=1),
                np.concatenate(self._observed_ids), self.settings.sigma)
        elif not np.any(log_likelihood != log_likelihood[:1]):
            return  # nothing told the values apart
        parameters, _ = resample_parameters(np.column_stack([self.log_d, self.mu_c]),
                                            log_likelihood, self.rng)
        # systematic resampling keeps the parents' order: the members take a random choice
        parameters = parameters[self.rng.permutation(len(parameters))]
        self.log_d = np.clip(parameters[:, 0], *LOG_D_RANGE)
        self.mu_c = np.clip(parameters[:, 1], *MU_C_RANGE)  # the members take them next

    def _start_window(self, t: float) -> None:
        """
        Start a window at t (s): the parameters' random walk, the smoother's members.

        Where the parameters' random walk ends at the window's end is drawn here
        (:attr:`_walk`): the members go there frame by frame on a Brownian bridge
        (:meth:`_drift`: the random walk's law, its end given), and the smoother's members
        run with that end, the parameters the window's end weighs, as when the window ran
        again at its end. Measured over seeds 1-3 of benchmarks/twin_forecast_scores.py
        (the most likely channel right 0.25 / 0.5 / 1 s before the exit, of 267 / 237 / 81;
        channel-mass error over 1 s): the window run again at its end 215 / 159 / 29, 0.284
        kg; this 212 / 159 / 24, 0.284 kg; tried: the walk taken all at the window's start
        194 / 158 / 24, 0.301 kg; the members going to the end in a straight line 200 / 154 /
        29, 0.299 kg.

        Each smoother member is the members' mean state with one of the P values of d and
        mu_C (:attr:`log_d`, :attr:`mu_c`), so that their predictions differ by their
        parameters alone: run from the members' own states, the state's noise made the
        likelihoods differ by tens to thousands for parameters that change no position
        (pieces that stick), the weights a lottery, and the parameters drift (mu_C to 0.98
        +- 0.04 for a truth of 0.7, benchmarks/twin_identify.py at 6 rad/s). They run frame
        by frame with the twin's members (:meth:`predict`), so that no frame carries the
        whole window's run. Only the pieces every member holds now count; of them the
        ``smoother_pieces`` that slide fastest relative to the cone in the members' mean
        (ties: the older). M more smoother members run from each member's own state with the
        values' mean d and mu_C: how their predictions spread is what the mean start's error
        does to the smoother's, which the likelihood integrates out
        (:func:`window_log_likelihood`).
        A copy whose piece left the cone predicts it where it left, and a frame that does not
        see a piece costs the values whose copy holds it (:meth:`_window_frame`).

        The Q copies of the pieces are in one state, run without the pair law (the copies of
        a piece overlap), in one result. With contact on (the members' pair law), only
        pieces with no other piece within 3 s0 in every member are weighed: a piece alone
        slides as the copies do, until it meets another in the window. (Each copy in a
        state of its own with the pair law, as before, cost 30 of 37 ms a frame at 10
        pieces and 4 members, against 7 ms without contact: doc/twin.md.)
        """
        self._window_t0, self._predicted, self._observed = t, [], []
        self._observed_ids, self._anomalies, self._departed = [], [], {}
        self._missed = np.zeros(len(self.log_d))
        self._window_pieces = np.zeros(0, dtype=np.int64)
        self._smoother = None
        self._drifted = t
        scale = self.settings.drift * math.sqrt(self.settings.window)
        p = len(self.log_d)
        self._walk = (np.clip(self.log_d + scale * self.rng.standard_normal(p), *LOG_D_RANGE),
                      np.clip(self.mu_c + scale * self.rng.standard_normal(p), *MU_C_RANGE))
        self.states = [self._with_products(s, k) for k, s in enumerate(self.states)]
        if not all(s.count for s in self.states):
            return
        first = self.states[0]
        held = first.ids[np.all([np.isin(first.ids, s.ids) for s in self.states], axis=0)]
        if self.params.model.interactions.enabled:  # the pieces apart from every other
            reach = 3.0 * self.params.model.product.s0
            held = held[np.all([self._apart(s, held, reach) for s in self.states], axis=0)]
        sliding = np.mean([np.linalg.norm(s.y[self._rows(s, held), 3:6], axis=1)
                           for s in self.states], axis=0).reshape(len(held))
        held = np.sort(held[np.argsort(-sliding, kind='stable')[:self.settings.smoother_pieces]])
        if not len(held):  # every member holds pieces, but not one the same: nothing to weigh
            return
        base = remove_particles(first, sorted(set(first.ids.tolist()) - set(held.tolist())))
        self._window_pieces = base.ids.copy()
        rows = np.stack([s.y[self._rows(s, base.ids)] for s in self.states])
        # the P values from the members' mean start, then each member's start with the
        # values' mean (what the mean start's error does to the predictions)
        mean = (np.array([self._walk[0].mean()]), np.array([self._walk[1].mean()]))
        members = ([self._with_products(replace(base, y=rows.mean(axis=0)), k, self._walk)
                    for k in range(p)]
                   + [self._with_products(replace(base, y=y), 0, mean) for y in rows])
        # the copies in one state, run without the pair law (they overlap): one result
        n, q = base.count, len(members)
        self._smoother = [replace(
            base, y=np.stack([s.y for s in members], axis=1).reshape(n * q, -1),
            products=np.stack([s.products for s in members], axis=1).reshape(n * q, -1),
            ids=(base.ids[:, None] * q + np.arange(q)).ravel(),
            step_size=np.repeat(base.step_size, q), next_id=(int(base.ids.max()) + 1) * q)]

    def _window_frame(self, t: float, ids: np.ndarray, xy: np.ndarray,
                      followed: np.ndarray) -> None:
        """
        Add the smoother's predictions of a frame's associated detections (ids, xy).

        followed: the pieces the frame's detections were associated against (ids).

        A piece counts while some copy of it is on the cone. A copy whose piece left
        predicts it where it left (one whose integration failed, where it failed): a value
        that made a piece leave while the camera still sees it is weighed by how far the
        piece is from that point. (Dropped from the likelihood instead, as before, such a
        value went unpunished: the piece stopped counting for every value.) A piece of the
        window that the twin still follows and that no detection was associated with costs
        each value whose copy still holds it :data:`MISSED_FRAME`. (Not a piece the twin
        dropped: the camera may see it under another id, and the values that kept it would
        pay for being right.)
        """
        if self._smoother is None:
            return
        inside = np.isin(ids, self._window_pieces)  # only they have copies
        ids, xy = ids[inside], xy[inside]
        omega = self._profile.omega(t)
        p, q = len(self.log_d), len(self.log_d) + len(self.states)
        present, at = self._copies(ids, omega)
        counted = np.all(np.isfinite(at[:, :, 0]), axis=0) & np.any(present, axis=0)
        held = ids[counted]
        predicted = at[:, counted].reshape(q, -1)
        unseen = np.setdiff1d(np.intersect1d(self._window_pieces, followed), ids)
        if len(unseen):
            self._missed += MISSED_FRAME * self._copies(unseen, omega)[0][:p].sum(axis=1)
        if not len(held):
            return
        self._predicted.append(predicted[:p])
        self._anomalies.append(predicted[p:] - predicted[p:].mean(axis=0))
        self._observed.append(xy[counted].ravel())
        self._observed_ids.append(np.repeat(held, 2))

    def _copies(self, ids: np.ndarray, omega: float) -> tuple[np.ndarray, np.ndarray]:
        """
        Return where the smoother's Q copies of pieces ids (n,) are.

        Returns on the cone (Q, n) bool, and world x, y (Q, n, 2) (m): where the copy is,
        where it left or failed (:attr:`_departed`), or NaN where it is neither (a piece
        the window does not hold).
        """
        q = len(self.log_d) + len(self.states)
        (state,) = self._smoother  # the copies of each piece in one state: id * Q + k
        keys = ids[None, :] * q + np.arange(q)[:, None]
        here = np.isin(keys, state.ids)
        where = np.full(keys.shape + (2,), np.nan)
        where[here] = self._world(state, keys[here], omega)[:, :2]
        for a, b in zip(*np.nonzero(~here)):
            where[a, b] = self._departed.get((0, int(keys[a, b])), np.nan)
        return here, where

    def _product(self, member: int, mass: float, parameters: Walk | None = None) -> ProductParams:
        log_d, mu_c = parameters or (self.log_d, self.mu_c)
        return replace(self.params.model.product, m=mass, d=float(np.exp(log_d[member])),
                       mu_C=float(mu_c[member]))

    def _with_products(self, state: SimState, member: int,
                       parameters: Walk | None = None) -> SimState:
        """Return the state with its products' rows for the member's d and mu_C (log d, mu_C)."""
        if not state.count:
            return state
        # one row, each piece's mass in its column (no other column depends on the mass):
        # a row per piece would cost 30 us each, with masses from load cells all differing;
        # each piece keeps the mass it was born with (see masses)
        row = product_row(self._product(member, self.params.model.product.m, parameters))
        products = np.repeat(row[None, :], state.count, axis=0)
        products[:, P_M] = state.products[:, P_M]
        return replace(state, products=products)

    def _birth(self, xy: np.ndarray, masses: np.ndarray | None, t: float) -> None:
        model = self.params.model
        first = self.states[0].next_id
        mean = self.piece_mass
        camera = [masses is not None and math.isfinite(masses[k]) for k in range(len(xy))]
        weights = [float(masses[k]) if camera[k] else mean for k in range(len(xy))]
        omega = self._profile.omega(self.t)
        grown = []
        for member, state in enumerate(self.states):
            points = xy + self.settings.sigma * self.rng.standard_normal(xy.shape)
            products = [self._product(member, w) for w in weights]
            q = np.array([[x, y, resting_height(model, product, x, y)]
                          for (x, y), product in zip(points, products)])
            state, ids = add_particles(state, self.params, q, products=products, omega=omega)
            grown.append(state)
        self.states = grown
        for k, i in enumerate(ids.tolist()):
            assert i == first + k  # every member numbers its pieces alike
            self._camera_mass[i] = weights[k] if camera[k] else math.nan
            self.last_seen[i] = t
            self.hits[i] = 1

    def _drop(self, ids: list[int]) -> None:
        if ids:
            self.states = [remove_particles(s, ids) for s in self.states]
        for i in ids:
            self._leaving.pop(i, None)
            self._camera_mass.pop(i, None)
            self.last_seen.pop(i, None)
            self.hits.pop(i, None)
            self.tracks.pop(i, None)

    def _drift(self, t: float) -> None:
        """Move the parameters along their random walk to t (s): the window's, or a step."""
        if self._walk is not None:  # a Brownian bridge to the walk's end at the window's end
            log_d_end, mu_c_end = self._walk
            end = self._window_t0 + self.settings.window
            step, left = max(t - self._drifted, 0.0), max(end - self._drifted, 0.0)
            self._drifted = t
            if step <= 0.0:
                return
            if step >= left:
                self.log_d, self.mu_c = log_d_end, mu_c_end
                return
            share = step / left
            scale = self.settings.drift * math.sqrt(step * (1.0 - share))
            m = len(self.log_d)
            self.log_d = (self.log_d + share * (log_d_end - self.log_d)
                          + scale * self.rng.standard_normal(m))
            self.mu_c = (self.mu_c + share * (mu_c_end - self.mu_c)
                         + scale * self.rng.standard_normal(m))
            return
        elapsed = max(t - self._drifted, 0.0)
        self._drifted = t
        if elapsed > 0.0:
            scale = self.settings.drift * math.sqrt(elapsed)
            self.log_d = self.log_d + scale * self.rng.standard_normal(len(self.log_d))
            self.mu_c = self.mu_c + scale * self.rng.standard_normal(len(self.mu_c))
