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
"""Detections to pieces: the gate and the optimal assignment, against brute force."""

from itertools import permutations

from cone_feeder_sim.twin.association import associate, GATE_CHI2
import numpy as np
import pytest
from scipy.stats import chi2

SIGMA = 0.002  # m


def covariances(n: int) -> np.ndarray:
    """Return n position covariances of SIGMA in x and y (m^2)."""
    return np.tile(np.eye(2) * SIGMA ** 2, (n, 1, 1))


def test_shuffled_detections_come_back_to_their_pieces() -> None:
    rng = np.random.default_rng(0)
    pieces = rng.uniform(-0.2, 0.2, (12, 2))
    order = rng.permutation(12)
    detections = pieces[order] + rng.normal(0.0, SIGMA / 4, (12, 2))
    result = associate(pieces, covariances(12), detections)
    assert len(result.pairs) == 12 and not result.missed.size and not result.unassigned.size
    np.testing.assert_array_equal(order[result.pairs[:, 1]], result.pairs[:, 0])


def test_a_missed_piece_and_a_false_detection_are_left_over() -> None:
    pieces = np.array([[0.0, 0.0], [0.05, 0.0], [0.10, 0.0]])
    detections = np.array([[0.1001, 0.0], [0.0, 0.0002], [-0.15, 0.1]])  # piece 1 missed
    result = associate(pieces, covariances(3), detections)
    assert sorted(map(tuple, result.pairs.tolist())) == [(0, 1), (2, 0)]
    assert result.missed.tolist() == [1] and result.unassigned.tolist() == [2]


def test_the_assignment_is_the_least_total_distance_not_the_greedy_one() -> None:
    # greedy nearest-first would give detection 0 to piece 1 (0.4) and detection 1 to
    # piece 0 (1.7): 3.05 in all; the optimum gives 0.6 -> 0 and 1.7 -> 1: 0.85
    pieces = np.array([[0.0, 0.0], [1.0, 0.0]])
    detections = np.array([[0.6, 0.0], [1.7, 0.0]])
    result = associate(pieces, np.tile(np.eye(2), (2, 1, 1)), detections)
    assert sorted(map(tuple, result.pairs.tolist())) == [(0, 0), (1, 1)]
    assert np.isclose(result.distance.sum(), 0.85)


def test_random_cases_match_brute_force() -> None:
    rng = np.random.default_rng(1)
    for _ in range(50):
        n = int(rng.integers(1, 6))
        pieces = rng.uniform(0.0, 0.01, (n, 2))
        detections = rng.uniform(0.0, 0.01, (n, 2))
        cov = np.array([np.diag(rng.uniform(1.0, 4.0, 2)) * 1e-6 for _ in range(n)])
        result = associate(pieces, cov, detections, gate=np.inf)
        inverse = np.linalg.inv(cov)
        d = np.array([[(detections[k] - pieces[i]) @ inverse[i] @ (detections[k] - pieces[i])
                       for k in range(n)] for i in range(n)])
        best = min(sum(d[i, p[i]] for i in range(n)) for p in permutations(range(n)))
        assert len(result.pairs) == n
        assert np.isclose(result.distance.sum(), best)
        np.testing.assert_allclose(result.distance, d[result.pairs[:, 0], result.pairs[:, 1]])


def test_the_gate_is_the_chi_square_quantile() -> None:
    # the closed form is scipy's quantile; a detection just inside the gate is assigned,
    # one just outside is not
    assert GATE_CHI2 == pytest.approx(chi2.ppf(0.999, 2), rel=1e-14)
    pieces = np.array([[0.0, 0.0]])
    for scale, assigned in ((0.999, True), (1.001, False)):
        detection = np.array([[np.sqrt(scale * GATE_CHI2) * SIGMA, 0.0]])
        result = associate(pieces, covariances(1), detection)
        assert (len(result.pairs) == 1) is assigned
        assert result.missed.size == (0 if assigned else 1)


def test_nothing_to_assign() -> None:
    result = associate(np.empty((0, 2)), np.empty((0, 2, 2)), np.zeros((3, 2)))
    assert result.pairs.shape == (0, 2) and result.unassigned.tolist() == [0, 1, 2]
    result = associate(np.zeros((2, 2)), covariances(2), np.empty((0, 2)))
    assert result.missed.tolist() == [0, 1] and not result.unassigned.size
