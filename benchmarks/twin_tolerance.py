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
Study: the solver's tolerances the twin's members need (``TwinSettings.loosen``).

30 pieces at rest on the annulus 0.05-0.17 m, a cone to 3 rad/s, reversing to 7 and 8 rad/s
(21 pieces leave in 5 s), run with the scenario's tolerances times 1, 10, 30, 100 and 1000.
Prints the wall time of the 5 s, the exits and their channels, and the largest position
difference from the run at the default tolerances::

    .venv/bin/python benchmarks/twin_tolerance.py
"""

import time

from calibration import calibration_line
from cone_feeder_sim.physics.params import ModelParams, SolverParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    add_particles, advance, resting_height, SimParams, SimState, warm_up, world_from_cone)
from cone_feeder_sim.twin.estimator import loosened
import numpy as np


def main() -> None:
    """Print the calibration and one line per tolerance."""
    print(calibration_line(), flush=True)
    warm_up()
    model = ModelParams()
    rng = np.random.default_rng(0)
    r = np.sqrt(rng.uniform(0.05 ** 2, 0.17 ** 2, 30))
    a = rng.uniform(0.0, 2.0 * np.pi, 30)
    q = np.array([[x, y, resting_height(model, model.product, x, y)]
                  for x, y in zip(r * np.cos(a), r * np.sin(a))])
    profile = RotationProfile.from_table([[0, 0], [0.5, 3.0], [1.5, 7.0], [2.0, -7.0],
                                          [3.5, -7.0], [4.0, 8.0]])
    reference = None
    for factor in (1.0, 10.0, 30.0, 100.0, 1000.0):
        params = loosened(SimParams(model=model, solver=SolverParams()), factor)
        plant, _ = add_particles(SimState(), params, q)
        advance(plant, params, profile, 0.01)  # compiled and warm
        start = time.perf_counter()
        result = advance(plant, params, profile, 5.0)
        wall = time.perf_counter() - start
        state = result.state
        position, _, _ = world_from_cone(state.y, state.angle, profile.omega(5.0))
        if reference is None:
            reference = (state.ids, position)
        mine = np.isin(state.ids, reference[0])
        theirs = np.isin(reference[0], state.ids)
        worst = float(np.abs(position[mine] - reference[1][theirs]).max()) if mine.any() else 0.0
        print(f'tolerances x{factor:g}: {wall:.3f} s for 5 s, {len(result.exits)} exits into '
              f'{sorted(result.exits.channel.tolist())}, {state.count} left, largest position '
              f'difference {1e3 * worst:.3f} mm', flush=True)
    print(calibration_line(), flush=True)


if __name__ == '__main__':
    main()
