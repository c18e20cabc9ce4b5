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

"""Tests of feeder.feed and of the feed in headless scenarios (the runner)."""

import math

from cone_feeder_sim.errors import ParameterError
from cone_feeder_sim.feeder.engine import EngineConfig, FeederEngine
from cone_feeder_sim.feeder.feed import draw_feed, feed_from_mapping, FEED_KEYS, FeedParams
from cone_feeder_sim.feeder.runner import run_scenario
from cone_feeder_sim.formats.scenario_file import scenario_from_mapping
from cone_feeder_sim.physics.params import ModelParams
import numpy as np
import pytest

MODEL = ModelParams()


def test_keys_are_the_nodes_feed_parameters() -> None:
    from cone_feeder_sim.ros.parameters import parameter_specs  # the node's table
    node_keys = {spec.name[len('feed.'):] for spec in parameter_specs(MODEL)
                 if spec.name.startswith('feed.')}
    assert node_keys == set(FEED_KEYS)


def test_from_mapping_names_the_key() -> None:
    feed, seed = feed_from_mapping({'rate': 4, 'rho_min': 0.05, 'seed': 3})
    assert (feed.rate, feed.rho_min, seed) == (4.0, 0.05, 3)
    with pytest.raises(ParameterError, match=r'rl\.feed\.rho_min = 0\.2 m must not exceed'):
        feed_from_mapping({'rho_min': 0.2, 'rho_max': 0.1}, 'rl.feed')
    with pytest.raises(ParameterError, match=r"unknown feed key\(s\) 'mass'"):
        feed_from_mapping({'mass': 1.0})


def test_draws_follow_the_parameters_and_the_room() -> None:
    feed = FeedParams(rate=2000.0, rho_min=0.05, rho_max=0.12, drop_height=0.04,
                      mass_rel_std=0.3, d_values=(30.0, 750.0))
    drop = draw_feed(np.random.default_rng(1), feed, MODEL, 1.0, 10 ** 6)
    count = len(drop.products)
    assert abs(count - 2000) < 5 * math.sqrt(2000)  # Poisson(2000)
    rho = np.hypot(drop.positions[:, 0], drop.positions[:, 1])
    assert rho.min() >= 0.05 and rho.max() <= 0.12
    surface = MODEL.h * (1.0 - rho / MODEL.r)
    np.testing.assert_allclose(drop.positions[:, 2] - surface, 0.04, atol=1e-15)
    # uniform per area: half the pieces inside the radius that halves the area
    median = math.sqrt((0.05 ** 2 + 0.12 ** 2) / 2)
    assert abs(np.mean(rho < median) - 0.5) < 0.05
    assert abs(drop.masses.mean() / MODEL.product.m - 1.0) < 0.03
    assert abs(drop.masses.std() / MODEL.product.m - 0.3) < 0.03
    assert {p.d for p in drop.products} == {30.0, 750.0}
    np.testing.assert_array_equal([p.m for p in drop.products], drop.masses)
    assert len(draw_feed(np.random.default_rng(1), feed, MODEL, 1.0, 7).products) == 7
    assert draw_feed(np.random.default_rng(1), feed, MODEL, 1.0, 0) is None
    assert draw_feed(np.random.default_rng(1), FeedParams(rate=0.0), MODEL, 1.0, 10) is None


def test_engine_feed_is_draw_feed_per_tick() -> None:
    feed = FeedParams(rate=300.0, mass_rel_std=0.2, d_values=(30.0, 225.0))
    engine = FeederEngine(EngineConfig(feed=feed, seed=11, dt=0.02))
    rng = np.random.default_rng(11)
    for _ in range(3):
        result = engine.tick()
        drop = draw_feed(rng, feed, MODEL, 0.02, 10 ** 6)
        fed = np.isin(result.ids, result.feed_ids)
        assert fed.sum() == len(drop.products)
        np.testing.assert_array_equal(result.masses[fed], drop.masses)


SCENARIO = {'duration': 0.3, 'rotation': [[0.0, 0.0], [0.2, 5.0]], 'output_interval': 0.05,
            'feed': {'rate': 40.0, 'mass_rel_std': 0.2, 'seed': 2}}


def test_runner_drops_the_feed_per_interval_reproducibly() -> None:
    scenario = scenario_from_mapping(SCENARIO)
    counts: list[int] = []
    first = run_scenario(scenario, lambda t, sim, step: counts.append(sim.state.count))
    rng = np.random.default_rng(2)
    expected = [len(d.products) if (d := draw_feed(rng, scenario.feed, scenario.model, 0.05,
                                                   10 ** 6)) else 0 for _ in range(6)]
    assert first.pieces == sum(expected) > 0
    assert first.end_time == pytest.approx(0.3)  # the run goes on while the feed is on
    assert counts[-1] == first.remaining_ids.size == sum(expected) - first.exit_table()[
        'ids'].size
    again = run_scenario(scenario)
    np.testing.assert_array_equal(first.remaining_ids, again.remaining_ids)
    other = run_scenario(scenario_from_mapping({**SCENARIO, 'feed': {**SCENARIO['feed'],
                                                                     'seed': 3}}))
    assert other.pieces != first.pieces or not np.array_equal(
        other.remaining_ids, first.remaining_ids)
