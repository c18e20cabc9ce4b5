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
Profile: where the integration steps go on bench_core.py's reversing cone.

Advances its scenario (``--pieces`` pieces, default 300) in 20-ms ticks and prints, every
0.1 s, the accepted and rejected steps per piece in that tick, then the share of all steps
taken during the ramps of omega(t), in the 0.1 s after each kink of omega(t), and rejected::

    .venv/bin/python benchmarks/steps_profile.py [--pieces 300]
"""

import argparse

from bench_core import DURATION, INTERVAL, starts, TABLE
from calibration import calibration_line
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import SimParams, Simulator
import numpy as np


def main() -> None:
    """Run the scenario tick by tick and print where its steps went."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--pieces', type=int, default=300)
    args = parser.parse_args()
    print(calibration_line())
    sim = Simulator(SimParams(), RotationProfile.from_table(TABLE))
    sim.add(starts(args.pieces))
    rows = []
    k = 0
    while sim.t < DURATION - 1e-12 and sim.state.count:
        k += 1
        count = sim.state.count
        step = sim.advance_to(min(DURATION, k * INTERVAL))
        rows.append((sim.t, count, step.stats.accepted, step.stats.rejected))
    table = np.array(rows)
    print(f'{"tick end s":>10} {"pieces":>7} {"accepted/piece":>15} {"rejected/piece":>15}')
    for t, count, accepted, rejected in table[::5]:
        print(f'{t:>10.2f} {int(count):>7} {accepted / count:>15.1f} {rejected / count:>15.2f}')
    steps = table[:, 2] + table[:, 3]
    after = np.zeros(len(table), dtype=bool)
    ramps = np.zeros(len(table), dtype=bool)
    knots = [t for t, _ in TABLE]
    for t in knots[1:]:
        after |= (table[:, 0] > t) & (table[:, 0] <= t + 0.1 + 1e-9)
    for (t0, w0), (t1, w1) in zip(TABLE, TABLE[1:]):
        if w0 != w1:
            ramps |= (table[:, 0] > t0) & (table[:, 0] <= t1 + 1e-9)
    print(f'steps during the ramps of omega(t): {steps[ramps].sum() / steps.sum():.3f} '
          f'(of the time: {ramps.mean():.3f}); in the 0.1 s after a kink: '
          f'{steps[after].sum() / steps.sum():.3f} (of the time: {after.mean():.3f}); '
          f'rejected: {table[:, 3].sum() / steps.sum():.3f}')
    print(calibration_line())


if __name__ == '__main__':
    main()
