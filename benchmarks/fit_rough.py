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
Study: fits where the cost is rough, single shooting against multiple shooting, side by side.

Cases like a new user's: the five pieces of bench_fit.py on a cone that turns one way at
6 rad/s and reverses to 5 rad/s (pieces stick, then break free at different times), 3 s
tracked at 33 frames/s with 1 mm of noise until each piece leaves, d and mu_C free over
the fit file's box, truths away from the parameter file's values where stick and slip
change with them. Each case is fitted from the parameter file's values with the defaults
(single shooting, restarts from better profile points, auto starts) and with
``segments: 0.25`` (multiple shooting first); the last case is held out (not one the
defaults were tuned on). Prints per case and method the estimates with their intervals,
whether both cover the truth, success, the restarts and the starts, and the wall time::

    .venv/bin/python benchmarks/fit_rough.py [--methods single segments]
"""

import argparse
from pathlib import Path
import tempfile
import time

from bench_fit import BASE, FREE, write_tracks
from calibration import calibration_line
from cone_feeder_sim.fit.problem import FitProblem
from cone_feeder_sim.fit.solve import fit
from cone_feeder_sim.fit.spec import fit_from_mapping
from cone_feeder_sim.formats.scenario_file import set_scenario_key
from cone_feeder_sim.physics.simulation import warm_up

ROUGH = BASE
#: (d, mu_C) of the cases; the last is held out
TRUTHS = ((315.0, 0.7225), (500.0, 0.6), (120.0, 0.78), (60.0, 0.65), (800.0, 0.55),
          (150.0, 0.62))
METHODS = {'single': {}, 'segments': {'segments': 0.25}}


def main() -> None:
    """Fit every case with every method; print the rows and the counts."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--methods', nargs='+', choices=tuple(METHODS), default=list(METHODS))
    parser.add_argument('--cases', type=int, nargs='+', default=list(range(len(TRUTHS))))
    args = parser.parse_args()
    print(calibration_line())
    warm_up()
    counts = {name: [0, 0] for name in args.methods}
    for n in args.cases:
        d, mu_c = TRUTHS[n]
        truth = set_scenario_key(set_scenario_key(ROUGH, 'model.d', d), 'model.mu_C', mu_c)
        label = f'case {n}{" (held out)" if n == len(TRUTHS) - 1 else ""}: d = {d:g}, ' \
                f'mu_C = {mu_c:g}'
        print(label, flush=True)
        with tempfile.TemporaryDirectory() as name:
            folder = Path(name)
            write_tracks(folder, truth, 300 + n, rate=33.0)
            for method in args.methods:
                start = time.perf_counter()
                result = fit(FitProblem(fit_from_mapping(
                    {'scenario': ROUGH, 'tracks': 'tracks.csv', 'free': FREE,
                     **METHODS[method]}, folder)))
                wall = time.perf_counter() - start
                inside = all(lo < v < hi for v, lo, hi in zip((d, mu_c), result.low,
                                                              result.high))
                counts[method][0] += inside
                counts[method][1] += result.success and inside
                estimates = ', '.join(
                    f'{e:.4g} [{lo:.4g}, {hi:.4g}]'
                    for e, lo, hi in zip(result.estimate, result.low, result.high))
                print(f'  {method:>9}: {estimates}; covers the truth {inside}, success '
                      f'{result.success}, {len(result.restarts)} restarts, '
                      f'{result.reached_best} of {len(result.start_costs)} starts at the '
                      f'lowest; {wall:.1f} s, {result.simulations} simulations', flush=True)
                for warning in result.warnings:
                    print(f'             warning: {warning}')
    for method, (inside, trusted) in counts.items():
        print(f'{method}: the truth inside both intervals in {inside} of {len(args.cases)} '
              f'cases, with success: true in {trusted}')
    print(calibration_line())


if __name__ == '__main__':
    main()
