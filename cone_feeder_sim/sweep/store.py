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
A sweep's output directory: one folder per job, the sweep's identity, the summary.

Layout of ``DIR``::

    sweep.json               the sweep: source, digest, varied keys, jobs (name, values)
    jobs/00003/scenario.yaml the job's scenario (cone-feeder-sim run reads it as it is)
    jobs/00003/parameters.yaml  the parameter file it names, if any
    jobs/00003/events.csv    its exits (the events CSV of cone-feeder-sim run)
    jobs/00003/packs.csv     its packs, when the scenario has a weigher
    jobs/00003/result.json   its outcome, written last: the job is finished when it exists
    summary.csv              one row per finished job (:func:`summary_columns`)
    summary.png              the summary figure

A directory holds one sweep: opening it for a sweep of another digest is refused, so
results of different sweep files never mix. A job is finished when its ``result.json``
holds its digest; a re-run runs only the others (and, if asked, the failed ones again).
"""

import csv
import io
import json
import math
import os
from pathlib import Path
from typing import Any

from .job import EVENTS_NAME, JobOutcome, METRICS, PACKS_NAME, write_job_files
from .spec import Job, Sweep
from ..errors import SweepError

FORMAT = 'cone_feeder_sim sweep 1'
SWEEP_FILE = 'sweep.json'
RESULT_FILE = 'result.json'
SUMMARY_FILE = 'summary.csv'
FIGURE_FILE = 'summary.png'
JOBS_DIR = 'jobs'


def _json_value(value: Any) -> Any:
    """Return value with non-finite floats as None (JSON has no NaN)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _atomic_write(path: Path, data: bytes) -> None:
    """Write a file completely or not at all (a temporary file renamed over it)."""
    tmp = path.with_name(path.name + '.tmp')
    with tmp.open('wb') as stream:
        stream.write(data)
        stream.flush()
        os.fsync(stream.fileno())
    os.replace(tmp, path)


def _cell(value: Any) -> str:
    if value is None:
        return ''
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ''
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return str(value)


