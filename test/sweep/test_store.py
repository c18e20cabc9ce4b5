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


"""Tests of a sweep's directory: job files, resume, one sweep per directory, the summary."""

import csv
import json
from pathlib import Path

from cone_feeder_sim.errors import SweepError
from cone_feeder_sim.sweep.figure import write_figure
from cone_feeder_sim.sweep.job import JobOutcome
from cone_feeder_sim.sweep.spec import sweep_from_mapping
from cone_feeder_sim.sweep.store import SweepStore
import pytest

BASE = {'duration': 1.0, 'rotation': [[0.0, 1.0]],
        'particles': [{'position': [0.11, -0.01, 0.0], 'on_surface': True}]}


def make_sweep(tmp_path: Path, values: list[float]):
    return sweep_from_mapping({'scenario': BASE, 'grid': {'model.d': values}}, tmp_path,
                              'sweep.yaml')


def outcome(job, status: str = 'done') -> JobOutcome:
    if status != 'done':
        return JobOutcome(name=job.name, digest=job.digest, status=status,
                          error='RuntimeError: no', cpu_s=0.5, worker='w:2')
    return JobOutcome(name=job.name, digest=job.digest, status='done',
                      metrics={'exits': 1, 'mean_exit_time': float('nan'), 'mass': 0.125,
                               'mass_ch01': 0.125, 'mass_ch02': 0.0, 'failures': 0,
                               'steps': 10},
                      files={'events.csv': b'particle,t\n0,0.5\n'}, cpu_s=1.5, worker='w:1')


def test_finished_jobs_are_skipped_and_the_summary_has_one_row_each(tmp_path: Path) -> None:
    sweep = make_sweep(tmp_path, [30.0, 225.0, 750.0])
    store = SweepStore(tmp_path / 'out', sweep)
    assert store.pending() == list(sweep.jobs)
    store.save(sweep.jobs[0], outcome(sweep.jobs[0]))
    store.save(sweep.jobs[2], outcome(sweep.jobs[2], 'failed'))
    reopened = SweepStore(tmp_path / 'out', make_sweep(tmp_path, [30.0, 225.0, 750.0]))
    assert [j.name for j in reopened.pending()] == ['00001']
    assert [j.name for j in reopened.pending(retry_failed=True)] == ['00001', '00002']
    path, rows = reopened.write_summary()
    with path.open() as stream:
        table = list(csv.DictReader(stream))
    assert [r['job'] for r in table] == ['00000', '00002']
    assert list(table[0])[:4] == ['job', 'model.d', 'status', 'error']
    for column in ('exits', 'cpu_s', 'events', 'mean_exit_time', 'failures', 'steps',
                   'mass_ch01', 'mass_ch02'):
        assert column in table[0]
    expected = {'model.d': '30.0', 'status': 'done', 'error': '', 'exits': '1',
                'mean_exit_time': '', 'cpu_s': '1.5', 'events': 'jobs/00000/events.csv'}
    assert {key: table[0][key] for key in expected} == expected
    assert (tmp_path / 'out' / table[0]['events']).read_bytes() == b'particle,t\n0,0.5\n'
    assert table[1]['status'] == 'failed' and table[1]['error'] == 'RuntimeError: no'
    assert table[1]['events'] == ''
    job_dir = tmp_path / 'out' / 'jobs' / '00000'
    assert (job_dir / 'scenario.yaml').read_text() == sweep.jobs[0].scenario
    write_figure(tmp_path / 'out' / 'summary.png', 'test', sweep.keys, rows)
    assert (tmp_path / 'out' / 'summary.png').read_bytes()[:4] == b'\x89PNG'


def test_a_directory_holds_one_sweep(tmp_path: Path) -> None:
    SweepStore(tmp_path / 'out', make_sweep(tmp_path, [30.0]))
    with pytest.raises(SweepError, match='holds the results of another sweep'):
        SweepStore(tmp_path / 'out', make_sweep(tmp_path, [31.0]))
    (tmp_path / 'busy').mkdir()
    (tmp_path / 'busy' / 'thesis.tex').write_text('x')
    with pytest.raises(SweepError, match='is not the directory of a sweep'):
        SweepStore(tmp_path / 'busy', make_sweep(tmp_path, [30.0]))
    SweepStore(tmp_path / 'empty', make_sweep(tmp_path, [30.0]))  # new and empty: fine


def test_a_result_of_another_job_content_is_not_finished(tmp_path: Path) -> None:
    sweep = make_sweep(tmp_path, [30.0])
    store = SweepStore(tmp_path / 'out', sweep)
    store.save(sweep.jobs[0], outcome(sweep.jobs[0]))
    result = tmp_path / 'out' / 'jobs' / '00000' / 'result.json'
    held = json.loads(result.read_text())
    result.write_text(json.dumps({**held, 'digest': 'f' * 64}))
    assert store.pending() == list(sweep.jobs)
    result.write_text('{"job": "00000", "dig')  # torn (cannot happen: written atomically)
    assert store.pending() == list(sweep.jobs)
