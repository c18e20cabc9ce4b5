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
Study: the twin following a change of product (mu_C steps from 0.85 to 0.7 at 5 s).

The plant is the physics core with a feed: a piece every 0.25 s, at rest on the annulus
0.05-0.12 m, on a cone reversing between -8 and 8 rad/s every 2 s (the outer pieces slide
and leave: about ten on the cone). Pieces fed from 5 s on are a new product (mu_C 0.7
instead of 0.85; d 225 throughout); those already on the cone keep theirs (with --all
every piece's mu_C changes, as when the cone's surface does). The twin (32
members, 0.5-s windows) starts from the file's prior (mu_C 0.85 +- 0.15). Prints its mu_C
every 0.5 s, and the time after the change at which its estimate came within two spreads of
0.7 and stayed there::

    .venv/bin/python benchmarks/twin_product_change.py [--seconds 12] [--members 32] [--all]
        [--drift 0.01]
"""

import argparse
from dataclasses import replace
import time

from calibration import calibration_line
from cone_feeder_sim.physics.params import ModelParams, product_row
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    add_particles, advance, resting_height, SimParams, SimState, warm_up, world_from_cone)
from cone_feeder_sim.twin.estimator import Twin, TwinSettings
import numpy as np

CHANGE = 5.0  # s


def main() -> None:
    """Print the calibration, the trace and the time to follow the change."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seconds', type=float, default=12.0)
    parser.add_argument('--members', type=int, default=32)
    parser.add_argument('--all', action='store_true',
                        help='every piece changes its mu_C at 5 s (as with a new cone '
                        'surface), not only the pieces fed from then on')
    parser.add_argument('--drift', type=float, default=TwinSettings.drift,
                        help="the parameters' random walk per second (TwinSettings.drift)")
    args = parser.parse_args()
    print(calibration_line(), flush=True)
    warm_up()
    model = ModelParams()
    params = SimParams(model=model)
    old, new = model.product, replace(model.product, mu_C=0.7)
    table = [[0.0, 0.0], [0.5, 8.0]]
    for k in range(int(args.seconds / 2.0) + 1):
        sign = -1.0 if k % 2 == 0 else 1.0
        table += [[2.0 * k + 1.5, -sign * 8.0], [2.0 * k + 2.0, sign * 8.0]]
    profile = RotationProfile.from_table(table)
    plant = SimState()
    feed = np.random.default_rng(3)
    twin = Twin(params, TwinSettings(members=args.members, sigma=0.001, mu_C_spread=0.15,
                                     seed=1, drift=args.drift))
    rng = np.random.default_rng(0)
    trace = []
    start = time.perf_counter()
    for k in range(1, int(round(30 * args.seconds)) + 1):
        t = k / 30.0
        plant = advance(plant, params, profile, t).state
        if k == round(30 * CHANGE) and args.all:  # the cone's surface changes: every piece's mu_C
            plant = replace(plant, products=np.array([product_row(new)] * plant.count))
        if k % 8 == 0:  # a piece every 0.27 s
            product = new if t >= CHANGE else old
            r, a = feed.uniform(0.05, 0.12), feed.uniform(0.0, 2.0 * np.pi)
            x, y = r * np.cos(a), r * np.sin(a)
            plant, _ = add_particles(plant, params, np.array(
                [[x, y, resting_height(model, product, x, y)]]), products=[product],
                omega=profile.omega(t))
        twin.cone_speed(t, profile.omega(t))
        seen, _, _ = world_from_cone(plant.y, plant.angle, profile.omega(t))
        twin.update(t, seen[:, :2] + rng.normal(0.0, 0.001, (plant.count, 2)))
        if k % 15 == 0:
            mu, spread = twin.parameters()['mu_C']
            trace.append((t, mu, spread, plant.count))
    wall = time.perf_counter() - start
    print('t (s), mu_C, spread, pieces on the cone:', flush=True)
    for t, mu, spread, count in trace:
        print(f'  {t:5.2f} {mu:.4f} {spread:.4f} {count}', flush=True)
    within = [abs(mu - 0.7) < 2.0 * spread for t, mu, spread, _ in trace]
    settled = None
    for i, (t, _, _, _) in enumerate(trace):
        if t > CHANGE and all(within[i:]):
            settled = t
            break
    print(f'followed the change {settled - CHANGE:.1f} s after it' if settled is not None
          else 'did not follow the change (not within two spreads of 0.7 to the end)',
          f'({wall:.1f} s wall for {args.seconds:g} s)', flush=True)
    print(calibration_line(), flush=True)


if __name__ == '__main__':
    main()
