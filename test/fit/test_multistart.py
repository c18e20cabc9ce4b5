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

"""Tests of the starts: the defaults find the valley that one start misses."""

from pathlib import Path

from cone_feeder_sim.fit.multistart import same_minimum, start_points
from cone_feeder_sim.fit.problem import FitProblem
from cone_feeder_sim.fit.solve import fit
from cone_feeder_sim.fit.spec import fit_from_mapping
import numpy as np
import pytest
from test_fit import far_start


def test_the_starts_cut_every_range_into_strata_and_are_seeded() -> None:
    lb, ub = np.array([0.0, -1.0]), np.array([1.0, 1.0])
    points = np.array(start_points(7, lb, ub))
    assert points.shape == (7, 2) and np.all(points >= lb) and np.all(points <= ub)
    for key in range(2):  # one point in each seventh of each range (a Latin hypercube)
        strata = np.floor((points[:, key] - lb[key]) / (ub[key] - lb[key]) * 7)
        assert sorted(strata) == list(range(7))
    np.testing.assert_array_equal(points, start_points(7, lb, ub))
    assert start_points(0, lb, ub) == []


def test_starts_inside_the_best_ones_confidence_region_reached_it() -> None:
    # sigma 1: chi2_2(0.95) = 5.99, so a cost 2.9 above the lowest is the same minimum
    costs = np.array([10.0, 12.9, 13.1, 50.0])
    np.testing.assert_array_equal(same_minimum(costs, 1.0, 2), [True, True, False, False])


@pytest.mark.slow
def test_the_default_starts_find_the_valley_one_start_misses(tmp_path: Path) -> None:
    # three pieces over 2 s, started far off (d = 20, mu_C = 0.95): one start stops in
    # another valley, and the test of fit says so; the defaults (auto starts) find the truth
    content = far_start(tmp_path)
    one = fit(FitProblem(fit_from_mapping({**content, 'starts': 1, 'processes': 1}, tmp_path)))
    assert abs(one.estimate[0] - 315.0) > 50.0 and not one.success
    assert one.warnings[0].startswith('the fit fails its test')
    result = fit(FitProblem(fit_from_mapping(content, tmp_path)))
    assert result.success, result.warnings
    assert len(result.start_costs) >= 8 and result.reached_best >= 3  # auto: 3 at the best
    assert result.start_costs[-1] > result.start_costs[0]  # some starts ended elsewhere
    for value, low, high in zip((315.0, 0.7225), result.low, result.high):
        assert low < value < high
