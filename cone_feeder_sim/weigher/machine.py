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
The multihead weigher below the cone: dosing channels, pool and weigh hoppers, packs.

A piece that leaves the cone into channel c (1-based, as in the exit events) rides that
channel's vibratory trough to its pool hopper. It takes ``transport_time`` at feed
amplitude 1; at amplitude a it advances a/transport_time of the trough per second, so the
pieces of a channel keep their order, and amplitude 0 stops the trough. A pool hopper
passes its whole content to the weigh hopper below when that one is empty; the gate takes
``gate_time``. A weigh hopper then settles for ``settle_time`` and is weighed once, with
load-cell noise (normal, ``load_cell_noise`` kg), and from then on takes part in the
combination. Every machine cycle (``cycles_per_minute``) the combination of weighed
hoppers is chosen by :func:`combination.select_combination` on the readings, oldest
product first on ties, and discharged into one pack.

:class:`Weigher` holds the machine's state and advances it by :meth:`Weigher.advance`;
every kilogram that came in is in a trough, a pool hopper, a gate, a weigh hopper or a
pack (:meth:`Weigher.balance`). No rclpy, no file I/O.
"""

from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, fields
import math
from typing import Any

import numpy as np

from .combination import MAX_SUBSETS, select_combination, subset_count
from ..errors import ParameterError
from ..physics.params import check_integer, check_number, Limit, MODEL_LIMITS

__all__ = ['check_machine', 'HEADS_LIMIT', 'Pack', 'Weigher', 'WEIGHER_LIMITS', 'WeigherParams',
           'WeigherStats', 'weigher_params_from_mapping']

#: Ranges of the weigher's parameters (units in the third field).
WEIGHER_LIMITS: dict[str, Limit] = {
    'target': Limit(0.0, 100.0, 'kg', lo_open=True),
    'max_over': Limit(0.0, 100.0, 'kg'),
    'tolerable_negative_error': Limit(0.0, 100.0, 'kg'),
    'min_heads': Limit(1, 32, 'heads'),
    'max_heads': Limit(1, 32, 'heads'),
    'cycles_per_minute': Limit(0.0, 600.0, '1/min', lo_open=True),
    'transport_time': Limit(0.0, 60.0, 's', lo_open=True),
    'gate_time': Limit(0.0, 10.0, 's'),
    'settle_time': Limit(0.0, 10.0, 's'),
    'load_cell_noise': Limit(0.0, 1.0, 'kg'),
    'seed': Limit(0, 2 ** 63 - 1, ''),
}
_INTEGERS = ('min_heads', 'max_heads', 'seed')
#: Heads of a machine: one per channel of the cone (the range of model.channel_count).
HEADS_LIMIT = MODEL_LIMITS['channel_count']


@dataclass(frozen=True)
class WeigherParams:
    """
    The machine below the cone (config/weigher.yaml; ranges in :data:`WEIGHER_LIMITS`).

    The machine has one head (dosing channel, pool and weigh hopper) per channel of the
    cone: the paper's has 14. target (kg) pack target; max_over (kg) most a pack may
    exceed the target (0 = no limit); tolerable_negative_error (kg) the legal TNE below
    the target; min_heads, max_heads hoppers per pack; cycles_per_minute machine cycles;
    transport_time (s) rim to pool hopper at feed amplitude 1; gate_time (s) pool to weigh
    hopper; settle_time (s) before a weigh hopper is weighed; load_cell_noise (kg)
    standard deviation of one weighing; seed of the load-cell noise.
    """

    target: float = 1.0
    max_over: float = 0.0
    tolerable_negative_error: float = 0.015
    min_heads: int = 1
    max_heads: int = 14
    cycles_per_minute: float = 60.0
    transport_time: float = 2.0
    gate_time: float = 0.3
    settle_time: float = 0.4
    load_cell_noise: float = 0.0005
    seed: int = 0

    def __post_init__(self) -> None:
        """Validate every field against :data:`WEIGHER_LIMITS`; name the key on failure."""
        for key, limit in WEIGHER_LIMITS.items():
            check = check_integer if key in _INTEGERS else check_number
            object.__setattr__(self, key, check(f'weigher.{key}', getattr(self, key), limit))
        if self.max_heads < self.min_heads:
            raise ParameterError(f"parameter 'weigher.max_heads' ({self.max_heads}) must not "
                                 f'be below weigher.min_heads ({self.min_heads})')

    @property
    def cycle(self) -> float:
        """Return the machine cycle in s."""
        return 60.0 / self.cycles_per_minute


def check_machine(params: WeigherParams, heads: int) -> int:
    """
    Return ``heads`` (one per cone channel) once a machine of them can run with ``params``.

    Refuses a head count outside :data:`HEADS_LIMIT` and a machine whose combinations are
    too many to enumerate every cycle (:data:`combination.MAX_SUBSETS`), naming the key.
    """
    heads = check_integer('heads (model.channel_count)', heads, HEADS_LIMIT)
    count = subset_count(heads, params.min_heads, params.max_heads)
    if count > MAX_SUBSETS:
        raise ParameterError(
            f"parameter 'weigher.max_heads': {heads} heads with {params.min_heads}.."
            f'{params.max_heads} per pack are {count:,} combinations, more than '
            f'{MAX_SUBSETS:,} to choose from each cycle; lower weigher.max_heads')
    return heads


def weigher_params_from_mapping(mapping: Any, base: WeigherParams | None = None) -> WeigherParams:
    """Build validated weigher parameters from a ``weigher`` mapping over ``base``."""
    base = base if base is not None else WeigherParams()
    if mapping is None:
        mapping = {}
    if not isinstance(mapping, Mapping):
        raise ParameterError(f'weigher must be a mapping of weigher parameters, got {mapping!r}')
    known = [f.name for f in fields(WeigherParams)]
    unknown = sorted(str(k) for k in set(mapping) - set(known))
    if unknown:
        raise ParameterError(f'unknown weigher key(s) {", ".join(map(repr, unknown))}; '
                             f'known: {", ".join(known)}')
    values = {f.name: getattr(base, f.name) for f in fields(WeigherParams)}
    values.update(mapping)
    return WeigherParams(**values)


@dataclass(frozen=True)
class Pack:
    """
    One pack.

    index (from 1); t (s) discharge time; mass (kg, true); measured (kg, the readings'
    sum); heads (the heads discharged, 1-based like the channels); giveaway (kg,
    mass - target).
    """

    index: int
    t: float
    mass: float
    measured: float
    heads: tuple[int, ...]
    giveaway: float


@dataclass(frozen=True)
class WeigherStats:
    """
    Statistics of the packs so far.

    packs; packs_per_minute over the time run; giveaway_mean, giveaway_std (kg);
    under_target, below_tne: fractions of packs with mass < target and < target - TNE;
    starved_per_cycle: mean number of heads without a weighed product at a cycle; cycles.
    """

    packs: int
    packs_per_minute: float
    giveaway_mean: float
    giveaway_std: float
    under_target: float
    below_tne: float
    starved_per_cycle: float
    cycles: int


class Weigher:
    """The weigher's state, advanced in time by :meth:`advance`; see the module docs."""

    def __init__(self, params: WeigherParams, heads: int = 14, t0: float = 0.0) -> None:
        """Start an empty machine of ``heads`` heads at t0 (s); the first cycle one later."""
        self.params = params
        heads = check_machine(params, heads)
        self.heads = heads
        self.t = float(t0)
        self.amplitude = np.ones(heads)
        #: per channel: [progress in [0, 1), mass] of the pieces on the trough, oldest first
        self._troughs: list[deque[list[float]]] = [deque() for _ in range(heads)]
        self.pool = np.zeros(heads)
        self._gate_until = np.full(heads, -math.inf)  # a gate is open until this time
        self.gate = np.zeros(heads)  # mass falling through the gate
        self.weigh = np.zeros(heads)  # true mass in the weigh hopper
        self._weighed_at = np.full(heads, math.nan)  # reading time; nan: not weighed yet
        self._settled_at = np.full(heads, math.nan)
        self.reading = np.zeros(heads)
        self._next_cycle = self.t + params.cycle  # cycle k at t0 + k cycle, not summed
        self._rng = np.random.default_rng(params.seed)
        self.mass_in = 0.0
        self.packed = 0.0
        self.packs: list[Pack] = []
        self._cycles = 0
        self._starved = 0
        self._t0 = self.t
        # running statistics of the giveaway (Welford), so stats() costs O(1)
        self._mean = 0.0
        self._m2 = 0.0
        self._under = 0
        self._below = 0

    # inputs -------------------------------------------------------------------------------
    def receive(self, channels: Iterable[int], masses: Iterable[float],
                times: Iterable[float] | None = None) -> None:
        """
        Put pieces that left the cone on their channels' troughs (channels 1-based).

        times (s): when each piece left, at or after the machine's time (default: now); the
        next :meth:`advance` carries it from then on, so a piece that left late in an
        interval is not early at its pool hopper. Pieces go on in the order of their times.
        """
        channels = list(channels)
        masses = list(masses)
        times = [self.t] * len(channels) if times is None else [float(t) for t in times]
        if not len(channels) == len(masses) == len(times):
            raise ParameterError(f'receive needs as many channels, masses and times; got '
                                 f'{len(channels)}, {len(masses)}, {len(times)}')
        checked = []
        for channel, mass, t in zip(channels, masses, times):  # all checked, then taken
            if not (math.isfinite(t) and t >= self.t):
                raise ParameterError(f'a piece cannot reach the weigher at {t!r} s, before '
                                     f'its time {self.t} s')
            channel = int(channel)
            if not 1 <= channel <= self.heads:
                raise ParameterError(f"channel {channel} is not one of the weigher's "
                                     f'{self.heads} channels')
            mass = float(mass)
            if not (math.isfinite(mass) and mass >= 0.0):
                raise ParameterError(f'a piece mass must be finite and >= 0, got {mass!r}')
            checked.append((t, channel, mass))
        for t, channel, mass in sorted(checked, key=lambda item: item[0]):
            lead = (t - self.t) * self.amplitude[channel - 1] / self.params.transport_time
            self._troughs[channel - 1].append([-lead, mass])
            self.mass_in += mass

    def set_amplitude(self, amplitude: Any) -> None:
        """Set the feed amplitude of every channel, (heads,) in [0, 2]; 0 stops a trough."""
        values = np.asarray(amplitude, dtype=float).reshape(-1)
        if values.shape != (self.heads,):
            raise ParameterError(f'amplitude needs {self.heads} values, got '
                                 f'{values.shape[0]}')
        if not (np.isfinite(values).all() and (values >= 0.0).all() and (values <= 2.0).all()):
            raise ParameterError(f'amplitude values must be in [0, 2], got {values.tolist()}')
        self.amplitude = values.copy()

    # time ---------------------------------------------------------------------------------
    def advance(self, t1: float) -> list[Pack]:
        """Advance the machine to t1 (s); return the packs made on the way."""
        made = []
        while True:
            t_next = min(t1, self._next_cycle)
            self._flow(t_next)
            if self._next_cycle > t1:
                break
            pack = self._cycle()
            if pack is not None:
                made.append(pack)
            self._next_cycle = self._t0 + (self._cycles + 1) * self.params.cycle
        return made

    def _flow(self, t1: float) -> None:
        """Move product through troughs, gates and weigh hoppers up to t1 (no cycle)."""
        p = self.params
        dt = t1 - self.t
        if dt < 0.0:
            raise ParameterError(f'time must not go back: {t1} < {self.t}')
        for c in range(self.heads):
            trough = self._troughs[c]
            step = self.amplitude[c] * dt / p.transport_time
            for piece in trough:
                piece[0] += step
            while trough and trough[0][0] >= 1.0:
                self.pool[c] += trough.popleft()[1]
        # gates that finished: their product lands in the weigh hopper, which settles
        done = (self._gate_until <= t1) & (self.gate > 0.0)
        for c in np.flatnonzero(done):
            self.weigh[c] += self.gate[c]
            self.gate[c] = 0.0
            self._settled_at[c] = self._gate_until[c] + p.settle_time
        # empty weigh hoppers take the pool's content (the gate opens now)
        start = (self.weigh == 0.0) & (self.gate == 0.0) & (self.pool > 0.0)
        for c in np.flatnonzero(start):
            self.gate[c] = self.pool[c]
            self.pool[c] = 0.0
            self._gate_until[c] = t1 + p.gate_time
            if p.gate_time == 0.0:
                self.weigh[c] += self.gate[c]
                self.gate[c] = 0.0
                self._settled_at[c] = t1 + p.settle_time
        # settled hoppers are weighed once
        ready = (self.weigh > 0.0) & np.isnan(self._weighed_at) & (self._settled_at <= t1)
        for c in np.flatnonzero(ready):
            noise = self._rng.normal(0.0, p.load_cell_noise) if p.load_cell_noise else 0.0
            self.reading[c] = max(self.weigh[c] + noise, 1e-12)
            self._weighed_at[c] = t1
        self.t = t1

    def _cycle(self) -> Pack | None:
        """Choose and discharge one combination at the cycle time self.t."""
        p = self.params
        self._cycles += 1
        available = ~np.isnan(self._weighed_at)
        self._starved += int(self.heads - available.sum())
        weights = np.where(available, self.reading, 0.0)
        ages = np.where(available, self.t - np.nan_to_num(self._weighed_at), 0.0)
        chosen = select_combination(weights, p.target,
                                    max_over=p.max_over if p.max_over > 0.0 else None,
                                    min_heads=p.min_heads, max_heads=p.max_heads, ages=ages)
        if chosen is None:
            return None
        heads = list(chosen)
        mass = 0.0
        for c in heads:
            mass += float(self.weigh[c])
        measured = 0.0
        for c in heads:
            measured += float(self.reading[c])
        self.weigh[heads] = 0.0
        self.reading[heads] = 0.0
        self._weighed_at[heads] = math.nan
        self._settled_at[heads] = math.nan
        self.packed += mass
        pack = Pack(index=len(self.packs) + 1, t=self.t, mass=mass, measured=measured,
                    heads=tuple(c + 1 for c in heads), giveaway=mass - p.target)
        self.packs.append(pack)
        n = len(self.packs)
        delta = pack.giveaway - self._mean
        self._mean += delta / n
        self._m2 += delta * (pack.giveaway - self._mean)
        self._under += mass < p.target
        self._below += mass < p.target - p.tolerable_negative_error
        self._flow(self.t)  # emptied hoppers take their pools' content at once
        return pack

    # accounting ---------------------------------------------------------------------------
    def in_troughs(self) -> np.ndarray:
        """Return the mass on each trough, (heads,) kg."""
        return np.array([sum(piece[1] for piece in trough) for trough in self._troughs])

    def balance(self) -> dict[str, float]:
        """Return where the mass is (kg): in, troughs, pools, gates, weigh hoppers, packed."""
        return {'in': self.mass_in, 'troughs': float(self.in_troughs().sum()),
                'pools': float(self.pool.sum()), 'gates': float(self.gate.sum()),
                'weigh': float(self.weigh.sum()), 'packed': self.packed}

    def hopper_readings(self) -> np.ndarray:
        """Return the weigh hoppers' readings, (heads,) kg; 0 where not weighed yet."""
        return np.where(self.available(), self.reading, 0.0)

    def available(self) -> np.ndarray:
        """Return which weigh hoppers are weighed and take part in the next cycle, (heads,)."""
        return ~np.isnan(self._weighed_at)

    def stats(self) -> WeigherStats:
        """Return the statistics of the packs so far (O(1): kept as the packs are made)."""
        minutes = (self.t - self._t0) / 60.0
        n = len(self.packs)
        return WeigherStats(
            packs=n, packs_per_minute=n / minutes if minutes > 0 else 0.0,
            giveaway_mean=self._mean if n else 0.0,
            giveaway_std=math.sqrt(self._m2 / (n - 1)) if n > 1 else 0.0,
            under_target=self._under / n if n else 0.0,
            below_tne=self._below / n if n else 0.0,
            starved_per_cycle=self._starved / self._cycles if self._cycles else 0.0,
            cycles=self._cycles)
