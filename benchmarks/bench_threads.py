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
Benchmark: the integration on 1 thread and on every core, side by side in one run.

N pieces resting on the cone at random positions (seeded) are advanced in 20 ms intervals
over a reversing rotation (at rest, -8 rad/s, +8 rad/s) with 1 thread, then with every
core numba found; printed are the wall and CPU seconds, the speed-up, and whether the final
states are bit-for-bit identical. The calibration workload comes first.

    .venv/bin/python benchmarks/bench_threads.py --pieces 150 1000 2000 --intervals 100
"""

import argparse
import time

from calibration import calibration_line
from cone_feeder_sim.physics.integrator import set_threads
from cone_feeder_sim.physics.params import ModelParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    add_particles, advance, resting_height, SimParams, SimState, warm_up)
import numba
import numpy as np


def start_state(params: SimParams, count: int) -> SimState:
    """Return ``count`` pieces resting on the cone at seeded random positions."""
    model = params.model
    rng = np.random.default_rng(0)
    rho = np.sqrt(rng.uniform(0.03 ** 2, 0.2 ** 2, count))
    theta = rng.uniform(0.0, 2.0 * np.pi, count)
    x, y = rho * np.cos(theta), rho * np.sin(theta)
    z = [resting_height(model, model.product, a, b) for a, b in zip(x, y)]
    state, _ = add_particles(SimState(), params, np.column_stack([x, y, z]), None, None,
                             omega=0.0)
    return state


def run(state: SimState, params: SimParams, profile: RotationProfile,
        intervals: int) -> tuple[float, float, SimState]:
    """Advance ``intervals`` times 20 ms; return wall s, CPU s and the final state."""
    wall, cpu = time.perf_counter(), time.process_time()
    for k in range(1, intervals + 1):
        state = advance(state, params, profile, 0.02 * k).state
    return time.perf_counter() - wall, time.process_time() - cpu, state


def main() -> None:
    """Print the calibration and a row per piece count."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--pieces', type=int, nargs='+', default=[150, 1000, 2000])
    parser.add_argument('--intervals', type=int, default=100)
    args = parser.parse_args()
    print(calibration_line())
    params = SimParams(model=ModelParams())
    warm_up()
    profile = RotationProfile.from_table([[0.0, 0.0], [0.4, -8.0], [1.0, -8.0], [1.4, 8.0]])
    cores = numba.config.NUMBA_NUM_THREADS
    print(f'# {args.intervals} intervals of 20 ms, reversing, 1 thread vs {cores}')
    print(f'{"pieces":>7} {"1 thread s":>11} {f"{cores} threads s":>12} {"CPU s":>7} '
          f'{"speed-up":>9} {"identical":>9}')
    for count in args.pieces:
        state = start_state(params, count)
        set_threads(1)
        one, _, final_one = run(state, params, profile, args.intervals)
        set_threads(0)
        many, cpu, final_many = run(state, params, profile, args.intervals)
        same = np.array_equal(final_one.y, final_many.y)
        print(f'{count:>7} {one:>11.3f} {many:>12.3f} {cpu:>7.3f} {one / many:>9.2f} '
              f'{str(same):>9}', flush=True)


if __name__ == '__main__':
    main()
