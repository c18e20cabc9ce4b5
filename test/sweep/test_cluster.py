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
Sweeps on real Dask processes: a worker killed mid-sweep, an interrupted sweep resumed.

A scheduler and two workers started with the ``dask`` command, and the local cluster of
``cone-feeder-sim sweep``; results equal to ``cone-feeder-sim run`` of each job, bit for bit.
"""

import dataclasses
import io
import json
import logging
import math
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time

from cone_feeder_sim.cli import main
from cone_feeder_sim.sweep.cluster import dask_client, HEARTBEAT_FAILURE, quiet_heartbeat
from cone_feeder_sim.sweep.job import write_job_files
from cone_feeder_sim.sweep.run import run_sweep
from cone_feeder_sim.sweep.spec import load_sweep
from distributed import Client
import pytest
import yaml

BIN = Path(sys.executable).parent
#: Generous caps on waiting for progress (processes start, load kernels, run jobs).
START_TIMEOUT = 120.0
SWEEP_TIMEOUT = 600.0
#: Eight pieces driven back and forth, then off the cone, with a weigher: each job is about
#: a quarter of a second of CPU on the development machine, so that a worker is in the middle
#: of one while another finishes, and every job has exits and packs to compare.
PIECES = [{'position': [0.10 * math.cos(0.8 * i), 0.10 * math.sin(0.8 * i), 0.0],
           'on_surface': True} for i in range(8)]
BASE = {'duration': 7.0, 'interactions': {'enabled': False},
        'rotation': [[0.0, 0.0], [0.5, 4.0], [1.5, 4.0], [2.0, -4.0], [3.0, -4.0],
                     [3.5, 9.0]],
        'particles': PIECES, 'weigher': {'target': 0.3, 'transport_time': 1.0}}
SWEEP = {'scenario': 'base.yaml',
         'grid': {'model.d': [30.0, 135.0, 225.0, 750.0], 'model.mu_C': [0.7, 0.85]}}


@pytest.fixture(scope='module')
def sweep_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp('sweep')
    (directory / 'base.yaml').write_text(yaml.safe_dump(BASE))
    path = directory / 'sweep.yaml'
    path.write_text(yaml.safe_dump(SWEEP))
    return path


@pytest.fixture(scope='module')
def serial(sweep_file: Path,
           tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[bytes, bytes]]:
    """Run every job's scenario of the sweep with cone-feeder-sim run (once per module)."""
    directory = tmp_path_factory.mktemp('serial')
    files = {}
    for job in load_sweep(sweep_file).jobs:
        (directory / job.name).mkdir()
        scenario = write_job_files(job, directory / job.name)
        events, packs = directory / f'events-{job.name}.csv', directory / f'packs-{job.name}.csv'
        assert main(['run', str(scenario), '--events', str(events), '--packs', str(packs),
                     '--quiet']) == 0
        files[job.name] = (events.read_bytes(), packs.read_bytes())
    assert all(len(events.splitlines()) > 1 and len(packs.splitlines()) > 1
               for events, packs in files.values())  # exits and packs to compare
    return files


def ran_the_jobs_scenarios(sweep_path: Path, out: Path) -> bool:
    """Tell whether each job directory holds the scenario the serial runs ran."""
    return all((out / 'jobs' / job.name / 'scenario.yaml').read_text() == job.scenario
               for job in load_sweep(sweep_path).jobs)


def swept_files(out: Path, names) -> dict[str, tuple[bytes, bytes]]:
    """Return the events and packs CSV of the jobs of a sweep directory."""
    return {name: ((out / 'jobs' / name / 'events.csv').read_bytes(),
                   (out / 'jobs' / name / 'packs.csv').read_bytes()) for name in names}


def results(out: Path) -> dict[str, dict]:
    """Return the finished jobs' result.json of a sweep directory."""
    found = {}
    for path in sorted(out.glob('jobs/*/result.json')):
        found[path.parent.name] = json.loads(path.read_text())
    return found


