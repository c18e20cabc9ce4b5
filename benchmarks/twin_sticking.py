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
Benchmark: the twin on a cone where every piece sticks (nothing identifies d or mu_C).

The plant is benchmarks/twin_headless.py's (30 pieces at rest, the cone reversing between
-3 and 3 rad/s every 2 s, 2 mm of noise), run alongside the twin (M members, the
estimator's defaults). Every 5 s of stream it prints the twin's d and mu_C (mean and spread
over the members; the plant's: 225 and 0.85, the prior's centre), how far the members' mean
state of each piece is from the plant's (the pieces matched by nearest position): in x, y,
in height and in the friction filter's force P, and the wall time of those 5 s::

    .venv/bin/python benchmarks/twin_sticking.py [--seconds 40] [--members 8]
"""

import argparse
import time

from calibration import calibration_line
from cone_feeder_sim.physics.params import ModelParams
from cone_feeder_sim.physics.simulation import advance, SimParams, warm_up, world_from_cone
from cone_feeder_sim.twin.estimator import Twin, TwinSettings
import numpy as np
from scipy.spatial import cKDTree
from twin_headless import plant_start, reversing_profile


def main() -> None:
    """Print the calibration, then the twin against the plant every 5 s."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seconds', type=float, default=40.0)
    parser.add_argument('--members', type=int, default=8)
    args = parser.parse_args()
    print(calibration_line(), flush=True)
    warm_up()
    params = SimParams(model=ModelParams())
    profile = reversing_profile(args.seconds)
    plant, rng = plant_start(params)
    twin = Twin(params, TwinSettings(members=args.members, sigma=0.002))
    wall = 0.0
    for k in range(1, int(round(30 * args.seconds)) + 1):
        t = k / 30.0
        plant = advance(plant, params, profile, t).state
        seen, _, _ = world_from_cone(plant.y, plant.angle, profile.omega(t))
        twin.cone_speed(t, profile.omega(t))
        start = time.perf_counter()
        twin.update(t, seen[:, :2] + rng.normal(0.0, 0.002, (plant.count, 2)))
        wall += time.perf_counter() - start
        if k % 150:
            continue
        held = twin._common()  # every member's pieces, and each member's rows of them
        mean = np.mean([s.y[twin._rows(s, held)] for s in twin.states], axis=0)
        _, nearest = cKDTree(mean[:, :2]).query(plant.y[:, :2])
        error = mean[nearest] - plant.y
        found = twin.parameters()
        print(f't {t:4.0f} s: d {found["d"][0]:5.0f} +- {found["d"][1]:3.0f}, mu_C '
              f'{found["mu_C"][0]:.2f} +- {found["mu_C"][1]:.2f}; largest error of a piece: '
              f'x, y {1e3 * np.hypot(error[:, 0], error[:, 1]).max():5.1f} mm, height '
              f'{1e3 * np.abs(error[:, 2]).max():6.1f} mm, P '
              f'{np.linalg.norm(error[:, 6:9], axis=1).max():6.2f} N; '
              f'{len(held)} pieces; {wall:.1f} s wall for these 5 s', flush=True)
        wall = 0.0
    print(calibration_line(), flush=True)


if __name__ == '__main__':
    main()
