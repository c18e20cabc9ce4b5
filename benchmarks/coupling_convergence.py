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
The multirate coupling's error against the coupled reference, tolerance by tolerance.

A default piece hits a heavier, larger one at 1 m/s in free flight (test_coupling's case);
for each ``coupling_tolerance`` it prints the largest position error against Radau at rtol
1e-10 on the coupled system over 0.3 s, and the coupling intervals taken. Example::

    .venv/bin/python benchmarks/coupling_convergence.py
"""

from pathlib import Path
import sys

from cone_feeder_sim.physics.params import InteractionParams, ModelParams, ProductParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import SimParams, Simulator
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / 'test'))
from reference_contacts import crowd_trajectory  # noqa: E402, I100
from reference_model import table2_params  # noqa: E402

STILL = [[0.0, 0.0], [100.0, 0.0]]


def main() -> None:
    """Print one row per tolerance."""
    positions = np.array([[-0.065, 0.0, 20.0], [0.0, 0.0, 20.0]])
    velocities = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    t_out = np.linspace(0.01, 0.3, 30)
    ref = crowd_trajectory([table2_params(1), table2_params(1, m=0.2, s0=0.03)],
                           np.hstack([positions, velocities, np.zeros((2, 3))]), STILL, 0.3,
                           t_eval=t_out).y.reshape(2, 9, -1)
    print(f'{"tolerance (m)":>14} {"largest error (m)":>18} {"intervals":>10}')
    for tolerance in (1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10):
        model = ModelParams(interactions=InteractionParams(
            enabled=True, pull_off=0.0, coupling='multirate', coupling_tolerance=tolerance))
        sim = Simulator(SimParams(model=model), RotationProfile.from_table(STILL))
        sim.add(positions, velocities, [ProductParams(), ProductParams(m=0.2, s0=0.03)])
        worst, intervals = 0.0, 0
        for k, t in enumerate(t_out):
            result = sim.advance_to(float(t))
            intervals += result.stats.coupling_intervals
            worst = max(worst, float(np.abs(sim.world()[0] - ref[:, 0:3, k]).max()))
        print(f'{tolerance:>14g} {worst:>18.3g} {intervals:>10}', flush=True)


if __name__ == '__main__':
    main()