class SweepStore:
    """The output directory of one sweep (created, or reopened to resume)."""

    def __init__(self, out: str | Path, sweep: Sweep) -> None:
        """Open ``out`` for ``sweep``; refuse a directory that holds something else."""
        self.out = Path(out)
        self.sweep = sweep
        manifest = self.out / SWEEP_FILE
        if manifest.exists():
            try:
                held = json.loads(manifest.read_text(encoding='utf-8'))
            except (OSError, ValueError) as exc:
                raise SweepError(f'cannot read {manifest}: {exc}') from exc
            if held.get('digest') != sweep.digest:
                raise SweepError(
                    f'{self.out} holds the results of another sweep ({held.get("source")}, '
                    f'{len(held.get("jobs", []))} jobs); give another --out, or remove it')
        elif self.out.exists() and (not self.out.is_dir() or any(self.out.iterdir())):
            raise SweepError(f'{self.out} exists and is not the directory of a sweep; give '
                             'a new or empty directory to --out')
        try:
            self.out.mkdir(parents=True, exist_ok=True)
            if not manifest.exists():  # first, so that the directory is a sweep's at once
                _atomic_write(manifest, json.dumps({
                    'format': FORMAT, 'source': sweep.source, 'digest': sweep.digest,
                    'keys': list(sweep.keys),
                    'jobs': [{'job': j.name, 'digest': j.digest, 'values': dict(j.values)}
                             for j in sweep.jobs]}, indent=1, default=str).encode())
            (self.out / JOBS_DIR).mkdir(exist_ok=True)
        except OSError as exc:
            raise SweepError(f'cannot write the sweep to {self.out}: {exc}') from exc

    def job_dir(self, job: Job) -> Path:
        """Return the directory of a job's files."""
        return self.out / JOBS_DIR / job.name

    def outcome(self, job: Job) -> dict[str, Any] | None:
        """Return the parsed result.json of a finished job, or None."""
        path = self.job_dir(job) / RESULT_FILE
        try:
            held = json.loads(path.read_text(encoding='utf-8'))
        except (OSError, ValueError):
            return None
        return held if held.get('digest') == job.digest else None

    def pending(self, retry_failed: bool = False) -> list[Job]:
        """Return the jobs still to run: unfinished ones, and failed ones if asked."""
        todo = []
        for job in self.sweep.jobs:
            held = self.outcome(job)
            if held is None or (retry_failed and held['status'] != 'done'):
                todo.append(job)
        return todo

    def save(self, job: Job, outcome: JobOutcome) -> None:
        """Write a job's files, then its result.json (which makes it finished)."""
        directory = self.job_dir(job)
        try:
            directory.mkdir(parents=True, exist_ok=True)
            for stale in (EVENTS_NAME, PACKS_NAME):
                (directory / stale).unlink(missing_ok=True)
            write_job_files(job, directory)
            for name, data in outcome.files.items():
                _atomic_write(directory / name, data)
            result = {
                'job': job.name, 'digest': job.digest, 'status': outcome.status,
                'error': outcome.error, 'traceback': outcome.traceback,
                'metrics': {k: _json_value(v) for k, v in outcome.metrics.items()},
                'files': sorted(outcome.files), 'cpu_s': outcome.cpu_s,
                'wall_s': outcome.wall_s, 'worker': outcome.worker,
                'kernel_loads': outcome.kernel_loads}
            _atomic_write(directory / RESULT_FILE, json.dumps(result, indent=1).encode())
        except OSError as exc:
            raise SweepError(f'cannot write the results of job {job.name} to {directory}: '
                             f'{exc}') from exc

    def rows(self) -> list[dict[str, Any]]:
        """Return one summary row per finished job, in job order."""
        rows = []
        for job in self.sweep.jobs:
            held = self.outcome(job)
            if held is None:
                continue
            files = set(held.get('files', []))
            rel = f'{JOBS_DIR}/{job.name}/'
            row = {'job': job.name, **job.values, 'status': held['status'],
                   'error': held['error'], **held['metrics'], 'cpu_s': held['cpu_s'],
                   'wall_s': held['wall_s'], 'worker': held['worker'],
                   'events': rel + EVENTS_NAME if EVENTS_NAME in files else '',
                   'packs_csv': rel + PACKS_NAME if PACKS_NAME in files else ''}
            rows.append(row)
        return rows

    def write_summary(self) -> tuple[Path, list[dict[str, Any]]]:
        """Write summary.csv from the finished jobs; return its path and the rows."""
        rows = self.rows()
        header = summary_columns(self.sweep.keys, rows)
        text = io.StringIO(newline='')
        writer = csv.writer(text)
        writer.writerow(header)
        writer.writerows([_cell(row.get(column)) for column in header] for row in rows)
        path = self.out / SUMMARY_FILE
        try:
            _atomic_write(path, text.getvalue().encode())
        except OSError as exc:
            raise SweepError(f'cannot write {path}: {exc}') from exc
        return path, rows


def summary_columns(keys: tuple[str, ...], rows: list[dict[str, Any]]) -> list[str]:
    """
    Return the columns of summary.csv.

    ``job``, the varied keys (dotted names), ``status``, ``error``, the metrics of
    :data:`~cone_feeder_sim.sweep.job.METRICS` that some job has (the weigher's only with a
    weigher), ``mass_chNN`` (kg per channel), ``cpu_s``, ``wall_s``, ``worker``, ``events``
    and ``packs_csv`` (the job's files, relative to the sweep directory).
    """
    present = set().union(*(row.keys() for row in rows)) if rows else set()
    always = ('exits', 'failures', 'steps', 'mean_exit_time', 'mass')
    metrics = [m for m in METRICS if m in present or m in always]
    channels = sorted(c for c in present if c.startswith('mass_ch'))
    return ['job', *keys, 'status', 'error', *metrics, *channels, 'cpu_s', 'wall_s',
            'worker', 'events', 'packs_csv']
