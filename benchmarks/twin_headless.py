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
Benchmark: the headless twin (``cone-feeder-sim twin``) over a recorded 60-s stream.

The stream is the physics core's: 30 pieces at rest on the annulus 0.05-0.17 m, a cone
reversing between -3 and 3 rad/s every 2 s, detections at 30 frames/s with 2 mm of noise,
the cone speed at each frame. The twin file's defaults (forecasts every 0.1 s at 0.5, 1
and 2 s) with M members (default: the twin file's, 8); prints the wall time of the run
against the stream's 60 s::

    .venv/bin/python benchmarks/twin_headless.py [--seconds 60] [--members 32 8]
        [--riders true false] [--smoother-pieces 6 4 6 4]

--riders false integrates every piece of a forecast to the horizon (forecast.forecast's
riders), to compare with the default side by side; --smoother-pieces runs each count in
turn (the pieces a window weighs d and mu_C by; default: the twin file's).
"""

import argparse
import csv
from pathlib import Path
import tempfile
import time

from calibration import calibration_line
from cone_feeder_sim.physics.params import ModelParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    add_particles, advance, resting_height, SimParams, SimState, warm_up, world_from_cone)
from cone_feeder_sim.twin.estimator import TwinSettings
from cone_feeder_sim.twin.run import run_twin
from cone_feeder_sim.twin.spec import load_twin, TwinSpec
import numpy as np
import yaml


def reversing_profile(seconds: float) -> RotationProfile:
    """Return the stream's cone: up to 3 rad/s in 0.5 s, reversing every 2 s (0.5-s ramps)."""
    table = [[0.0, 0.0], [0.5, 3.0]]
    for k in range(int(seconds / 2.0) + 1):
        sign = 1.0 if k % 2 == 0 else -1.0
        table += [[2.0 * k + 1.5, sign * 3.0], [2.0 * k + 2.0, -sign * 3.0]]
    return RotationProfile.from_table(table)


def plant_start(params: SimParams, pieces: int = 30) -> tuple[SimState, np.random.Generator]:
    """Return the plant's pieces at rest on the annulus, and the stream's noise source."""
    model = params.model
    rng = np.random.default_rng(30)
    r = np.sqrt(rng.uniform(0.05 ** 2, 0.17 ** 2, pieces))
    a = rng.uniform(0.0, 2.0 * np.pi, pieces)
    q = np.array([[x, y, resting_height(model, model.product, x, y)]
                  for x, y in zip(r * np.cos(a), r * np.sin(a))])
    return add_particles(SimState(), params, q)[0], rng


def write_stream(folder: Path, seconds: float) -> None:
    """Simulate the plant and write detections.csv, cone.csv, scenario.yaml."""
    params = SimParams(model=ModelParams())
    profile = reversing_profile(seconds)
    plant, rng = plant_start(params)
    with (folder / 'detections.csv').open('w', newline='') as d, \
            (folder / 'cone.csv').open('w', newline='') as c:
        detections, cone = csv.writer(d), csv.writer(c)
        detections.writerow(['t', 'x', 'y', 'z', 'track_id'])
        cone.writerow(['t', 'omega'])
        for k in range(1, int(round(30 * seconds)) + 1):
            t = k / 30.0
            plant = advance(plant, params, profile, t).state
            cone.writerow([f'{t:.6f}', profile.omega(t)])
            seen, _, _ = world_from_cone(plant.y, plant.angle, profile.omega(t))
            seen[:, :2] += rng.normal(0.0, 0.002, (plant.count, 2))
            for (x, y, z), i in zip(seen, plant.ids):
                detections.writerow([f'{t:.6f}', x, y, z, int(i)])
    (folder / 'scenario.yaml').write_text(yaml.safe_dump(
        {'duration': seconds, 'rotation': [[0.0, 0.0]],
         'particles': [{'position': [0.1, 0.0, 0.0], 'on_surface': True}]}))


def stream_twin(folder: Path, **settings: object) -> TwinSpec:
    """Write a twin file for :func:`write_stream`'s files in folder (with settings); load it."""
    (folder / 'twin.yaml').write_text(yaml.safe_dump(
        {'scenario': 'scenario.yaml', 'detections': 'detections.csv', 'cone': 'cone.csv',
         **settings}))
    return load_twin(folder / 'twin.yaml')


def main() -> None:
    """Print the calibration and the wall time per ensemble size."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seconds', type=float, default=60.0)
    parser.add_argument('--members', type=int, nargs='+', default=[None])
    parser.add_argument('--riders', choices=['true', 'false'], nargs='+', default=['true'])
    parser.add_argument('--smoother-pieces', type=int, nargs='+', default=[None])
    args = parser.parse_args()
    print(calibration_line(), flush=True)
    warm_up()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write_stream(folder, args.seconds)
        runs = ((m, r, k) for m in args.members for r in args.riders
                for k in args.smoother_pieces)
        for n, (members, riders, pieces) in enumerate(runs):
            settings = {key: value for key, value in (('members', members),
                                                      ('smoother_pieces', pieces))
                        if value is not None}
            spec = stream_twin(folder, **settings)
            start = time.perf_counter()
            summary = run_twin(spec, folder / f'out{n}', riders=riders == 'true')
            wall = time.perf_counter() - start
            chosen = spec.tuning.get('smoother_pieces', TwinSettings.smoother_pieces)
            print(f'M = {spec.members}, riders {riders}, smoother_pieces {chosen}: '
                  f'{wall:.1f} s wall for a '
                  f'{args.seconds:g}-s stream of 30 pieces ({summary.frames} frames, '
                  f'{summary.forecasts} forecasts, NIS {summary.nis:.0f} for '
                  f'{summary.observed})', flush=True)
    print(calibration_line(), flush=True)


if __name__ == '__main__':
    main()
