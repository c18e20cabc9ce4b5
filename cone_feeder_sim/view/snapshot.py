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
What a view shows at one moment, taken from the headless runner or the engine.

A :class:`Snapshot` is a copy of the state that a view draws later, on its own thread:
the pieces in the world frame, the cone's angle and speed, the channel masses and the
hopper readings. :class:`Watcher` takes a :class:`Moment` (the state as it is, nothing
computed) from the runner's progress callback or from the engine's ticks, turns exits and
packs into :class:`Event` lines, and makes the snapshot of a moment later, on the view's
thread. numpy and scipy; no viewer library.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..feeder.engine import FeederEngine, TickResult
from ..physics.params import ModelParams, P_M, P_S0
from ..physics.simulation import (
    ExitEvents, SimState, Simulator, StepResult, world_from_cone)
from ..weigher.machine import Pack, Weigher

__all__ = ['Event', 'Moment', 'ProductKinds', 'Snapshot', 'touching_pairs', 'Watcher']


@dataclass(frozen=True)
class Snapshot:
    """
    The feeder at simulation time t (s).

    angle (rad) the cone's angle phi; omega (rad/s) its speed; ids (N,) int64 the pieces'
    ids; positions (N, 3) m in the world frame; radii (N,) m their outer radius s0; kinds
    (N,) int a product index per piece (stable over a run: the colour); contacts (K, 2) int
    the index pairs of touching pieces (empty without contact between pieces);
    channel_mass (C,) kg the mass each channel received; hoppers (H,) kg the weigh
    hoppers' readings, None without a weigher.
    """

    t: float
    angle: float
    omega: float
    ids: np.ndarray
    positions: np.ndarray
    radii: np.ndarray
    kinds: np.ndarray
    contacts: np.ndarray
    channel_mass: np.ndarray
    hoppers: np.ndarray | None


@dataclass(frozen=True)
class Event:
    """A line for the event log: at t (s), ``text``; ``kind`` 'exit' or 'pack'."""

    t: float
    kind: str
    text: str


