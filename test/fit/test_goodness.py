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

"""Tests of the test of fit: chi-square of the whole and of each piece against the noise."""

from pathlib import Path

from cone_feeder_sim.fit.goodness import ALPHA, goodness_of_fit
from cone_feeder_sim.fit.noise import Noise
from cone_feeder_sim.fit.problem import FitProblem
from cone_feeder_sim.fit.solve import fit
from cone_feeder_sim.fit.spec import fit_from_mapping
from cone_feeder_sim.formats.scenario_file import set_scenario_key
import numpy as np
from test_fit import BASE, FREE, write_tracks


def test_residuals_that_are_the_noise_pass_at_the_test_size() -> None:
    rng = np.random.default_rng(0)
    owner = np.repeat(np.arange(5), 200)
    failed = sum(not goodness_of_fit(rng.normal(0.0, 0.001, 1000), owner, Noise(0.001, 'noise'),
                                     2).passed for _ in range(2000))
    # the whole and five pieces, each test at ALPHA (the pieces Bonferroni): a rate of at
    # most 2 ALPHA, 4 expected in 2000; 12 is that rate's 99.99 % binomial quantile
    assert failed <= 12 and 2000 * 2 * ALPHA == 4.0


def test_a_piece_off_by_three_sigma_fails_and_is_named() -> None:
    rng = np.random.default_rng(1)
    owner = np.repeat(np.arange(5), 200)
    residuals = rng.normal(0.0, 0.001, 1000)
    residuals[owner == 3] += 0.003
    test = goodness_of_fit(residuals, owner, Noise(0.001, 'noise'), 2)
    assert not test.passed and test.failing == [3]
    assert test.pieces[3][0] > 3.0 and test.pieces[0][0] < 1.2
    # a noise given ten times too small fails every piece
    small = goodness_of_fit(rng.normal(0.0, 0.001, 1000), owner, Noise(1e-4, 'noise'), 2)
    assert not small.passed and small.failing == [0, 1, 2, 3, 4]


def test_an_estimated_noise_widens_the_threshold_by_its_uncertainty() -> None:
    owner = np.repeat(np.arange(2), 50)
    residuals = np.full(100, 0.00125)  # chi2 / dof = 1.58
    assert not goodness_of_fit(residuals, owner, Noise(0.001, 'noise'), 1).passed
    assert goodness_of_fit(residuals, owner, Noise(0.001, 'tracks', rel_se=0.05), 1).passed


def test_a_wrong_model_fails_the_test_of_fit_and_names_the_pieces(tmp_path: Path) -> None:
    # the tracks come from a cone that reversed 0.3 s earlier than the fit's scenario says
    base = {**BASE, 'duration': 2.5, 'particles': BASE['particles'][:3]}
    earlier = {**base, 'rotation': [[0.0, 0.0], [0.5, -8.0], [1.2, -8.0], [1.7, 6.0]]}
    write_tracks(tmp_path / 'tracks.csv', set_scenario_key(earlier, 'model.d', 315.0), 30.0,
                 0.001, 4, lose_exits=True)
    result = fit(FitProblem(fit_from_mapping(
        {'scenario': base, 'tracks': 'tracks.csv', 'free': FREE, 'starts': 1,
         'processes': 1}, tmp_path)))
    assert not result.success
    test = result.fit_test
    assert test is not None and not test.passed and test.failing
    assert result.warnings[0].startswith('the fit fails its test')
    assert all(f'{p} (rms ' in result.warnings[0] for p in test.failing)
    # no interval is given as tight: low and high are the free range
    assert result.interval.startswith('not estimated: the fit failed its test')
    np.testing.assert_array_equal(result.low, [10.0, 0.3])
    np.testing.assert_array_equal(result.high, [1000.0, 0.98])
