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
Benchmark: what contact between pieces costs the twin, per frame (``Twin.update``).

The plant: N pieces dropped at random on the annulus 0.05-0.17 m of a cone reversing at
±3 rad/s (twin_headless.py's profile), the pair law on; the camera sees every piece at 30
frames/s with 2 mm of noise. Twins of M members take it with the pair law on and off, with
the default window of 0.5 s and with window 0 (no smoother: what the members alone cost);
the mean and p95 of the frames after the first 2 s are printed, side by side in one run::

    .venv/bin/python benchmarks/twin_contact_cost.py [--pieces 10 30] [--members 4]
        [--seconds 6]
"""

import argparse
from dataclasses import replace
import time

from calibration import calibration_line
from cone_feeder_sim.physics.params import InteractionParams, ModelParams
from cone_feeder_sim.physics.simulation import advance, SimParams, warm_up, world_from_cone
from cone_feeder_sim.twin.estimator import Twin, TwinSettings
import numpy as np
from twin_headless import plant_start, reversing_profile


def frames(pieces: int, seconds: float) -> list[tuple[float, float, np.ndarray]]:
    """Return the plant's (t, cone speed, detections (n, 2)) at 30 frames/s."""
    model = replace(ModelParams(), interactions=InteractionParams(enabled=True))
    params = SimParams(model=model)
    plant, rng = plant_start(params, pieces)
    profile = reversing_profile(seconds)
    out = []
    for k in range(1, int(round(30 * seconds)) + 1):
        t = k / 30.0
        plant = advance(plant, params, profile, t).state
        seen, _, _ = world_from_cone(plant.y, plant.angle, profile.omega(t))
        out.append((t, profile.omega(t), seen[:, :2] + rng.normal(0.0, 0.002, (plant.count, 2))))
    return out


def case(stream: list, members: int, contact: bool, window: float) -> str:
    """Run a twin over the stream; return its line of figures."""
    model = replace(ModelParams(), interactions=InteractionParams(enabled=contact))
    twin = Twin(SimParams(model=model), TwinSettings(members=members, window=window))
    costs = []
    for t, omega, xy in stream:
        twin.cone_speed(t, omega)
        start = time.perf_counter()
        twin.update(t, xy)
        costs.append(time.perf_counter() - start)
    ms = 1e3 * np.array(costs[60:])
    return (f'pair law {"on " if contact else "off"}, window {window:g} s: mean {ms.mean():.1f} '
            f'ms, p95 {np.percentile(ms, 95):.1f} ms a frame; pieces followed '
            f'{len(twin.pieces()[0])} of {len(stream[-1][2])}')


def main() -> None:
    """Print the calibration and the cases."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--pieces', type=int, nargs='+', default=[10, 30])
    parser.add_argument('--members', type=int, default=4)
    parser.add_argument('--seconds', type=float, default=6.0)
    args = parser.parse_args()
    print(calibration_line(), flush=True)
    warm_up()
    for pieces in args.pieces:
        stream = frames(pieces, args.seconds)
        for contact, window in ((False, 0.5), (True, 0.5), (False, 0.0), (True, 0.0)):
            print(f'N = {pieces}, M = {args.members}, '
                  + case(stream, args.members, contact, window), flush=True)
    print(calibration_line(), flush=True)


if __name__ == '__main__':
    main()
