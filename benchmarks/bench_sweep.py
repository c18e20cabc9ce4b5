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
Benchmark: a sweep of 16 jobs on the local Dask cluster against the same jobs run serially.

Serial: every job's scenario file run by ``cone-feeder-sim run`` (its ``main``), one after
the other in this process, kernels already loaded, numba on every core (what a user gets
with a loop over ``cone-feeder-sim run``, less the process starts). Sweep: ``run_sweep``
into a new directory, start of the LocalCluster (one single-threaded worker per core) and
its kernel loading included. The two alternate, ``--rounds`` times, so that both see the
same machine; the calibration workload is printed first and last.

States (``--states``): ``contact``, twelve touching pieces driven back and forth for 14 s
(interactions on, about a second per job on the development machine), and ``alone``, the
same pieces without contact (a third of that, and numba's threads speed the serial run:
the cluster's overhead shows). ``--stretch`` makes the jobs longer (the scenario's times
multiplied). Target: wall time of the sweep at most 0.6 of the serial one with 16 jobs on
2 cores::

    .venv/bin/python benchmarks/bench_sweep.py
"""

import argparse
import contextlib
import io
import json
import math
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

from calibration import calibration_line
from cone_feeder_sim.cli import main as cli_main
from cone_feeder_sim.physics.simulation import warm_up
from cone_feeder_sim.sweep.cluster import available_cores
from cone_feeder_sim.sweep.job import write_job_files
from cone_feeder_sim.sweep.run import run_sweep
from cone_feeder_sim.sweep.spec import Sweep, sweep_from_mapping

PIECES = [{'position': [0.03 + 0.01 * (i % 8) * math.cos(i),
                        0.03 + 0.01 * (i % 8) * math.sin(i), 0.0], 'on_surface': True}
          for i in range(12)]
ROTATION = [[0.0, 0.0], [1.0, 4.0], [3.0, 4.0], [4.0, -4.0], [9.0, -4.0], [10.0, 9.0]]


def make_sweep(state: str, jobs: int, stretch: float = 1.0) -> Sweep:
    """
    Return a sweep of ``jobs`` jobs (model.d x model.mu_C) in the given state.

    stretch: the rotation table's times and the duration multiplied by it (longer jobs).
    """
    rotation = [[stretch * t, omega] for t, omega in ROTATION]
    base = {'duration': 14.0 * stretch, 'rotation': rotation, 'particles': PIECES,
            'interactions': {'enabled': state == 'contact'}}
    d = [30.0 + 720.0 * i / max(1, jobs // 2 - 1) for i in range(jobs // 2)]
    return sweep_from_mapping({'scenario': base, 'grid': {'model.d': d,
                                                          'model.mu_C': [0.7, 0.85]}},
                              Path('.'), state)


def serial(sweep: Sweep, tmp: Path) -> float:
    """Run every job with cone-feeder-sim run in this process; return the wall time (s)."""
    start = time.perf_counter()
    for job in sweep.jobs:
        directory = tmp / job.name
        directory.mkdir(parents=True)
        scenario = write_job_files(job, directory)
        with contextlib.redirect_stderr(io.StringIO()):
            code = cli_main(['run', str(scenario), '--events', str(directory / 'e.csv'),
                             '--quiet'])
        assert code == 0
    return time.perf_counter() - start


def serial_processes(sweep: Sweep, tmp: Path) -> float:
    """Run every job as its own cone-feeder-sim run process; return the wall time (s)."""
    command = str(Path(sys.executable).parent / 'cone-feeder-sim')
    start = time.perf_counter()
    for job in sweep.jobs:
        directory = tmp / job.name
        directory.mkdir(parents=True)
        scenario = write_job_files(job, directory)
        subprocess.run([command, 'run', str(scenario), '--events', str(directory / 'e.csv'),
                        '--quiet'], check=True, capture_output=True)
    return time.perf_counter() - start


def swept(sweep: Sweep, out: Path, workers: int | None) -> tuple[float, float]:
    """Run the sweep into ``out``; return the wall time and the jobs' summed CPU time (s)."""
    start = time.perf_counter()
    report = run_sweep(sweep, out, workers=workers)
    wall = time.perf_counter() - start
    assert report.done == len(sweep.jobs), report
    cpu = sum(json.loads(p.read_text())['cpu_s'] for p in out.glob('jobs/*/result.json'))
    return wall, cpu


def main() -> None:
    """Print the calibration, the serial and sweep times and their ratio per state."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--jobs', type=int, default=16)
    parser.add_argument('--rounds', type=int, default=2)
    parser.add_argument('--workers', type=int, default=None)
    parser.add_argument('--processes', action='store_true',
                        help='also time the serial runs as one process per job (round 0)')
    parser.add_argument('--stretch', type=float, nargs='+', default=[1.0, 4.0],
                        help='job lengths: the scenario time stretched by these factors')
    parser.add_argument('--states', nargs='+', default=['contact', 'alone'],
                        choices=['contact', 'alone'])
    args = parser.parse_args()
    print(calibration_line())
    print(f'cores: {available_cores()}, numba threads in the serial runs: '
          f'{os.environ.get("NUMBA_NUM_THREADS", "default")}, jobs: {args.jobs}')
    warm_up()
    with tempfile.TemporaryDirectory() as tmp:
        for state in args.states:
            for stretch in args.stretch:
                sweep = make_sweep(state, args.jobs, stretch)
                for r in range(args.rounds):
                    base = Path(tmp) / f'{state}-{stretch}-{r}'
                    serial_s = serial(sweep, base / 'serial')
                    sweep_s, cpu_s = swept(sweep, base / 'sweep', args.workers)
                    print(f'{state:8s} x{stretch:<4g} round {r}: serial {serial_s:6.2f} s, sweep '
                          f'{sweep_s:6.2f} s (jobs {cpu_s:6.2f} s CPU), sweep/serial '
                          f'{sweep_s / serial_s:.2f}', flush=True)
                    if args.processes and r == 0:
                        alone = serial_processes(sweep, base / 'processes')
                        print(f'{"":8s} {"":5s} serial as {len(sweep.jobs)} processes '
                              f'{alone:6.2f} s: sweep/serial {sweep_s / alone:.2f}', flush=True)
    print(calibration_line())


if __name__ == '__main__':
    main()
