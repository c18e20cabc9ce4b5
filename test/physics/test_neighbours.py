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


"""The cell-list neighbour search against checking every pair."""

from cone_feeder_sim.physics.neighbours import contact_pairs, contact_pairs_brute
import numpy as np
import pytest


@pytest.mark.parametrize('count, spread, seed', [
    (2, 0.05, 0), (10, 0.05, 1), (300, 0.2, 2), (1000, 0.45, 3), (500, 0.03, 4)])
def test_same_pairs_as_checking_every_pair(count: int, spread: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    x = rng.uniform(-spread, spread, (count, 3))
    reach = rng.uniform(0.01, 0.03, count)
    np.testing.assert_array_equal(contact_pairs(x, reach), contact_pairs_brute(x, reach))


def test_tip_rim_and_far_above() -> None:
    # around the tip (x, y near 0, cells of negative and positive index), at the rim of a
    # 0.45 m cone and a piece a metre up
    x = np.array([[0.0, 0.0, 0.03], [-0.01, 0.002, 0.028], [0.012, -0.03, 0.029],
                  [0.224, 0.0, 0.0], [0.2, 0.01, 0.004], [-0.224, 0.0, 0.001],
                  [0.0, 0.0, 1.0], [0.0, 0.0, 0.97]])
    reach = np.full(len(x), 0.025)
    pairs = contact_pairs(x, reach)
    np.testing.assert_array_equal(pairs, contact_pairs_brute(x, reach))
    assert {(0, 1), (0, 2), (3, 4), (6, 7)} <= {tuple(p) for p in pairs}


@pytest.mark.parametrize('fast', [1, 30, 300])
def test_fast_pieces_with_a_long_reach_find_all_their_pairs(fast: int) -> None:
    # the reach is widened by the distance a piece can move: a few (or many) fast pieces
    # reach much further than the crowd; pairs fast-slow and fast-fast must all be found
    rng = np.random.default_rng(fast)
    x = rng.uniform(-0.2, 0.2, (600, 3))
    reach = np.full(600, 0.025)
    reach[rng.choice(600, fast, replace=False)] = rng.uniform(0.05, 0.3, fast)
    pairs = contact_pairs(x, reach)
    np.testing.assert_array_equal(pairs, contact_pairs_brute(x, reach))
    assert len(pairs) > 600


def test_a_dense_pile_grows_the_buffer() -> None:
    rng = np.random.default_rng(9)
    x = rng.uniform(-0.01, 0.01, (200, 3))  # every pair touches: 19,900 pairs
    pairs = contact_pairs(x, np.full(200, 0.025))
    assert len(pairs) == 200 * 199 // 2
    np.testing.assert_array_equal(pairs, contact_pairs_brute(x, np.full(200, 0.025)))


def test_edge_cases() -> None:
    assert contact_pairs(np.zeros((0, 3)), np.zeros(0)).shape == (0, 2)
    assert contact_pairs(np.zeros((1, 3)), np.ones(1)).shape == (0, 2)
    # exactly at the sum of the reaches: not in contact
    assert contact_pairs(np.array([[0.0, 0, 0], [0.5, 0, 0]]), np.full(2, 0.25)).shape == (0, 2)
    with pytest.raises(ValueError, match='finite'):
        contact_pairs(np.array([[0.0, 0, 0], [np.nan, 0, 0]]), np.ones(2))
    with pytest.raises(ValueError, match='2 pieces'):
        contact_pairs(np.zeros((2, 3)), np.ones(3))
