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

"""Tests of the profile-likelihood intervals: where they cross, and keys the data miss."""

from pathlib import Path

from cone_feeder_sim.fit.problem import FitProblem
from cone_feeder_sim.fit.profiles import DELTA_CHI2
from cone_feeder_sim.fit.solve import fit
from cone_feeder_sim.fit.spec import fit_from_mapping
from cone_feeder_sim.formats.scenario_file import set_scenario_key
import numpy as np
import pytest
from test_fit import BASE, FREE, write_tracks

SHORT = {**BASE, 'duration': 1.5, 'particles': BASE['particles'][:3]}


def test_a_nearly_linear_key_has_the_interval_of_its_standard_error(tmp_path: Path) -> None:
    write_tracks(tmp_path / 'tracks.csv', set_scenario_key(SHORT, 'model.d', 315.0), 30.0,
                 0.001, 11)
    result = fit(FitProblem(fit_from_mapping(
        {'scenario': SHORT, 'tracks': 'tracks.csv', 'free': {'model.d': [10.0, 1000.0]},
         'starts': 1, 'processes': 1, 'noise': 0.001}, tmp_path)))
    assert result.success, result.warnings
    profile = result.profiles['model.d']
    values, delta = np.array(profile['values']), np.array(profile['delta_chi2'])
    # the profile is the cost: zero at the estimate, rising on both sides
    assert delta[values == result.estimate[0]] == 0.0
    assert np.all(np.diff(delta[values >= result.estimate[0]]) > 0.0)
    assert np.all(np.diff(delta[values <= result.estimate[0]]) < 0.0)
    # the interval's ends lie where the profile crosses chi2_1(0.95), read off its points
    for end in (result.low[0], result.high[0]):
        assert np.interp(end, values, delta) == pytest.approx(DELTA_CHI2, rel=0.1)
    # one key, noise given and fitted: the half widths are 1.96 sigma (from sigma, not s)
    s = np.sqrt(2.0 * result.cost / (result.fit_test.dof + 1))
    half = 1.96 * result.stderr[0] * 0.001 / s
    assert result.high[0] - result.estimate[0] == pytest.approx(half, rel=0.1)
    assert result.estimate[0] - result.low[0] == pytest.approx(half, rel=0.1)


def test_a_key_that_does_not_change_the_tracks_is_not_identifiable(tmp_path: Path) -> None:
    # the Young's modulus acts only where pieces touch: here they never do (contact off)
    write_tracks(tmp_path / 'tracks.csv', set_scenario_key(SHORT, 'model.d', 315.0), 30.0,
                 0.001, 12)
    result = fit(FitProblem(fit_from_mapping(
        {'scenario': SHORT, 'tracks': 'tracks.csv', 'starts': 1, 'processes': 1,
         'free': {'model.d': [10.0, 1000.0], 'model.young_modulus': [1.0e4, 1.0e5]}},
        tmp_path)))
    assert result.flat['model.young_modulus'] == (True, True)
    assert (result.low[1], result.high[1]) == pytest.approx((1.0e4, 1.0e5))
    assert result.flat['model.d'] == (False, False)
    assert result.low[0] < 315.0 < result.high[0]
    named = [w for w in result.warnings if w.startswith('model.young_modulus: its profile')]
    assert len(named) == 2 and 'not identifiable' in named[0]
    mapping = result.as_mapping()['parameters']
    assert mapping['model.young_modulus']['identifiable'] == {'low': False, 'high': False}


@pytest.mark.slow
def test_the_95_percent_intervals_cover_the_truth_over_20_seeds(tmp_path: Path) -> None:
    # noisy tracks of the same truth, 20 noise seeds: about 19 intervals of 20 should cover
    base = {**BASE, 'duration': 1.0, 'particles': BASE['particles'][:3]}
    truth_values = np.array([315.0, 0.7225])
    truth = set_scenario_key(set_scenario_key(base, 'model.d', 315.0), 'model.mu_C', 0.7225)
    covered = np.zeros(2, dtype=int)
    for seed in range(20):
        folder = tmp_path / str(seed)
        folder.mkdir()
        write_tracks(folder / 'tracks.csv', truth, 15.0, 0.001, 100 + seed)
        result = fit(FitProblem(fit_from_mapping(
            {'scenario': base, 'tracks': 'tracks.csv', 'free': FREE, 'starts': 1,
             'processes': 1, 'noise': 0.001}, folder)))
        assert result.success and result.interval.startswith('profile likelihood')
        covered += (result.low < truth_values) & (truth_values < result.high)
    assert all(18 <= c <= 20 for c in covered), covered
