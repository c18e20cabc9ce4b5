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
Study: the twin's estimator following a plant, with its prior right and wrong.

The plant is the physics core: five pieces on a cone that speeds up to 6 rad/s and reverses
(one leaves at 0.77 s), seen at 30 frames/s with 1 mm of noise for 3 s. The twin (32
members) gets the detections and the cone speed. Two cases: the plant's product is the
default (d = 225, mu_C = 0.85) and the twin's prior is right (spreads 5 % and 0.01); the
plant's product is d = 450, mu_C = 0.7 and the twin's prior is the default with spreads 50 %
and 0.05. Prints per case the NIS against its chi-square bounds (alpha = 1e-3), the worst
position error, the births after the first frame, the parameters' estimates with their
spreads, and the wall time against the 3 s simulated::

    .venv/bin/python benchmarks/twin_follow.py
"""

from dataclasses import replace
import time

from calibration import calibration_line
from cone_feeder_sim.physics.params import ModelParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    add_particles, advance, resting_height, SimParams, SimState, warm_up, world_from_cone)
from cone_feeder_sim.twin.estimator import Twin, TwinSettings
import numpy as np
from scipy.stats import chi2

PROFILE = RotationProfile.from_table([[0.0, 0.0], [0.5, 6.0], [1.5, 6.0], [2.0, -6.0]])
PLACES = [[0.10, 0.02], [-0.08, 0.09], [0.03, -0.13], [-0.12, -0.05], [0.20, 0.03]]


def case(label: str, truth: dict, settings: TwinSettings) -> None:
    """Follow the plant of truth (product keys) with settings; print the figures."""
    model = ModelParams()
    params = SimParams(model=model)
    product = replace(model.product, **truth)
    q = np.array([[x, y, resting_height(model, product, x, y)] for x, y in PLACES])
    plant, _ = add_particles(SimState(), params, q, products=[product] * len(q))
    twin = Twin(params, settings)
    rng = np.random.default_rng(0)
    nis = dof = births = 0
    worst = 0.0
    start = time.perf_counter()
    for k in range(1, 91):
        t = k / 30.0
        plant = advance(plant, params, PROFILE, t).state
        twin.cone_speed(t, PROFILE.omega(t))
        seen, _, _ = world_from_cone(plant.y, plant.angle, PROFILE.omega(t))
        frame = twin.update(t, seen[:, :2] + rng.normal(0.0, settings.sigma, (plant.count, 2)))
        if k > 1:
            nis, dof, births = nis + frame.nis, dof + frame.observed, births + frame.births
            _, mean, _ = twin.pieces()
            error = np.linalg.norm(mean[:, None, :] - seen[None, :, :2], axis=2).min(axis=1)
            worst = max(worst, float(error.max()))
    wall = time.perf_counter() - start
    estimates = ', '.join(f'{key} {value:.4g} +- {spread:.2g} (truth {truth[key]:g})'
                          for key, (value, spread) in twin.parameters().items())
    print(f'{label}: NIS {nis:.0f} for {dof} observations (bounds {chi2.ppf(5e-4, dof):.0f}'
          f'-{chi2.ppf(1 - 5e-4, dof):.0f}); worst error {1e3 * worst:.2f} mm; births after '
          f'the first frame {births}; {estimates}; {wall:.2f} s wall for 3 s', flush=True)


def main() -> None:
    """Print the calibration and both cases."""
    print(calibration_line())
    warm_up()
    case('prior right', {'d': 225.0, 'mu_C': 0.85},
         TwinSettings(members=32, sigma=0.001, d_spread=0.05, mu_C_spread=0.01,
                      seed=1))
    case('prior wrong', {'d': 450.0, 'mu_C': 0.7}, TwinSettings(members=32, sigma=0.001, seed=1))
    print(calibration_line())


if __name__ == '__main__':
    main()
