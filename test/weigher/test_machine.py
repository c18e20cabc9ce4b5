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

"""The weigher below the cone: flow, timing, accounting, statistics and refusals."""

from itertools import combinations
import math

from cone_feeder_sim.errors import ParameterError
from cone_feeder_sim.weigher.machine import (
    Weigher, weigher_params_from_mapping, WeigherParams)
import numpy as np
import pytest


def test_a_piece_rides_its_trough_passes_the_gate_settles_and_is_packed() -> None:
    p = WeigherParams(target=0.1, min_heads=1, max_heads=3, transport_time=2.0,
                      gate_time=0.3, settle_time=0.4, load_cell_noise=0.0,
                      cycles_per_minute=60.0)
    w = Weigher(p, heads=3)
    w.receive([2], [0.12])
    w.advance(1.99)
    assert w.in_troughs()[1] == 0.12 and w.pool[1] == 0.0
    w.advance(2.0)  # arrives at 2.0 s, the gate opens at once (the weigh hopper is empty)
    assert w.gate[1] == 0.12 and not w.available()[1]
    w.advance(2.69)
    assert w.weigh[1] == 0.12 and not w.available()[1]  # settling until 2.7 s
    packs = w.advance(2.99)
    assert w.available()[1] and not packs
    packs = w.advance(3.0)  # the cycle at 3 s packs it
    assert [(pk.t, pk.mass, pk.heads) for pk in packs] == [(3.0, 0.12, (2,))]
    assert packs[0].giveaway == pytest.approx(0.02)


def test_starved_heads_are_counted_at_every_cycle() -> None:
    # the heads without a weighed product, counted here just before each cycle
    p = WeigherParams(target=0.1, min_heads=1, max_heads=2, transport_time=0.5,
                      gate_time=0.15, settle_time=0.15, load_cell_noise=0.0,
                      cycles_per_minute=60.0)
    w = Weigher(p, heads=4)
    arrivals = [(0.13, 1, 0.06), (0.41, 3, 0.05), (1.27, 2, 0.07), (2.61, 1, 0.04),
                (2.65, 4, 0.05), (4.33, 3, 0.11)]
    counted, t, packs = [], 0.0, []
    for cycle in range(1, 7):  # cycles at 1, 2, ... 6 s; no arrival or settling on them
        for when, channel, mass in arrivals:
            if t < when <= cycle:
                packs += w.advance(when)
                w.receive([channel], [mass], [when])
        packs += w.advance(cycle - 1e-6)
        counted.append(4 - int(w.available().sum()))
        packs += w.advance(float(cycle))
        t = float(cycle)
    stats = w.stats()
    assert stats.cycles == 6 and packs
    assert stats.starved_per_cycle == pytest.approx(sum(counted) / 6, abs=1e-15)
    assert 0 < sum(counted) < 24
    # no product at all: every head starves at every cycle
    empty = Weigher(p, heads=4)
    empty.advance(5.0)
    assert empty.stats().starved_per_cycle == 4.0


def test_amplitude_scales_the_trough_and_zero_stops_it() -> None:
    p = WeigherParams(max_heads=2, transport_time=2.0, load_cell_noise=0.0)
    w = Weigher(p, heads=2)
    w.set_amplitude([0.5, 0.0])
    w.receive([1, 2], [0.1, 0.1])
    w.advance(3.9)
    assert w.pool.sum() == 0.0 and w.gate.sum() == 0.0
    w.advance(4.0)  # half speed: 4 s
    assert w.gate[0] == 0.1 and w.in_troughs()[1] == 0.1
    with pytest.raises(ParameterError, match='amplitude'):
        w.set_amplitude([1.0, math.nan])
    with pytest.raises(ParameterError, match='2 values'):
        w.set_amplitude([1.0])


def test_a_piece_rides_from_the_time_it_left_the_cone() -> None:
    p = WeigherParams(max_heads=2, transport_time=1.0, load_cell_noise=0.0)
    w = Weigher(p, heads=2)
    w.receive([1, 1], [0.2, 0.1], times=[0.3, 0.1])  # the later one goes on second
    w.advance(1.099)
    assert w.pool.sum() + w.gate.sum() == 0.0
    w.advance(1.1)
    assert w.gate[0] == 0.1 and w.in_troughs()[0] == 0.2
    with pytest.raises(ParameterError, match='before'):
        w.receive([1], [0.1], times=[0.5])
    with pytest.raises(ParameterError, match='as many'):
        w.receive([1], [0.1, 0.2])
    assert w.mass_in == pytest.approx(0.3)  # refused pieces are not taken


def test_order_is_kept_on_a_trough() -> None:
    p = WeigherParams(max_heads=1, transport_time=1.0, load_cell_noise=0.0)
    w = Weigher(p, heads=1)
    w.receive([1], [0.1])
    w.advance(0.5)
    w.receive([1], [0.2])
    w.advance(1.0)
    assert w.gate[0] == 0.1 and w.in_troughs()[0] == 0.2  # the first one first


