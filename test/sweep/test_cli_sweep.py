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


"""The command `cone-feeder-sim sweep`: arguments, a missing Dask, a bad sweep, no scheduler."""

import json
from pathlib import Path
import re
import sys

from cone_feeder_sim.cli import main
import pytest

SWEEP = """\
scenario:
  duration: 1.0
  rotation: [[0.0, 1.0]]
  particles: [{position: [0.1, 0.0, 0.0], on_surface: true}]
grid: {model.d: [30.0, 225.0]}
"""


@pytest.fixture
def sweep_file(tmp_path: Path) -> Path:
    path = tmp_path / 'sweep.yaml'
    path.write_text(SWEEP)
    return path


def test_without_dask_it_says_how_to_install_it(
        sweep_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    monkeypatch.setitem(sys.modules, 'distributed', None)  # import distributed fails
    for name in ('cone_feeder_sim.sweep.run', 'cone_feeder_sim.sweep.cluster'):
        monkeypatch.delitem(sys.modules, name, raising=False)  # imported again, and fail
    assert main(['sweep', str(sweep_file), '--out', str(tmp_path / 'out')]) == 2
    assert "pip install 'cone_feeder_sim[sweep]'" in capsys.readouterr().err
    assert not (tmp_path / 'out').exists()


@pytest.mark.parametrize('extra, message', [
    (['--workers', '0'], '--workers must be at least 1'),
    (['--workers', '2', '--scheduler', 'tcp://127.0.0.1:1'], '--workers sets the local'),
])
def test_bad_arguments(sweep_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture,
                       extra: list[str], message: str) -> None:
    assert main(['sweep', str(sweep_file), '--out', str(tmp_path / 'out'), *extra]) == 2
    assert message in capsys.readouterr().err


def test_a_malformed_sweep_fails_before_anything_runs(
        sweep_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    sweep_file.write_text(SWEEP.replace('model.d: [30.0, 225.0]', 'model.d: [30.0, -2.0]'))
    assert main(['sweep', str(sweep_file), '--out', str(tmp_path / 'out')]) == 2
    assert 'model.d = -2.0: ' in capsys.readouterr().err
    assert not (tmp_path / 'out').exists()


def test_an_unreachable_scheduler_is_named(
        sweep_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture,
        monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip('distributed', reason='the optional extra cone_feeder_sim[sweep]')
    from cone_feeder_sim.sweep import cluster
    monkeypatch.setattr(cluster, 'CONNECT_TIMEOUT', '1s')
    assert main(['sweep', str(sweep_file), '--out', str(tmp_path / 'out'),
                 '--scheduler', 'tcp://127.0.0.1:1']) == 2
    assert 'cannot reach the Dask scheduler at tcp://127.0.0.1:1' in capsys.readouterr().err
    assert (tmp_path / 'out' / 'sweep.json').exists()  # nothing ran; a re-run resumes


def test_retry_failed_runs_only_the_failed_jobs_again(sweep_file: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture) -> None:
    pytest.importorskip('distributed')
    out = tmp_path / 'out'
    command = ['sweep', str(sweep_file), '--out', str(out), '--workers', '1']
    assert main(command) == 0
    first = {job: (out / 'jobs' / job / 'events.csv').read_bytes() for job in ('00000', '00001')}
    # what a run whose worker died leaves of a job: its result, failed, and no files
    result = out / 'jobs' / '00001' / 'result.json'
    held = json.loads(result.read_text())
    held.update(status='failed', error='KilledWorker: the workers running it died',
                metrics={})
    result.write_text(json.dumps(held))
    (out / 'jobs' / '00001' / 'events.csv').unlink()
    kept = (out / 'jobs' / '00000' / 'result.json').stat().st_mtime_ns
    capsys.readouterr()
    assert main(command) == 1  # without --retry-failed: nothing runs, the failure stays
    err = capsys.readouterr().err
    assert '2 finished before, 0 to run' in err and 'failed' in err
    assert json.loads(result.read_text())['status'] == 'failed'
    assert main(command + ['--retry-failed']) == 0
    err = capsys.readouterr().err
    assert '1 finished before, 1 to run' in err and re.search(r'\] job 00001 done', err)
    assert json.loads(result.read_text())['status'] == 'done'
    assert (out / 'jobs' / '00001' / 'events.csv').read_bytes() == first['00001']
    assert (out / 'jobs' / '00000' / 'result.json').stat().st_mtime_ns == kept
    assert ',failed,' not in (out / 'summary.csv').read_text()
