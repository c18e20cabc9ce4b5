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
Running a sweep: the jobs that are not finished, on Dask, into the sweep's directory.

:func:`run_sweep` opens the directory (:class:`~cone_feeder_sim.sweep.store.SweepStore`:
refused if it holds another sweep), runs the pending jobs on a local cluster or a
scheduler (:mod:`~cone_feeder_sim.sweep.cluster`), saves each job as it comes back and
writes ``summary.csv`` and ``summary.png`` at the end, also when interrupted (Ctrl-C): the
finished jobs are kept and a re-run runs the others.
"""

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from .cluster import cluster_notes, dask_client, run_jobs
from .figure import write_figure
from .job import JobOutcome
from .spec import Job, Sweep
from .store import FIGURE_FILE, SweepStore


@dataclass(frozen=True)
class SweepReport:
    """
    What a sweep run did: jobs in the sweep, finished before, run now, and the totals.

    done and failed count every finished job of the directory (before and now).
    """

    jobs: int
    skipped: int
    ran: int
    done: int
    failed: int
    summary: Path
    figure: Path | None


def run_sweep(sweep: Sweep, out: str | Path, *, scheduler: str | None = None,
              workers: int | None = None, retry_failed: bool = False,
              log: Callable[[str], None] = lambda line: None) -> SweepReport:
    """
    Run the sweep's pending jobs on Dask into ``out``; return what was done.

    scheduler: the address of a Dask scheduler (None: a LocalCluster of ``workers``
    processes, default one per core); retry_failed: run failed jobs again; log: called
    with each line of progress.
    """
    store = SweepStore(out, sweep)
    todo = store.pending(retry_failed)
    log(f'{len(sweep.jobs)} jobs ({", ".join(sweep.keys)} varied): '
        f'{len(sweep.jobs) - len(todo)} finished before, {len(todo)} to run')
    ran = 0

    def save(job: Job, outcome: JobOutcome) -> None:
        nonlocal ran
        store.save(job, outcome)
        ran += 1
        what = (f'{outcome.metrics["exits"]} exits' if outcome.status == 'done'
                else outcome.error)
        log(f'[{ran}/{len(todo)}] job {job.name} {outcome.status} in {outcome.cpu_s:.2f} s '
            f'CPU on {outcome.worker or "?"}: {what}')

    interrupted = True
    try:
        if todo:
            with dask_client(scheduler, workers) as client:
                for note in cluster_notes(client):
                    log(note)
                run_jobs(client, todo, save)
        interrupted = False
    finally:
        summary, rows = store.write_summary()
        figure = None
        if rows and not interrupted:
            figure = write_figure(store.out / FIGURE_FILE, sweep.source or 'sweep',
                                  sweep.keys, rows)
    failed = sum(row['status'] != 'done' for row in rows)
    return SweepReport(jobs=len(sweep.jobs), skipped=len(sweep.jobs) - len(todo), ran=ran,
                       done=len(rows) - failed, failed=failed, summary=summary,
                       figure=figure)