def touching_pairs(positions: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """
    Return the index pairs (K, 2), i < j, sorted, of pieces closer than their radii's sum.

    positions (N, 3) m; radii (N,) m. Candidates come from scipy's KD-tree within twice the
    largest radius.
    """
    if positions.shape[0] < 2:
        return np.zeros((0, 2), dtype=np.int64)
    from scipy.spatial import cKDTree  # here: 0.2 s of every command's start-up otherwise
    near = cKDTree(positions).query_pairs(2.0 * float(radii.max()), output_type='ndarray')
    gap = np.linalg.norm(positions[near[:, 0]] - positions[near[:, 1]], axis=1)
    pairs = near[gap < radii[near[:, 0]] + radii[near[:, 1]]].astype(np.int64)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


class ProductKinds:
    """
    A product index per piece, in order of first appearance: its colour.

    A product is a product row without its mass: the feed draws every piece's mass (its
    ``mass_rel_std``), and pieces of one product differ only in that. A piece keeps the
    index it got first (by id); ids that left are forgotten.
    """

    def __init__(self) -> None:
        """Start with no products and no pieces seen."""
        self._index: dict[bytes, int] = {}
        self._by_id: dict[int, int] = {}

    def __call__(self, ids: np.ndarray, products: np.ndarray) -> np.ndarray:
        """Return the index (N,) int of each piece: ids (N,), products (N, PRODUCT_WIDTH)."""
        kinds = np.empty(ids.shape[0], dtype=np.int64)
        by_id = {}
        for k, piece in enumerate(ids.tolist()):
            kind = self._by_id.get(piece)
            if kind is None:
                row = products[k].copy()
                row[P_M] = 0.0
                kind = self._index.setdefault(row.tobytes(), len(self._index))
            by_id[piece] = kinds[k] = kind
        self._by_id = by_id
        return kinds


@dataclass(frozen=True)
class Moment:
    """
    What the simulation hands a view after a step: the state itself, nothing computed.

    state: the simulator's or engine's state (immutable: each step makes a new one);
    omega (rad/s); channel_mass (C,) kg and hoppers (H,) kg or None: copies.
    """

    state: SimState
    omega: float
    channel_mass: np.ndarray
    hoppers: np.ndarray | None


def exit_events(exits: ExitEvents) -> list[Event]:
    """Return a line per piece that left: its id, channel, angle and mass."""
    return [Event(float(t), 'exit', f'piece {int(i)} left into channel {int(c)} at '
                                    f'{float(a):.1f} deg ({1e3 * float(m):.0f} g)')
            for i, t, c, a, m in zip(exits.ids, exits.t, exits.channel, exits.angle_deg,
                                     exits.mass)]


def pack_events(packs: Sequence[Pack]) -> list[Event]:
    """Return a line per pack: its index, mass, giveaway and heads."""
    return [Event(pack.t, 'pack', f'pack {pack.index}: {1e3 * pack.mass:.1f} g (giveaway '
                                  f'{1e3 * pack.giveaway:+.1f} g), heads '
                                  f'{", ".join(str(h) for h in pack.heads)}')
            for pack in packs]


class Watcher:
    """
    Takes moments and events from a run and makes snapshots of them.

    The moments come from the runner's intervals or the engine's ticks. model: the run's
    model (the channel count, whether pieces touch); weigher: the machine the runner
    drives, for its hopper readings and packs (None: none).
    :meth:`interval` and :meth:`ticks` run on the simulation's thread and only copy what
    the next step changes in place; :meth:`snapshot` does the work, on the view's thread.
    """

    def __init__(self, model: ModelParams, weigher: Weigher | None = None) -> None:
        """Start at the beginning of a run: no channel mass, no packs seen."""
        self._contacts = model.interactions.enabled
        self._weigher = weigher
        self._kinds = ProductKinds()
        self._channel_mass = np.zeros(model.channels.count)
        self._packs_seen = 0

    def interval(self, t: float, sim: Simulator, step: StepResult) -> tuple[Moment, list[Event]]:
        """Return the moment and events of the runner's interval that ended at t (s)."""
        exits = step.exits
        events = []
        if len(exits):
            np.add.at(self._channel_mass, exits.channel - 1, exits.mass)
            events = exit_events(exits)
        hoppers = None
        if self._weigher is not None:
            hoppers = self._weigher.hopper_readings()
            events += pack_events(self._weigher.packs[self._packs_seen:])
            self._packs_seen = len(self._weigher.packs)
        return Moment(sim.state, sim.omega(), self._channel_mass.copy(), hoppers), events

    def ticks(self, engine: FeederEngine, results: Sequence[TickResult]
              ) -> tuple[Moment, list[Event]]:
        """Return the engine's moment now and the events of its ticks ``results``."""
        events = [event for result in results
                  for event in exit_events(result.exits) + pack_events(result.packs)]
        weigher = engine.weigher
        return Moment(engine.state, engine.omega, engine.channel_mass,
                      weigher.hopper_readings() if weigher is not None else None), events

    def snapshot(self, moment: Moment) -> Snapshot:
        """Return the snapshot of a moment: world positions, radii, kinds, contacts."""
        state = moment.state
        positions = world_from_cone(state.y, state.angle, moment.omega)[0]
        radii = state.products[:, P_S0].copy()
        contacts = (touching_pairs(positions, radii) if self._contacts
                    else np.zeros((0, 2), dtype=np.int64))
        return Snapshot(t=float(state.t), angle=float(state.angle), omega=float(moment.omega),
                        ids=state.ids.copy(), positions=positions, radii=radii,
                        kinds=self._kinds(state.ids, state.products), contacts=contacts,
                        channel_mass=moment.channel_mass, hoppers=moment.hoppers)
