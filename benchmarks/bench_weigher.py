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
Benchmark: the weigher's cost, beside the cone's tick it rides on.

1. ``select_combination`` per call for 10, 14 and 16 heads (every subset) and for 24 and
   32 heads with a head limit, on random hopper weights (median of many calls).
2. The machine (troughs, hoppers, a cycle per second) advanced by 20-ms ticks with the
   feed's pieces arriving, against the engine's own 50-Hz tick with N pieces turning on
   the cone (interactions off), side by side: the weigher's share of the tick.

The calibration workload is printed first::

    .venv/bin/python benchmarks/bench_weigher.py
"""

import statistics
import time

from bench_states import places
from calibration import calibration_line
from cone_feeder_sim.feeder.engine import DriveParams, EngineConfig, FeederEngine, FeedParams
from cone_feeder_sim.weigher import select_combination, subset_count
from cone_feeder_sim.weigher.machine import Weigher, WeigherParams
import numpy as np


def time_selection(heads: int, max_heads: int, calls: int = 200) -> float:
    """Return the median time (s) of one select_combination call."""
    rng = np.random.default_rng(heads)
    times = []
    for _ in range(calls):
        weights = rng.uniform(0.1, 0.4, heads)
        start = time.perf_counter()
        select_combination(weights, 1.0, max_heads=max_heads, ages=rng.uniform(0, 5, heads))
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def time_ticks(count: int, ticks: int = 500) -> tuple[float, float]:
    """Return the mean engine tick and the mean weigher advance (s) per 20-ms tick."""
    engine = FeederEngine(EngineConfig(drive=DriveParams(cmd_timeout=0.0),
                                       feed=FeedParams(max_pieces=count)))
    engine.spawn(places(count, 0.0))  # at rest on the cone, then carried at 2 rad/s
    engine.command(2.0)
    weigher = Weigher(WeigherParams(target=0.5))
    rng = np.random.default_rng(0)
    for _ in range(50):
        engine.tick()
    engine_s = weigher_s = 0.0
    for _ in range(ticks):
        start = time.perf_counter()
        engine.tick()
        engine_s += time.perf_counter() - start
        arrivals = rng.poisson(0.08)  # 4 pieces/s leave the cone
        start = time.perf_counter()
        t0 = weigher.t
        weigher.receive(rng.integers(1, 15, arrivals), np.full(arrivals, 0.125),
                        t0 + rng.uniform(0.0, 0.02, arrivals))
        weigher.advance(t0 + 0.02)
        weigher_s += time.perf_counter() - start
    return engine_s / ticks, weigher_s / ticks


def main() -> None:
    """Print the calibration, the selection times and the tick shares."""
    print(calibration_line())
    select_combination([0.2] * 4, 0.3)  # load the compiled kernel
    print('# select_combination, median of 200 calls on random weights (target 1 kg)')
    print(f'{"heads":>6} {"max heads":>10} {"subsets":>9} {"ms":>8}')
    for heads, max_heads in ((10, 10), (14, 14), (16, 16), (24, 6), (32, 5)):
        ms = 1e3 * time_selection(heads, max_heads)
        print(f'{heads:>6} {max_heads:>10} {subset_count(heads, 1, max_heads):>9} {ms:>8.3f}',
              flush=True)
    print('# per 50-Hz tick: engine (N pieces turning at 2 rad/s) and weigher (14 heads, '
          '4 pieces/s, 60 cycles/min)')
    print(f'{"N":>6} {"engine ms":>10} {"weigher ms":>11} {"share":>7}')
    for count in (20, 150, 2000):
        engine_s, weigher_s = time_ticks(count)
        print(f'{count:>6} {1e3 * engine_s:>10.3f} {1e3 * weigher_s:>11.3f} '
              f'{100 * weigher_s / engine_s:>6.1f}%', flush=True)


if __name__ == '__main__':
    main()
