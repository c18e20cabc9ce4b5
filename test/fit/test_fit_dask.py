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

"""A fit's simulations on a Dask cluster give the same fit as in this process."""

from pathlib import Path

from cone_feeder_sim.cli import main
from cone_feeder_sim.fit.problem import FitProblem
from cone_feeder_sim.fit.solve import dask_mapper, fit
from cone_feeder_sim.fit.spec import fit_from_mapping
from cone_feeder_sim.formats.scenario_file import set_scenario_key
from cone_feeder_sim.sweep.cluster import dask_client
from distributed import LocalCluster
import numpy as np
import pytest
from test_fit import BASE, FREE, write_tracks
import yaml


@pytest.mark.slow
def test_a_fit_on_a_dask_cluster_is_the_fit_here(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture) -> None:
    base = {**BASE, 'duration': 0.6, 'particles': BASE['particles'][:3]}
    truth = set_scenario_key(set_scenario_key(base, 'model.d', 315.0), 'model.mu_C', 0.7225)
    write_tracks(tmp_path / 'tracks.csv', truth, 30.0, 0.001, 7, lose_exits=True)
    # the starts and the profiles' sides are the cluster's jobs too
    fits = [{'scenario': base, 'tracks': 'tracks.csv', 'free': FREE, 'method': 'global',
             'global': {'popsize': 3, 'maxiter': 2}, 'starts': 2, 'processes': 1},
            {'scenario': base, 'tracks': 'tracks.csv', 'free': FREE, 'segments': 0.3,
             'starts': 1, 'processes': 1, 'profiles': False}]
    here = [fit(FitProblem(fit_from_mapping(content, tmp_path))) for content in fits]
    (tmp_path / 'fit.yaml').write_text(yaml.safe_dump(fits[0]))
    with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster:
        with dask_client(cluster.scheduler_address) as client:
            there = [fit(FitProblem(fit_from_mapping(content, tmp_path)),
                         dask_mapper(client)) for content in fits]
        # the command, on the scheduler given by its address
        assert main(['fit', str(tmp_path / 'fit.yaml'), '--out', str(tmp_path / 'r.yaml'),
                     '--scheduler', cluster.scheduler_address]) == 0
    for a, b in zip(here, there):
        np.testing.assert_array_equal(a.estimate, b.estimate)
        np.testing.assert_array_equal(a.low, b.low)
        np.testing.assert_array_equal(a.high, b.high)
        assert a.simulations == b.simulations and a.window_simulations == b.window_simulations
    result = yaml.safe_load((tmp_path / 'r.yaml').read_text())
    assert result['parameters']['model.d']['estimate'] == here[0].estimate[0]
    assert 'simulations' in capsys.readouterr().err


@pytest.mark.parametrize('flags, fragment', [
    (['--workers', '2', '--scheduler', 'tcp://127.0.0.1:1'], '--workers sets the local cluster'),
    (['--workers', '0'], '--workers must be at least 1'),
])
def test_a_cluster_is_asked_for_once(tmp_path: Path, capsys: pytest.CaptureFixture,
                                     flags: list, fragment: str) -> None:
    assert main(['fit', str(tmp_path / 'fit.yaml'), '--out', str(tmp_path / 'r.yaml'),
                 *flags]) != 0
    assert fragment in capsys.readouterr().err
