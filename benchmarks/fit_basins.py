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
Study: the starts from which single and multiple shooting find the truth.

The tracks of bench_fit.py (5 pieces x 3 s, d = 315, mu_C = 0.7225, 30 frames/s, 1 mm of
noise, each piece until it leaves the cone) are fitted from a grid of 5 x 5 starts in
d in [15, 1000] and mu_C in [0.35, 0.95], by single shooting and by multiple shooting with
windows of 0.5 s and 0.25 s. A fit has found the truth when both estimates lie within two
standard errors of it. Prints the grid of each method (+ found, . not) and the counts::

    .venv/bin/python benchmarks/fit_basins.py
"""

import time

from bench_fit import BASE, FREE, tracks_folder
from cone_feeder_sim.fit.problem import FitProblem
from cone_feeder_sim.fit.solve import fit
from cone_feeder_sim.fit.spec import fit_from_mapping
from cone_feeder_sim.formats.scenario_file import set_scenario_key
import numpy as np

D_STARTS = (15.0, 50.0, 150.0, 500.0, 1000.0)
MU_STARTS = (0.35, 0.5, 0.65, 0.8, 0.95)
METHODS = (('single shooting', None), ('segments 0.5', 0.5), ('segments 0.25', 0.25))
TRUTH = (315.0, 0.7225)


def main() -> None:
    """Fit from every start with every method; print the grids."""
    with tracks_folder() as folder:
        for label, segments in METHODS:
            start = time.perf_counter()
            rows = []
            for mu in MU_STARTS:
                marks = ''
                for d in D_STARTS:
                    scenario = set_scenario_key(set_scenario_key(BASE, 'model.d', d),
                                                'model.mu_C', mu)
                    content = {'scenario': scenario, 'tracks': 'tracks.csv', 'free': FREE}
                    if segments is not None:
                        content['segments'] = segments
                    result = fit(FitProblem(fit_from_mapping(content, folder)))
                    found = np.all(np.abs(result.estimate - TRUTH) < 2.0 * result.stderr)
                    marks += '+' if found else '.'
                rows.append(f'    mu_C {mu:4.2f}  {marks}')
            found = sum(row.count('+') for row in rows)
            print(f'{label}: the truth from {found} of {len(D_STARTS) * len(MU_STARTS)} '
                  f'starts ({time.perf_counter() - start:.0f} s); d = '
                  f'{", ".join(f"{d:g}" for d in D_STARTS)} left to right')
            print('\n'.join(rows), flush=True)


if __name__ == '__main__':
    main()
