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
Running one job of a sweep: the job's scenario through ``cone-feeder-sim run``'s code.

:func:`run_job` is what a Dask worker calls. It writes the job's scenario (and parameter
file) into a temporary directory, loads it with :func:`~cone_feeder_sim.formats.
scenario_file.load_scenario` and runs it with :func:`~cone_feeder_sim.formats.run_files.
run_to_files`, exactly as ``cone-feeder-sim run scenario.yaml --events events.csv`` does,
and returns the files' bytes and the job's metrics: the worker needs no shared file
system, and the client alone writes the sweep's directory. A job that raises is a result
(status ``failed`` with its error), not an exception.
"""

import contextlib
from dataclasses import dataclass, field
import os
from pathlib import Path
import shutil
import socket
import sys
import tempfile
import time
import traceback
from typing import Any

import numba
from numba.core.registry import CPUDispatcher
import numpy as np

from .spec import Job, PARAMETERS_NAME
from ..feeder.runner import RunResult
from ..feeder.scenario import Scenario
from ..formats.run_files import run_to_files
from ..formats.scenario_file import load_scenario
from ..physics.integrator import set_threads
from ..physics.simulation import warm_up
from ..weigher.combination import warm_up as warm_up_weigher

SCENARIO_NAME = 'scenario.yaml'
EVENTS_NAME = 'events.csv'
PACKS_NAME = 'packs.csv'
#: The metrics of a job, in summary order (``mass_chNN`` per channel follow ``mass``).
METRICS = ('exits', 'remaining', 'failures', 'steps', 'rejected', 'end_time',
           'mean_exit_time', 'mass', 'packs', 'packs_per_minute', 'giveaway_mean',
           'giveaway_std', 'under_target')


@dataclass(frozen=True)
class JobOutcome:
    """
    What a job produced, wherever it ran.

    status: ``done`` or ``failed`` (error: the exception, type and message; traceback: its
    traceback); metrics: the summary values (:data:`METRICS`, ``mass_chNN`` in kg per
    channel; times in s; NaN where undefined, e.g. the mean exit time without exits; the
    weigher's only with a weigher); files: file name -> bytes (events CSV, packs CSV);
    cpu_s: the CPU time of the worker process during the job (numba's threads included;
    the job's own with one job per process, as a sweep runs them); wall_s; worker:
    host:pid of the worker; kernel_loads: compiled kernels the job had to load (0 where
    the worker loaded them when it joined).
    """

    name: str
    digest: str
    status: str
    error: str = ''
    traceback: str = ''
    metrics: dict[str, Any] = field(default_factory=dict)
    files: dict[str, bytes] = field(default_factory=dict)
    cpu_s: float = 0.0
    wall_s: float = 0.0
    worker: str = ''
    kernel_loads: int = 0


def kernel_loads() -> int:
    """Return how many compiled kernels this process has loaded or compiled (numba's count)."""
    total = 0
    for name, module in list(sys.modules.items()):
        if not name.startswith('cone_feeder_sim.') or module is None:
            continue
        for obj in vars(module).values():
            if isinstance(obj, CPUDispatcher):
                total += sum(obj.stats.cache_hits.values()) + sum(
                    obj.stats.cache_misses.values())
    return total


def load_kernels() -> None:
    """Load (or compile) every compiled kernel a job may call: the cone's and the weigher's."""
    warm_up()
    warm_up_weigher()


def job_metrics(scenario: Scenario, result: RunResult) -> dict[str, Any]:
    """Return a run's summary metrics (:data:`METRICS` and ``mass_chNN``)."""
    table = result.exit_table()
    channels = scenario.model.channels.count
    per_channel = np.bincount(table['channel'] - 1, weights=table['mass'], minlength=channels)
    metrics: dict[str, Any] = {
        'exits': int(table['ids'].size), 'remaining': int(result.remaining_ids.size),
        'failures': len(result.failures), 'steps': result.accepted_steps,
        'rejected': result.rejected_steps, 'end_time': result.end_time,
        'mean_exit_time': float(np.mean(table['t'])) if table['t'].size else float('nan'),
        'mass': float(np.sum(table['mass']))}
    if result.weigher is not None:
        stats = result.weigher.stats()
        metrics.update(packs=stats.packs, packs_per_minute=stats.packs_per_minute,
                       giveaway_mean=stats.giveaway_mean, giveaway_std=stats.giveaway_std,
                       under_target=stats.under_target)
    metrics.update({f'mass_ch{c + 1:02d}': float(m) for c, m in enumerate(per_channel)})
    return metrics


def write_job_files(job: Job, directory: Path) -> Path:
    """Write the job's scenario (and parameter file) into ``directory``; return the scenario."""
    (directory / PARAMETERS_NAME).write_text(job.parameters, encoding='utf-8')
    path = directory / SCENARIO_NAME
    path.write_text(job.scenario, encoding='utf-8')
    return path


def run_job(job: Job) -> JobOutcome:
    """Run one job on one thread (numba's too) and return its outcome; never raises."""
    wall, cpu = time.perf_counter(), time.process_time()
    loads = kernel_loads()
    worker = f'{socket.gethostname()}:{os.getpid()}'
    tmp = tempfile.mkdtemp(prefix=f'cone-feeder-sim-job-{job.name}-')
    try:  # error messages name the job's directory of the sweep, not the temporary one
        with contextlib.ExitStack() as cleanup:
            cleanup.callback(shutil.rmtree, tmp, ignore_errors=True)
            cleanup.callback(numba.set_num_threads, numba.get_num_threads())
            set_threads(1)  # numba's thread count is per thread: this job's thread
            directory = Path(tmp)
            scenario = load_scenario(write_job_files(job, directory))
            packs = directory / PACKS_NAME if scenario.weigher is not None else None
            files = run_to_files(scenario, directory / EVENTS_NAME, packs=packs,
                                 source=SCENARIO_NAME)
            metrics = job_metrics(scenario, files.result)
            content = {path.name: path.read_bytes()
                       for path in (directory / EVENTS_NAME, packs) if path is not None}
    except Exception as exc:  # noqa: B902 - a job's error is its result; the sweep goes on
        return JobOutcome(name=job.name, digest=job.digest, status='failed',
                          error=f'{type(exc).__name__}: {exc}'.replace(tmp, f'jobs/{job.name}'),
                          traceback=traceback.format_exc(),
                          cpu_s=time.process_time() - cpu, wall_s=time.perf_counter() - wall,
                          worker=worker, kernel_loads=kernel_loads() - loads)
    return JobOutcome(name=job.name, digest=job.digest, status='done', metrics=metrics,
                      files=content, cpu_s=time.process_time() - cpu,
                      wall_s=time.perf_counter() - wall, worker=worker,
                      kernel_loads=kernel_loads() - loads)
