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
Study: the twin's on-line identification of d and mu_C, truths away from the prior.

The plant is the physics core: seven pieces on a cone reversing between -v and v every 2 s
(at 6 rad/s they stick to it: d changes no position, mu_C none by more than 0.2 mm in 6 s;
at 8 rad/s the outer ones slide and leave, and d and mu_C move them by centimetres), seen
at 30 frames/s with 1 mm of noise for 6 s. The twin (32 members, 32 values of d and mu_C)
starts from the file's prior (d 225 +- 50 % on the log scale, mu_C 0.85 +- 0.15) and gets
the detections and the cone speed. For each truth it prints the estimates with their
spreads and the errors in spreads (z), for the window smoother (``window`` 0.5 s, the
default) and the frame-by-frame analysis (``window`` 0)::

    .venv/bin/python benchmarks/twin_identify.py [--seconds 6] [--members 32] [--speed 6 8]
        [--window 0.5 0] [--particles 32] [--smoother-pieces 6] [--seed 1] [--loosen 10]
"""

import argparse
from dataclasses import replace
import time

from calibration import calibration_line
from cone_feeder_sim.physics.params import ModelParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    add_particles, advance, resting_height, SimParams, SimState, warm_up, world_from_cone)
from cone_feeder_sim.twin.estimator import Twin, TwinSettings
import numpy as np

PLACES = [[0.10, 0.02], [-0.08, 0.09], [0.03, -0.13], [-0.12, -0.05], [0.06, 0.11],
          [-0.02, -0.07], [0.07, -0.02]]


def reversing(speed: float) -> RotationProfile:
    """Return the cone reversing between -speed and speed (rad/s) every 2 s."""
    return RotationProfile.from_table([[0.0, 0.0], [0.5, speed], [1.5, speed], [2.0, -speed],
                                       [3.5, -speed], [4.0, speed], [5.5, speed],
                                       [6.0, -speed]])


TRUTHS = [{'d': 450.0, 'mu_C': 0.85}, {'d': 225.0, 'mu_C': 0.7}, {'d': 450.0, 'mu_C': 0.7},
          {'d': 100.0, 'mu_C': 1.0}]


def case(truth: dict, window: float, seconds: float, settings: TwinSettings,
         speed: float) -> None:
    """Follow the plant of truth with the twin; print the estimates against the truth."""
    profile = reversing(speed)
    model = ModelParams()
    params = SimParams(model=model)
    product = replace(model.product, **truth)
    q = np.array([[x, y, resting_height(model, product, x, y)] for x, y in PLACES])
    plant, _ = add_particles(SimState(), params, q, products=[product] * len(q))
    twin = Twin(params, replace(settings, window=window))
    rng = np.random.default_rng(0)
    start = time.perf_counter()
    for k in range(1, int(round(30 * seconds)) + 1):
        t = k / 30.0
        plant = advance(plant, params, profile, t).state
        twin.cone_speed(t, profile.omega(t))
        seen, _, _ = world_from_cone(plant.y, plant.angle, profile.omega(t))
        twin.update(t, seen[:, :2] + rng.normal(0.0, 0.001, (plant.count, 2)))
    wall = time.perf_counter() - start
    parts = []
    for key, (value, spread) in twin.parameters().items():
        parts.append(f'{key} {value:.4g} +- {spread:.2g} (truth {truth[key]:g}, z '
                     f'{(value - truth[key]) / spread:+.1f})')
    print(f'{speed:g} rad/s, window {window:g} s, truth d {truth["d"]:g}, mu_C {truth["mu_C"]:g}: '
          f'{"; ".join(parts)}; {plant.count} pieces left; {wall:.1f} s wall', flush=True)


def main() -> None:
    """Print the calibration and the cases."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seconds', type=float, default=6.0)
    parser.add_argument('--members', type=int, default=32)
    parser.add_argument('--speed', type=float, nargs='+', default=[6.0, 8.0])
    parser.add_argument('--window', type=float, nargs='+', default=[0.5, 0.0])
    parser.add_argument('--seed', type=int, default=1, help="the twin's seed")
    parser.add_argument('--particles', type=int, default=TwinSettings.particles)
    parser.add_argument('--smoother-pieces', type=int, default=TwinSettings.smoother_pieces)
    parser.add_argument('--loosen', type=float, default=TwinSettings.loosen,
                        help="the members' solver tolerances times this")
    args = parser.parse_args()
    settings = TwinSettings(members=args.members, sigma=0.001, mu_C_spread=0.15, seed=args.seed,
                            particles=args.particles, smoother_pieces=args.smoother_pieces,
                            loosen=args.loosen)
    print(calibration_line(), flush=True)
    warm_up()
    for speed in args.speed:
        for truth in TRUTHS:
            for window in args.window:
                case(truth, window, args.seconds, settings, speed)
    print(calibration_line(), flush=True)


if __name__ == '__main__':
    main()