def wait_for(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        time.sleep(0.05)


@pytest.fixture
def scheduler(tmp_path: Path):
    """Start ``dask scheduler`` and two ``dask worker`` processes; yield (address, workers)."""
    env = {**os.environ, 'NUMBA_NUM_THREADS': '1'}
    info = tmp_path / 'scheduler.json'
    procs = [subprocess.Popen(
        [str(BIN / 'dask'), 'scheduler', '--host', '127.0.0.1', '--port', '0',
         '--no-dashboard', '--scheduler-file', str(info)],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        wait_for(info.exists, START_TIMEOUT, 'the scheduler')
        workers = [subprocess.Popen(
            [str(BIN / 'dask'), 'worker', '--scheduler-file', str(info), '--nthreads', '1',
             '--no-nanny', '--no-dashboard', '--name', f'worker-{i}'],
            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for i in range(2)]
        procs += workers
        address = json.loads(info.read_text())['address']
        with Client(address, timeout='60s') as client:
            client.wait_for_workers(2, timeout=START_TIMEOUT)
        yield address, workers
    finally:
        for proc in procs:
            proc.kill()
            proc.wait()


@pytest.mark.slow
def test_a_killed_worker_leaves_the_sweep_complete_and_identical(
        scheduler, sweep_file: Path, serial: dict, tmp_path: Path) -> None:
    address, workers = scheduler
    out = tmp_path / 'out'
    with Client(address, timeout='60s') as client:
        pids = client.run(os.getpid)
        victim_pid = workers[0].pid
        victim = next(addr for addr, pid in pids.items() if pid == victim_pid)
        survivor = next(addr for addr in pids if addr != victim)
        sweep = subprocess.Popen(
            [str(BIN / 'cone-feeder-sim'), 'sweep', str(sweep_file), '--out', str(out),
             '--scheduler', address], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True)
        try:
            wait_for(lambda: 1 <= len(results(out)) and client.processing([victim])[victim],
                     SWEEP_TIMEOUT, 'a finished job and one in flight on the victim')
            in_flight = client.processing([victim])[victim]
            before = set(results(out))
            workers[0].send_signal(signal.SIGKILL)
            log, _ = sweep.communicate(timeout=SWEEP_TIMEOUT)
        finally:
            sweep.kill()
        assert sweep.returncode == 0, log
        assert len(before) < 8 and in_flight
        assert list(client.run(os.getpid)) == [survivor]
    done = results(out)
    assert sorted(done) == [f'{i:05d}' for i in range(8)]
    assert {r['status'] for r in done.values()} == {'done'}
    assert '8 of 8 jobs done, 0 failed' in log
    # the kernels (the cone's and the weigher's) were loaded when the workers joined
    assert {r['kernel_loads'] for r in done.values()} == {0}
    assert ran_the_jobs_scenarios(sweep_file, out)
    assert swept_files(out, done) == serial


def test_a_job_that_raises_fails_alone(scheduler, sweep_file: Path, tmp_path: Path) -> None:
    address, _ = scheduler
    sweep = load_sweep(sweep_file)
    broken = dataclasses.replace(sweep.jobs[2], scenario='duration: -1.0\n')
    sweep = dataclasses.replace(sweep, jobs=(*sweep.jobs[:2], broken, *sweep.jobs[3:5]))
    lines: list[str] = []
    report = run_sweep(sweep, tmp_path / 'out', scheduler=address, log=lines.append)
    assert (report.done, report.failed, report.ran) == (4, 1, 5)
    done = results(tmp_path / 'out')
    assert done['00002']['status'] == 'failed'
    assert done['00002']['error'].startswith('ScenarioError: ')
    assert done['00002']['error'] == ('ScenarioError: jobs/00002/scenario.yaml: scenario is '
                                      "missing the key 'rotation'")
    assert any(re.search(r'job 00002 failed .*ScenarioError', line) for line in lines)
    with (tmp_path / 'out' / 'summary.csv').open() as stream:
        summary = stream.read()
    assert summary.count('\n') == 6 and ',failed,ScenarioError: ' in summary


def default_sigint() -> None:
    """Let the child see SIGINT even where the test runner's parent ignores it."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
@pytest.mark.slow
def test_an_interrupted_sweep_runs_only_its_missing_jobs(sweep_file: Path, serial: dict,
                                                         tmp_path: Path,
                                                         signum: signal.Signals) -> None:
    out = tmp_path / 'out'
    command = [str(BIN / 'cone-feeder-sim'), 'sweep', str(sweep_file), '--out', str(out),
               '--workers', '1']
    # its own process group, as a command in a terminal: Ctrl-C (SIGINT) reaches the local
    # cluster's worker processes too; SIGTERM (kill) only the command
    first = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                             text=True, start_new_session=True, preexec_fn=default_sigint)
    try:
        wait_for(lambda: len(results(out)) >= 2, SWEEP_TIMEOUT, 'two finished jobs')
        if signum == signal.SIGINT:
            os.killpg(first.pid, signum)
        else:
            first.send_signal(signum)
        log, _ = first.communicate(timeout=SWEEP_TIMEOUT)
    finally:
        first.kill()
    assert first.returncode == 128 + signum, log
    assert f'interrupted by {signum.name}: the finished jobs are in' in log
    assert 'Traceback' not in log
    finished = results(out)
    assert 2 <= len(finished) < 8
    stamps = {name: (out / 'jobs' / name / 'result.json').stat().st_mtime_ns
              for name in finished}
    second = subprocess.run(command, capture_output=True, text=True, timeout=SWEEP_TIMEOUT)
    assert second.returncode == 0, second.stderr
    assert f'{len(finished)} finished before, {8 - len(finished)} to run' in second.stderr
    ran = set(re.findall(r'\] job (\d+) done', second.stderr))
    assert ran == {f'{i:05d}' for i in range(8)} - set(finished)
    assert {name: (out / 'jobs' / name / 'result.json').stat().st_mtime_ns
            for name in finished} == stamps
    done = results(out)
    assert len(done) == 8 and {r['status'] for r in done.values()} == {'done'}
    assert ran_the_jobs_scenarios(sweep_file, out)
    assert swept_files(out, done) == serial
    with (out / 'summary.csv').open() as stream:
        assert stream.read().count('\n') == 9
    assert (out / 'summary.png').stat().st_size > 0


def numba_threads_after_a_reload() -> tuple[int, int]:
    """Return numba's thread pool size before and after it reloads its configuration."""
    import numba
    before = numba.config.NUMBA_NUM_THREADS
    numba.core.config.reload_config()  # what every compile does
    return before, numba.config.NUMBA_NUM_THREADS


def test_the_local_cluster_has_one_single_threaded_worker_per_process() -> None:
    with dask_client(workers=2) as client:
        info = client.scheduler_info()['workers']
        assert [w['nthreads'] for w in info.values()] == [1, 1]
        assert len(set(client.run(os.getpid).values())) == 2
        # the worker's environment says what numba was started with: a compile finds it so
        for before, after in client.run(numba_threads_after_a_reload).values():
            assert before == after


#: A sweep's main module as the console script is one: numba imported at its top, so a
#: spawned worker imports it (as __mp_main__) before the nanny sets the worker's environment.
NUMBA_MAIN = """\
import numba

from cone_feeder_sim.sweep.cluster import dask_client


def compile_now():
    @numba.njit
    def twice(x):
        return 2 * x
    return twice(21)


if __name__ == '__main__':
    with dask_client(workers=1) as client:  # its kernels (and numba's threads) load first
        print('compiled:', client.submit(compile_now).result())
"""


def test_a_worker_compiles_after_its_threads_started(tmp_path: Path) -> None:
    # the first sweep after an install failed once with "Cannot set NUMBA_NUM_THREADS to a
    # different value once the threads have been launched": numba imported with the
    # machine's thread count, the worker's environment then saying another, and a compile
    # (which reloads numba's configuration) after the thread pool had started
    script = tmp_path / 'sweep_main.py'
    script.write_text(NUMBA_MAIN)
    env = {**os.environ, 'NUMBA_NUM_THREADS': '2'}  # not 1, whatever the machine's cores
    done = subprocess.run([sys.executable, str(script)], env=env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=START_TIMEOUT)
    assert done.returncode == 0 and 'compiled: 42' in done.stdout, done.stderr[-3000:]


def test_a_failed_heartbeat_is_one_line_without_traceback() -> None:
    logger = logging.getLogger('distributed.worker.test-heartbeat')
    stream = io.StringIO()
    handler = logging.StreamHandler(stream)
    logger.addHandler(handler)
    logger.addFilter(quiet_heartbeat)
    try:
        try:
            raise OSError('Stream is closed')
        except OSError:
            logger.exception(f'{HEARTBEAT_FAILURE}.')
            logger.exception('Something else.')
    finally:
        logger.removeHandler(handler)
    lines = stream.getvalue().splitlines()
    assert lines[0] == f'{HEARTBEAT_FAILURE}.' and lines[1] == 'Something else.'
    assert lines[2] == 'Traceback (most recent call last):'  # other errors keep theirs
