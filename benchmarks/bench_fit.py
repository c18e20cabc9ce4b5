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
Benchmark: a 2-parameter trajectory fit on 5 pieces x 3 s of tracks (issue 21's target: 60 s).

The tracks are simulated with d and mu_C 40 % and 15 % away from the parameter file's
values, sampled at 30 frames/s with 1 mm of noise, and fitted from the parameter file's
values (model.d in [10, 1000], model.mu_C in [0.3, 0.98]). Prints the wall time, the number
of simulations and the share of the time spent simulating, after the calibration line::

    .venv/bin/python benchmarks/bench_fit.py
"""

import csv
from pathlib import Path
import tempfile
import time

from calibration import calibration_line
from cone_feeder_sim.fit import problem as problem_module
from cone_feeder_sim.fit.problem import FitProblem, predict
from cone_feeder_sim.fit.solve import fit
from cone_feeder_sim.fit.spec import fit_from_mapping
from cone_feeder_sim.fit.tracks import Tracks
from cone_feeder_sim.formats.scenario_file import scenario_from_mapping, set_scenario_key
from cone_feeder_sim.physics.simulation import warm_up
import numpy as np

BASE = {'duration': 3.0, 'rotation': [[0.0, 0.0], [0.5, -8.0], [1.5, -8.0], [2.0, 6.0]],
        'particles': [{'position': p, 'on_surface': True} for p in (
            [0.11, -0.01, 0.0], [-0.10, -0.01, 0.0], [0.08, -0.13, 0.0], [-0.07, 0.04, 0.0],
            [0.14, 0.06, 0.0])]}


def main() -> None:
    """Make the tracks, fit, print the figures."""
    print(calibration_line())
    warm_up()
    truth = set_scenario_key(set_scenario_key(BASE, 'model.d', 315.0), 'model.mu_C', 0.7225)
    times = np.arange(0.0, 3.0, 1.0 / 30.0)
    particle = np.tile(np.arange(5), len(times))
    t = np.repeat(times, 5)
    seen = predict(scenario_from_mapping(truth), Tracks(particle, t, np.zeros((len(t), 3))))
    seen += np.random.default_rng(0).normal(0.0, 0.001, seen.shape)
    with tempfile.TemporaryDirectory() as folder:
        with (Path(folder) / 'tracks.csv').open('w', newline='') as stream:
            writer = csv.writer(stream)
            writer.writerow(['particle', 't', 'x', 'y'])
            writer.writerows((p, s, x, y) for p, s, (x, y, _) in zip(particle, t, seen))
        spec = fit_from_mapping({'scenario': BASE, 'tracks': 'tracks.csv', 'free': {
            'model.d': [10.0, 1000.0], 'model.mu_C': [0.3, 0.98]}}, Path(folder))
    simulating = [0.0]
    original = problem_module.predict

    def timed(*args, **kwargs):
        start = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            simulating[0] += time.perf_counter() - start

    problem_module.predict = timed
    start = time.perf_counter()
    result = fit(FitProblem(spec))
    wall = time.perf_counter() - start
    problem_module.predict = original
    for key, estimate, stderr in zip(result.keys, result.estimate, result.stderr):
        print(f'{key} = {estimate:.6g} +- {stderr:.3g}')
    print(f'wall time {wall:.2f} s, {result.simulations} simulations, '
          f'{100 * simulating[0] / wall:.0f} % of the time simulating')
    print(calibration_line())


if __name__ == '__main__':
    main()
