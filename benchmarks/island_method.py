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
Which method for the island coupling's common steps: ROS34PW2 or RODAS4, side by side.

The island coupling solves each step with every piece's own Jacobian block only, which
leaves the pair forces out of the linear solves. A W-method (ROS34PW2) keeps its order
whatever the Jacobian; RODAS4 (the pieces' own method) does not. A crowd of 12 touching
pieces (nine resting near the rim, three dropped on them) on a cone reversing in 0.5 s is
run for 0.3 s with each method at the default tolerances and 10x tighter, and compared
with the exact coupling at 1e-2 of the defaults' tolerances (the reference; 1e-4 did not
finish in 30 minutes).
Printed: the largest position error, the integration steps per particle-second and the
CPU time::

    .venv/bin/python benchmarks/island_method.py
"""

from dataclasses import replace
import time

from calibration import calibration_line
from cone_feeder_sim.physics import simulation
from cone_feeder_sim.physics.island import RODAS4_BLOCK, ROS34PW2
from cone_feeder_sim.physics.params import InteractionParams, ModelParams, SolverParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import resting_height, SimParams, Simulator
import numpy as np

REVERSING = [[0.0, 0.0], [0.2, 6.0], [0.3, 6.0], [0.5, -6.0], [2.0, -6.0]]
XY = [[0.10 + 0.046 * i, 0.046 * j] for i in range(3) for j in (-1, 0, 1)]


def crowd(model: ModelParams) -> np.ndarray:
    """Return 12 positions (m): nine resting pieces and three 4 cm above them."""
    rest = np.array([[a, b, resting_height(model, model.product, a, b)] for a, b in XY])
    return np.vstack([rest, rest[:3] + [0.0, 0.023, 0.04]])


def run(coupling: str, scale: float) -> tuple[np.ndarray, int, float]:
    """Return the positions after 0.3 s (12, 3), the steps and the CPU seconds."""
    model = ModelParams(interactions=InteractionParams(enabled=True, coupling=coupling))
    base = SolverParams()
    solver = replace(base, rtol=base.rtol * scale, atol_position=base.atol_position * scale,
                     atol_velocity=base.atol_velocity * scale,
                     atol_force=base.atol_force * scale)
    sim = Simulator(SimParams(model=model, solver=solver), RotationProfile.from_table(REVERSING))
    sim.add(crowd(model))
    steps = 0
    cpu = time.process_time()
    for k in range(1, 16):
        result = sim.advance_to(0.02 * k)
        steps += result.stats.accepted + result.stats.rejected
    q = np.full((12, 3), np.nan)
    q[sim.state.ids] = sim.world()[0]
    return q, steps, time.process_time() - cpu


def main() -> None:
    """Print each method's error and cost at three tolerances."""
    print(calibration_line())
    run('island', 1.0)  # load the kernels
    reference, _, _ = run('exact', 1e-2)
    print(f'{"method":>24} {"tolerances":>10} {"max error (m)":>14} {"steps/p-s":>10} '
          f'{"CPU s":>7}')
    for method in (ROS34PW2, RODAS4_BLOCK):
        simulation.ISLAND_METHOD = method
        for scale in (1.0, 0.1):
            q, steps, cpu = run('island', scale)
            print(f'{method.name:>24} {scale:>10g} {np.nanmax(np.abs(q - reference)):>14.3e} '
                  f'{steps / (12 * 0.3):>10.0f} {cpu:>7.2f}', flush=True)
    simulation.ISLAND_METHOD = ROS34PW2
    q, steps, cpu = run('exact', 1.0)
    print(f'{"exact coupling":>24} {1.0:>10g} {np.nanmax(np.abs(q - reference)):>14.3e} '
          f'{steps / (12 * 0.3):>10.0f} {cpu:>7.2f}', flush=True)


if __name__ == '__main__':
    main()
