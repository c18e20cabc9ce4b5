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

"""Tests of what a view shows: touching pairs against all pairs, colours by product."""

from cone_feeder_sim.physics.params import P_D, P_M, product_row, ProductParams
from cone_feeder_sim.view.snapshot import ProductKinds, touching_pairs
import numpy as np


def test_touching_pairs_and_product_kinds() -> None:
    rng = np.random.default_rng(5)
    positions = rng.uniform(-0.1, 0.1, (60, 3))
    radii = rng.uniform(0.01, 0.03, 60)
    expected = [(i, j) for i in range(60) for j in range(i + 1, 60)
                if np.linalg.norm(positions[i] - positions[j]) < radii[i] + radii[j]]
    assert len(expected) > 10
    assert [tuple(p) for p in touching_pairs(positions, radii)] == expected
    assert touching_pairs(positions[:1], radii[:1]).shape == (0, 2)
    rows = np.array([product_row(ProductParams().with_overrides(
        {'m': 0.1 + 0.01 * k, 'd': 30.0 if k % 3 else 750.0})) for k in range(6)])
    kinds = ProductKinds()
    first = kinds(np.arange(6), rows)
    assert first.tolist() == [0, 1, 1, 0, 1, 1]  # the mass is not the product, d is
    rows[:, P_M] = 0.5  # a piece keeps its colour; a new id of a new product gets the next
    rows[:, P_D] = 135.0
    assert kinds(np.array([5, 9]), rows[:2]).tolist() == [1, 2]


def test_a_moment_handed_over_is_not_changed_by_later_steps() -> None:
    """The view keeps the state object itself: later steps must make new arrays."""
    from cone_feeder_sim.feeder.engine import EngineConfig, FeederEngine, FeedParams
    from cone_feeder_sim.feeder.runner import start_simulator
    from cone_feeder_sim.formats.scenario_file import scenario_from_mapping
    from cone_feeder_sim.physics.params import ModelParams
    from cone_feeder_sim.view.snapshot import Watcher
    engine = FeederEngine(EngineConfig(feed=FeedParams(rate=50.0)))
    engine.command(5.0)
    watcher = Watcher(ModelParams())
    for _ in range(5):
        engine.tick()
    moment, _ = watcher.ticks(engine, [])
    scenario = scenario_from_mapping({'duration': 1.0, 'rotation': [[0.0, 6.0]], 'particles': [
        {'position': [0.1, 0.0, 0.0], 'on_surface': True},
        {'position': [0.0, 0.2, 0.0], 'on_surface': True}]})
    sim = start_simulator(scenario)
    interval, _ = watcher.interval(0.1, sim, sim.advance_to(0.1))
    kept = [(m.state.y.copy(), m.state.products.copy(), m.state.ids.copy(), m.state.t)
            for m in (moment, interval)]
    for _ in range(5):
        engine.tick()
    sim.advance_to(0.5)
    for m, (y, products, ids, t) in zip((moment, interval), kept):
        np.testing.assert_array_equal(m.state.y, y)
        np.testing.assert_array_equal(m.state.products, products)
        np.testing.assert_array_equal(m.state.ids, ids)
        assert m.state.t == t
    assert engine.t > moment.state.t and len(moment.state.ids) > 0


def test_exits_and_packs_become_log_lines_once() -> None:
    from cone_feeder_sim.feeder.runner import start_simulator
    from cone_feeder_sim.formats.scenario_file import scenario_from_mapping
    from cone_feeder_sim.physics.params import ModelParams
    from cone_feeder_sim.view.snapshot import Watcher
    from cone_feeder_sim.weigher.machine import Pack

    class Machine:  # what the watcher reads of a weigher: its packs and hopper readings
        packs: list[Pack] = []

        def hopper_readings(self) -> np.ndarray:
            return np.full(14, 0.25)

    machine = Machine()
    watcher = Watcher(ModelParams(), machine)  # type: ignore[arg-type]
    scenario = scenario_from_mapping({'duration': 1.0, 'rotation': [[0.0, 0.0]], 'particles': [
        {'position': [0.215, 0.0, 0.0], 'velocity': [1.0, 0.0, 0.0], 'on_surface': True}]})
    sim = start_simulator(scenario)
    step = sim.advance_to(0.05)
    assert len(step.exits) == 1
    machine.packs.append(Pack(index=1, t=0.04, mass=1.012, measured=1.0115, heads=(2, 7),
                              giveaway=0.012))
    moment, events = watcher.interval(0.05, sim, step)
    channel = int(step.exits.channel[0])
    assert [e.kind for e in events] == ['exit', 'pack']
    assert events[0].text.startswith(f'piece 0 left into channel {channel} at ')
    assert events[1].text == 'pack 1: 1012.0 g (giveaway +12.0 g), heads 2, 7'
    assert moment.channel_mass[channel - 1] == ModelParams().product.m
    np.testing.assert_array_equal(moment.hoppers, 0.25)
    _, again = watcher.interval(0.1, sim, sim.advance_to(0.1))
    assert again == []  # each exit and pack once
