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


"""Tests of one sweep job: the same files as cone-feeder-sim run, metrics, failures."""

import csv
import dataclasses
import io
from pathlib import Path

from cone_feeder_sim.cli import main
from cone_feeder_sim.sweep import job as job_module
from cone_feeder_sim.sweep.job import run_job, write_job_files
from cone_feeder_sim.sweep.spec import sweep_from_mapping
import numpy as np
import pytest

BASE = {
    'duration': 6.0,
    'rotation': [[0.0, 0.0], [0.4, -10.47]],
    'particles': [{'position': [0.11, -0.01, 0.03], 'd': 225.0},
                  {'position': [0.14, 0.06, 0.03], 'd': 30.0},
                  {'position': [0.02, 0.0, 0.0], 'on_surface': True},
                  {'position': [-0.08, 0.05, 0.0], 'on_surface': True, 'm': 0.2}],
    'weigher': {'target': 0.2, 'transport_time': 1.0, 'load_cell_noise': 0.001},
}


@pytest.fixture(scope='module')
def jobs(tmp_path_factory: pytest.TempPathFactory):
    tmp = tmp_path_factory.mktemp('sweep')
    return sweep_from_mapping({'scenario': BASE, 'grid': {'rotation.1.1': [-10.47, 12.0]},
                               'seeds': [3]}, tmp).jobs


def test_a_job_writes_what_cone_feeder_sim_run_writes(jobs, tmp_path: Path) -> None:
    for job in jobs:
        outcome = run_job(job)
        assert outcome.status == 'done', outcome.error
        directory = tmp_path / job.name
        directory.mkdir()
        scenario = write_job_files(job, directory)
        events, packs = directory / 'events.csv', directory / 'packs.csv'
        assert main(['run', str(scenario), '--events', str(events), '--packs', str(packs),
                     '--quiet']) == 0
        assert outcome.files == {'events.csv': events.read_bytes(),
                                 'packs.csv': packs.read_bytes()}
        assert outcome.files['packs.csv'].count(b'\n') > 1  # some packs were made


def test_metrics_agree_with_the_events(jobs) -> None:
    outcome = run_job(jobs[0])
    rows = list(csv.DictReader(io.StringIO(outcome.files['events.csv'].decode())))
    metrics = outcome.metrics
    assert metrics['exits'] == len(rows) and metrics['exits'] + metrics['remaining'] == 4
    assert metrics['mean_exit_time'] == pytest.approx(np.mean([float(r['t']) for r in rows]))
    for channel in range(1, 15):
        expected = sum(float(r['mass']) for r in rows if int(r['channel']) == channel)
        assert metrics[f'mass_ch{channel:02d}'] == pytest.approx(expected)
    assert metrics['mass'] == pytest.approx(sum(float(r['mass']) for r in rows))
    assert metrics['steps'] > 0 and metrics['failures'] == 0
    assert metrics['end_time'] == 6.0  # with a weigher the run goes on to the duration
    assert metrics['packs'] == outcome.files['packs.csv'].count(b'\n') - 1
    assert outcome.cpu_s > 0 and outcome.wall_s > 0 and outcome.worker


def test_a_job_that_raises_is_a_failed_outcome(jobs, monkeypatch: pytest.MonkeyPatch) -> None:
    broken = dataclasses.replace(jobs[0], scenario='duration: 1.0\nparticles: []\n')
    outcome = run_job(broken)
    assert outcome.status == 'failed' and outcome.files == {}
    assert outcome.error == ('ScenarioError: jobs/00000/scenario.yaml: scenario is missing '
                             "the key 'rotation'")

    def boom(*args: object, **kwargs: object) -> None:
        raise RuntimeError('the disk is on fire')

    monkeypatch.setattr(job_module, 'run_to_files', boom)
    outcome = run_job(jobs[0])
    assert outcome.status == 'failed'
    assert outcome.error == 'RuntimeError: the disk is on fire'
    assert 'boom' in outcome.traceback


def test_a_job_leaves_the_thread_count_of_its_thread(jobs) -> None:
    import numba
    before = numba.get_num_threads()
    run_job(jobs[0])
    assert numba.get_num_threads() == before
