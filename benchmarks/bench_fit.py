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
Benchmark: a 2-parameter trajectory fit on 5 pieces x 3 s of tracks (target: 60 s).

The tracks are simulated with d and mu_C 40 % and 15 % away from the parameter file's
values, sampled at 30 frames/s with 1 mm of noise until each piece leaves the cone. Four
fits, after the calibration line: from the parameter file's values, and from d = 1000,
mu_C = 0.35 (where one start of single shooting stops in another valley), each with one
start (``starts: 1``, the ``--quick`` fit, its Jacobian's columns on a thread per core)
and with the defaults (auto starts on a process per core, profile-likelihood intervals).

Each prints the estimates with their 95 % intervals, the test of fit, how many starts
reached the lowest cost, the wall time and the simulations (whole runs and windows), and
where the time went (simulations and wall time of the starts, profiles and restarts)::

    .venv/bin/python benchmarks/bench_fit.py
"""

from collections.abc import Iterator
import contextlib
import csv
from pathlib import Path
import tempfile
import threading
import time
from typing import Any

from calibration import calibration_line
from cone_feeder_sim.fit import problem as problem_module
from cone_feeder_sim.fit import shooting as shooting_module
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
FREE = {'model.d': [10.0, 1000.0], 'model.mu_C': [0.3, 0.98]}


class Stopwatch:
    """Sum the time spent in wrapped functions over all threads (s)."""

    def __init__(self) -> None:
        """Start at zero."""
        self.total = 0.0
        self._lock = threading.Lock()

    def wrap(self, function: Any) -> Any:
        """Return ``function`` timed."""
        def timed(*args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                with self._lock:
                    self.total += time.perf_counter() - start
        return timed


#: The benchmark's truth: d and mu_C 40 % and 15 % away from the parameter file's values.
TRUTH = set_scenario_key(set_scenario_key(BASE, 'model.d', 315.0), 'model.mu_C', 0.7225)


def write_tracks(folder: Path, truth: dict | None = None, seed: int = 5,
                 rate: float = 30.0) -> None:
    """Write 1-mm tracks of ``truth`` (TRUTH) at ``rate`` frames/s, each piece until it leaves."""
    scenario = scenario_from_mapping(TRUTH if truth is None else truth)
    times = np.arange(0.0, 3.0, 1.0 / rate)
    particle = np.tile(np.arange(5), len(times))
    t = np.repeat(times, 5)
    seen = predict(scenario, Tracks(particle, t, np.zeros((len(t), 3))))
    keep = np.hypot(seen[:, 0], seen[:, 1]) < scenario.model.r - 1e-6
    seen += np.random.default_rng(seed).normal(0.0, 0.001, seen.shape)
    with (folder / 'tracks.csv').open('w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(['particle', 't', 'x', 'y'])
        writer.writerows((p, s, x, y) for p, s, (x, y, _) in zip(
            particle[keep], t[keep], seen[keep]))


def run(label: str, content: dict, folder: Path) -> None:
    """Fit once and print the figures."""
    watch = Stopwatch()
    originals = problem_module.predict, shooting_module.trace
    problem_module.predict = watch.wrap(originals[0])
    shooting_module.trace = watch.wrap(originals[1])
    try:
        problem = FitProblem(fit_from_mapping(content, folder))
        start = time.perf_counter()
        result = fit(problem)
        wall = time.perf_counter() - start
    finally:
        problem_module.predict, shooting_module.trace = originals
    estimates = ', '.join(f'{key} = {estimate:.5g} [{low:.5g}, {high:.5g}]' for key, estimate,
                          low, high in zip(result.keys, result.estimate, result.low,
                                           result.high))
    test = result.fit_test
    assert test is not None
    print(f'{label}: {estimates}\n    success {result.success}, chi2/dof '
          f'{test.reduced:.3g}, {result.reached_best} of {len(result.start_costs)} starts at '
          f'the lowest cost; wall time {wall:.2f} s, {result.simulations} simulations and '
          f'{result.window_simulations} windows ({watch.total:.2f} s simulating in this '
          'process)\n    stages: ' + ', '.join(
              f'{name} {n} simulations {t:.2f} s' for name, (n, t) in result.stages.items()),
          flush=True)


@contextlib.contextmanager
def tracks_folder() -> Iterator[Path]:
    """Print the calibration, load the kernels, yield a folder with the tracks; calibrate."""
    print(calibration_line())
    warm_up()
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        write_tracks(folder)
        yield folder
    print(calibration_line())


def main() -> None:
    """Make the tracks, fit four ways, print the figures."""
    with tracks_folder() as folder:
        plain = {'scenario': BASE, 'tracks': 'tracks.csv', 'free': FREE}
        far = {**plain, 'scenario': set_scenario_key(set_scenario_key(
            BASE, 'model.d', 1000.0), 'model.mu_C', 0.35)}
        for where, content in (("from the parameter file's values", plain),
                               ('from d = 1000, mu_C = 0.35', far)):
            run(f'{where}: one start (--quick), a thread per core',
                {**content, 'starts': 1, 'workers': 0}, folder)
            run(f'{where}: the defaults (auto starts on a process per core)', content, folder)


if __name__ == '__main__':
    main()
