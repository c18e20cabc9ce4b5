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
Study: recovery without the truth, the fit's defaults against truths drawn over the box.

Ten truths (d, mu_C) drawn (seeded) over the fit file's box, d in [10, 1000] in log scale and
mu_C in [0.3, 0.98]; for each, the five pieces of bench_fit.py over 3 s, tracked at
30 frames/s with 1 mm of noise until they leave, fitted from the parameter file's values
with the defaults (auto starts, noise estimated from the tracks, profile intervals). Prints
each truth, the estimate and its 95 % interval, whether the interval covers the truth, the
test of fit, the starts at the lowest cost, the restarts from better points the profiles
found and the wall time; then the counts: covered, reported ``success: true`` with the truth
more than three intervals' widths away (should be none), and the restarts (all, the most in
one fit). ``--keys 3`` frees mu_S too (truths drawn in [0.5, 2])::

    .venv/bin/python benchmarks/fit_recovery.py [--truths 10] [--keys 2]
"""

import argparse
from pathlib import Path
import tempfile
import time

from bench_fit import BASE, write_tracks
from calibration import calibration_line
from cone_feeder_sim.fit.problem import FitProblem
from cone_feeder_sim.fit.solve import fit
from cone_feeder_sim.fit.spec import fit_from_mapping
from cone_feeder_sim.formats.scenario_file import set_scenario_key
from cone_feeder_sim.physics.simulation import warm_up
import numpy as np

BOXES = {'model.d': (10.0, 1000.0), 'model.mu_C': (0.3, 0.98), 'model.mu_S': (0.5, 2.0)}


def main() -> None:
    """Draw the truths, fit each with the defaults, print the rows and the counts."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--truths', type=int, default=10)
    parser.add_argument('--keys', type=int, choices=(2, 3), default=2)
    args = parser.parse_args()
    keys = list(BOXES)[:args.keys]
    print(calibration_line())
    warm_up()
    rng = np.random.default_rng(2026)
    covered = trusted_wrong = 0
    restarts = []
    for n in range(args.truths):
        values = []
        for key in keys:
            low, high = BOXES[key]
            values.append(float(np.exp(rng.uniform(np.log(low), np.log(high)))
                                if key == 'model.d' else rng.uniform(low, high)))
        truth = BASE
        for key, value in zip(keys, values):
            truth = set_scenario_key(truth, key, value)
        with tempfile.TemporaryDirectory() as name:
            folder = Path(name)
            write_tracks(folder, truth, 100 + n)
            start = time.perf_counter()
            result = fit(FitProblem(fit_from_mapping(
                {'scenario': BASE, 'tracks': 'tracks.csv',
                 'free': {k: list(BOXES[k]) for k in keys}}, folder)))
            wall = time.perf_counter() - start
        inside = all(lo < v < hi for v, lo, hi in zip(values, result.low, result.high))
        far = any(abs(v - e) > 3.0 * (hi - lo) for v, e, lo, hi in zip(
            values, result.estimate, result.low, result.high))
        covered += inside
        trusted_wrong += result.success and far
        restarts.append(len(result.restarts))
        test = result.fit_test
        assert test is not None
        rows = '; '.join(f'{k} {v:.4g} -> {e:.4g} [{lo:.4g}, {hi:.4g}]' for k, v, e, lo, hi in
                         zip(keys, values, result.estimate, result.low, result.high))
        print(f'truth {n}: {rows}; covered {inside}; success {result.success} (chi2/dof '
              f'{test.reduced:.3g}); {result.reached_best} of {len(result.start_costs)} '
              f'starts at the lowest cost; {len(result.restarts)} restarts; {wall:.1f} s',
              flush=True)
    print(f'covered {covered} of {args.truths}; success with the truth more than 3 '
          f'widths away: {trusted_wrong}; restarts {sum(restarts)} in all, at most '
          f'{max(restarts)} in one fit')
    print(calibration_line())


if __name__ == '__main__':
    main()
