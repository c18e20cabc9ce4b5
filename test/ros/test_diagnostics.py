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

"""Tests of ros.diagnostics: the statuses sim_node publishes, from plain values."""

from cone_feeder_sim.feeder.engine import EngineConfig, FeederEngine, FeedParams, PieceSpec
from cone_feeder_sim.ros.diagnostics import (
    DiagnosticsWindow, recording_status, RunTotals, simulation_status, weigher_status)
from cone_feeder_sim.ros.pacing import Pacer
from cone_feeder_sim.weigher.machine import WeigherStats


def values(status: dict) -> dict[str, str]:
    return {item['key']: item['value'] for item in status['values']}


def test_simulation_status_says_when_the_node_cannot_keep_up() -> None:
    engine = FeederEngine(EngineConfig(dt=0.02))
    window = DiagnosticsWindow(wall=10.0, sim=0.0)
    for _ in range(25):
        result = engine.tick()
    window.ticks, window.step_s, window.step_max = 25, 1.0, 0.06
    pacer = Pacer(0.02, 1.0, 0.5)
    slow = simulation_status('/sim_node', window, 12.0, engine, pacer, False, result, 3, 0, 1)
    assert slow['level'] == 1 and slow['name'] == '/sim_node: simulation'
    assert slow['message'].startswith('cannot keep up: real-time factor 0.25 < 1')
    table = values(slow)
    assert table['ticks in window'] == '25' and table['step time mean (ms)'] == '40.000'
    assert table['exits (total)'] == '3' and table['refused inputs (total)'] == '1'
    on_time = simulation_status('/n', window, 10.5, engine, pacer, False, result, 0, 0, 0)
    assert on_time['level'] == 0 and on_time['message'] == 'real-time factor 1.00 (target 1)'
    paused = simulation_status('/n', window, 12.0, engine, pacer, True, None, 0, 0, 0)
    assert paused['message'] == 'paused at t = 0.500 s'
    assert values(paused)['drive mode'] == 'not started'
    window.coupling_forced, window.contacts = 7, 60
    forced = simulation_status('/n', window, 10.5, engine, pacer, False, result, 0, 0, 0)
    assert forced['level'] == 1 and '7 coupling intervals accepted above' in forced['message']
    assert values(forced)['touching pairs (max)'] == '60'


def test_recording_and_weigher_statuses() -> None:
    assert recording_status('/n', None, None)['message'] == 'not recording'
    stopped = recording_status('/n', None, 'disk full')
    assert stopped['level'] == 2 and stopped['message'] == 'recording stopped: disk full'
    stats = WeigherStats(packs=12, packs_per_minute=30.0, giveaway_mean=0.0123,
                         giveaway_std=0.002, under_target=0.0, below_tne=0.0,
                         starved_per_cycle=1.5, cycles=40)
    good = weigher_status('/n', stats)
    assert good['level'] == 0 and good['message'] == '12 packs, 30.0/min, giveaway 12.3 g'
    assert values(good)['giveaway mean (g)'] == '12.30'
    short = weigher_status('/n', WeigherStats(**{**stats.__dict__, 'below_tne': 0.1}))
    assert short['level'] == 1


def test_window_and_totals_count_published_ticks() -> None:
    engine = FeederEngine(EngineConfig(dt=0.02, feed=FeedParams(rate=0.0),
                                       initial_pieces=(PieceSpec((0.215, 0.0, 0.03),
                                                                 (1.0, 0.0, 0.0)),)))
    window, totals = DiagnosticsWindow(wall=0.0, sim=0.0), RunTotals()
    results = [engine.tick() for _ in range(3)]
    for result, step_s in zip(results, (0.01, 0.03, 0.015)):
        window.count(result, step_s, 0.002, 0.02)
        totals.count(result, step_s, 0.002)
    assert (window.ticks, window.overruns, window.step_max) == (3, 1, 0.03)
    assert window.step_s == totals.step_s == 0.01 + 0.03 + 0.015
    assert window.accepted == sum(r.stats.accepted for r in results) > 0
    assert (totals.ticks, totals.exits, totals.failures) == (3, 1, 0)  # the piece left
    assert totals.last_tick is results[-1] and totals.publish_s == 3 * 0.002