def test_every_kilogram_is_somewhere_over_a_long_run() -> None:
    p = WeigherParams(target=0.5, load_cell_noise=0.001, seed=3)
    w = Weigher(p)
    rng = np.random.default_rng(1)
    for k in range(1, 30_001):  # 10 minutes at 50 Hz
        t = 0.02 * k
        arrivals = rng.poisson(0.08)
        w.receive(rng.integers(1, 15, arrivals), rng.uniform(0.05, 0.2, arrivals))
        if rng.random() < 0.001:
            w.set_amplitude(rng.uniform(0.0, 1.5, 14))
        w.advance(t)
    b = w.balance()
    held = b['troughs'] + b['pools'] + b['gates'] + b['weigh'] + b['packed']
    assert held == pytest.approx(b['in'], rel=1e-12)
    assert b['packed'] == pytest.approx(sum(pk.mass for pk in w.packs), rel=1e-12)
    s = w.stats()
    assert s.packs > 100 and s.cycles == 600
    give = np.array([pk.giveaway for pk in w.packs])  # the running statistics, recomputed
    assert s.giveaway_mean == pytest.approx(give.mean(), rel=1e-9)
    assert s.giveaway_std == pytest.approx(give.std(ddof=1), rel=1e-9)
    assert s.under_target == np.mean(give < 0.0)
    assert s.below_tne == np.mean(give < -0.015)
    assert s.packs_per_minute == pytest.approx(s.packs / 10.0)
    assert all(pk.mass >= 0.5 - 0.01 for pk in w.packs)  # noise can cheat the target a little


def test_determinism() -> None:
    def run() -> list:
        w = Weigher(WeigherParams(target=0.3, load_cell_noise=0.002, seed=5))
        rng = np.random.default_rng(2)
        for k in range(1, 3001):
            n = rng.poisson(0.2)
            w.receive(rng.integers(1, 15, n), rng.uniform(0.05, 0.2, n))
            w.advance(0.02 * k)
        return [(pk.t, pk.mass, pk.measured, pk.heads) for pk in w.packs]
    first = run()
    assert first and first == run()


def test_giveaway_matches_enumeration_for_independent_hoppers() -> None:
    # Each cycle every head holds one product of weight 0.1, 0.2 or 0.3 kg (equally likely,
    # independent, no noise): the pack is the smallest subset total >= target. The
    # distribution of the giveaway follows from enumerating the 3^4 fillings of 4 heads.
    values = [0.1, 0.2, 0.3]
    target = 0.45
    heads = 4
    expected: dict[float, float] = {}
    for filling in np.array(np.meshgrid(*[values] * heads)).T.reshape(-1, heads):
        totals = [sum(float(filling[i]) for i in sub) for k in range(1, heads + 1)
                  for sub in combinations(range(heads), k)]
        best = min((x for x in totals if x >= target), default=None)
        key = round(best - target, 9) if best is not None else None
        expected[key] = expected.get(key, 0.0) + 1.0 / 3 ** heads
    p = WeigherParams(max_heads=heads, target=target, load_cell_noise=0.0,
                      transport_time=0.01, gate_time=0.0, settle_time=0.0,
                      cycles_per_minute=60.0)
    rng = np.random.default_rng(0)
    counts: dict[float, int] = {}
    cycles = 20_000
    for _ in range(cycles):  # a fresh machine each time: independent fillings
        w = Weigher(p, heads=heads)
        w.receive(range(1, heads + 1), rng.choice(values, heads))
        packs = w.advance(1.0)  # the first cycle
        key = round(packs[0].giveaway, 9) if packs else None
        counts[key] = counts.get(key, 0) + 1
    for key, prob in expected.items():
        se = math.sqrt(prob * (1 - prob) / cycles)
        assert abs(counts.get(key, 0) / cycles - prob) < 5 * se + 1e-12, (key, prob)
    assert set(counts) <= set(expected)


@pytest.mark.parametrize('key, value, match', [
    ('min_heads', 0, 'weigher.min_heads'), ('min_heads', 2.5, 'weigher.min_heads'),
    ('target', 0.0, 'weigher.target'), ('target', math.nan, 'weigher.target'),
    ('cycles_per_minute', -1.0, 'weigher.cycles_per_minute'),
    ('transport_time', math.inf, 'weigher.transport_time'),
    ('load_cell_noise', -0.1, 'weigher.load_cell_noise'),
    ('max_heads', 0, 'weigher.max_heads'), ('seed', -1, 'weigher.seed'),
    ('colour', 'red', 'colour'),
])
def test_bad_configuration_is_refused_naming_the_key(key: str, value, match: str) -> None:
    with pytest.raises(ParameterError, match=match):
        weigher_params_from_mapping({key: value})


def test_defaults_and_bad_input() -> None:
    p = weigher_params_from_mapping({})
    assert p == WeigherParams() and p.cycle == 1.0
    with pytest.raises(ParameterError, match='heads'):
        Weigher(p, heads=0)
    with pytest.raises(ParameterError, match='min_heads'):
        WeigherParams(min_heads=5, max_heads=3)
    w = Weigher(p)
    with pytest.raises(ParameterError, match='channel 15'):
        w.receive([15], [0.1])
    with pytest.raises(ParameterError, match='mass'):
        w.receive([1], [math.nan])
    w.advance(1.0)
    with pytest.raises(ParameterError, match='back'):
        w.advance(0.5)
