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
The jobs of a sweep on Dask: a ``LocalCluster`` of this machine's cores, or a scheduler.

Without an address, :func:`dask_client` starts a ``LocalCluster`` with one worker process
per core, each with one thread, and each job runs numba's kernels on that thread
(:func:`~.job.run_job` sets numba's thread count of its thread to one): the jobs, not the
pieces of one job, are what runs in parallel. The workers get no ``NUMBA_NUM_THREADS`` of
their own: a spawned worker imports the command's main module (and numba, at the machine's
core count) before the nanny sets the worker's environment, and numba refuses a later
compile once its thread pool runs at another size than the variable then says ("Cannot set
NUMBA_NUM_THREADS to a different value once the threads have been launched"). With an address
(``tcp://host:port``) it connects to a running scheduler (``dask scheduler`` and ``dask
worker``, dask-jobqueue on SLURM, dask-kubernetes, ``dask ssh``); its workers need
cone_feeder_sim installed, not the sweep's directory, since every job's files come back
to the client. :class:`KernelLoader` loads the compiled kernels once per worker as it
joins. Dask retries the job of a worker that dies on another one (up to
``distributed.scheduler.allowed-failures`` deaths, then the job is recorded as failed).
"""

import asyncio
from collections.abc import Callable, Iterable, Iterator
import concurrent.futures
import contextlib
import logging
import os
import signal
import threading

from distributed import as_completed, Client, LocalCluster
from distributed.diagnostics.plugin import WorkerPlugin

from .job import JobOutcome, load_kernels, run_job
from .spec import Job
from ..errors import SweepError

#: How long to try reaching a scheduler before giving up.
CONNECT_TIMEOUT = '30s'


class KernelLoader(WorkerPlugin):
    """Load (or compile) the cone's and the weigher's kernels on a worker when it joins."""

    name = 'cone-feeder-sim-kernels'

    async def setup(self, worker: object) -> None:
        """Load the kernels beside the worker's event loop (a compile can take a minute)."""
        await asyncio.to_thread(load_kernels)


#: The message a worker logs, with a traceback, when a heartbeat finds no scheduler.
HEARTBEAT_FAILURE = 'Failed to communicate with scheduler during heartbeat'


def quiet_heartbeat(record: logging.LogRecord) -> bool:
    """
    Keep a local worker's failed-heartbeat message without its traceback (a log filter).

    In a LocalCluster the scheduler lives in the sweep command's process: when Ctrl-C closes
    it, a worker's heartbeat can race the shutdown and log an OSError with a traceback (seen
    about once in seven interrupted sweeps). The one-line message stays; every record is
    kept.
    """
    if record.getMessage().startswith(HEARTBEAT_FAILURE):
        record.exc_info = None
        record.exc_text = None
    return True


class IgnoreInterrupt(WorkerPlugin):
    """
    Make a local worker process ignore SIGINT: Ctrl-C is the client's to handle.

    A terminal sends Ctrl-C to the whole process group, the LocalCluster's worker processes
    included; the client then closes the cluster in order (cancelling the jobs), instead of
    every worker dying with a traceback of its own (and a heartbeat that races the
    scheduler's shutdown says so in one line, :func:`quiet_heartbeat`). Only for the workers
    of a LocalCluster.
    """

    name = 'cone-feeder-sim-ignore-interrupt'

    def setup(self, worker: object) -> None:
        """Ignore SIGINT in this process (the worker's event loop runs in its main thread)."""
        logging.getLogger('distributed.worker').addFilter(quiet_heartbeat)
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)


def available_cores() -> int:
    """Return the cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None) -> Iterator[Client]:
    """
    Yield a Dask client: of a new LocalCluster (``workers`` processes), or of ``scheduler``.

    Either way the workers have :class:`KernelLoader`. Closing closes the local cluster.
    """
    with contextlib.ExitStack() as stack:
        if scheduler is None:
            count = workers if workers is not None else available_cores()
            cluster = stack.enter_context(LocalCluster(
                n_workers=count, threads_per_worker=1, processes=True,
                dashboard_address=None, silence_logs=logging.ERROR))
            client = stack.enter_context(Client(cluster))
            client.register_plugin(IgnoreInterrupt())
        else:
            try:
                client = stack.enter_context(Client(scheduler, timeout=CONNECT_TIMEOUT))
            except (OSError, ValueError) as exc:
                raise SweepError(f'cannot reach the Dask scheduler at {scheduler}: '
                                 f'{exc}') from exc
        client.register_plugin(KernelLoader())
        yield client


def run_jobs(client: Client, jobs: Iterable[Job],
             done: Callable[[Job, JobOutcome], None]) -> None:
    """
    Run jobs on the client's cluster; call ``done`` with each outcome as it comes.

    A job whose workers died too often, or whose task failed outside the job (a worker
    without cone_feeder_sim, say), is a failed outcome. Jobs not yet done when this ends
    early (an exception in ``done``, Ctrl-C) are cancelled.
    """
    futures = {client.submit(run_job, job, key=f'cone-feeder-sim-{job.name}-{job.digest[:16]}',
                             retries=0): job for job in jobs}
    try:
        for future in as_completed(futures):
            job = futures.pop(future)
            try:
                outcome = future.result()
            except (Exception, asyncio.CancelledError,  # noqa: B902 - KilledWorker, ...
                    concurrent.futures.CancelledError) as exc:
                outcome = JobOutcome(name=job.name, digest=job.digest, status='failed',
                                     error=_task_error(exc))
            future.release()
            done(job, outcome)
    finally:
        if futures:
            client.cancel(list(futures))


def _task_error(exc: BaseException) -> str:
    if type(exc).__name__ == 'KilledWorker':
        return ('KilledWorker: the workers running it died more often than the scheduler '
                f'allows (its distributed.scheduler.allowed-failures): {exc}')
    return f'{type(exc).__name__}: {exc}'


def cluster_notes(client: Client) -> list[str]:
    """Return what to say about a cluster: its workers, and those that do not fit a sweep."""
    info = client.scheduler_info()
    workers = info.get('workers', {})
    notes = [f'Dask scheduler {info.get("address")}: {len(workers)} workers']
    if not workers:
        notes.append('the scheduler has no workers yet: the jobs wait for them (Ctrl-C to '
                     'stop)')
    threaded = sorted(addr for addr, w in workers.items() if w.get('nthreads', 1) > 1)
    if threaded:
        notes.append(f'warning: {len(threaded)} workers have more than one thread (e.g. '
                     f'{threaded[0]}); start them with --nthreads 1: jobs beside each other '
                     "share one process's CPU time and numba's thread pool")
    return notes
