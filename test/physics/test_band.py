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

"""Banded LU and the band order, against numpy's dense solve."""

from cone_feeder_sim.physics.band import band_factor, band_order, band_solve
import numpy as np
import pytest


def banded(a: np.ndarray, kl: int) -> np.ndarray:
    """Return the band storage (N, 3 kl + 1) of a square matrix with kl sub-diagonals."""
    n = a.shape[0]
    ab = np.zeros((n, 3 * kl + 1))
    for r in range(n):
        for c in range(max(0, r - kl), min(n, r + kl + 1)):
            ab[r, c - r + kl] = a[r, c]
    return ab


@pytest.mark.parametrize('n, kl', [(1, 0), (5, 1), (30, 4), (60, 11), (12, 11), (12, 30)])
def test_band_solve_equals_the_dense_solve(n: int, kl: int) -> None:
    rng = np.random.default_rng(n + kl)
    for trial in range(20):
        a = rng.normal(size=(n, n))
        if trial % 2:  # small diagonal: the pivots must come from below
            a[np.diag_indices(n)] *= 1e-3
        rows, cols = np.indices((n, n))
        a[np.abs(rows - cols) > kl] = 0.0
        b = rng.normal(size=n)
        ab = banded(a, min(kl, n - 1))
        piv = np.empty(n, dtype=np.int64)
        assert band_factor(ab, piv, min(kl, n - 1))
        x = b.copy()
        band_solve(ab, piv, min(kl, n - 1), x)
        np.testing.assert_allclose(a @ x, b, atol=1e-9 * np.abs(a).max() * np.abs(x).max())


def test_a_singular_band_is_refused() -> None:
    a = np.diag([1.0, 2.0, 0.0, 4.0])
    a[0, 1] = 3.0
    piv = np.empty(4, dtype=np.int64)
    assert not band_factor(banded(a, 1), piv, 1)
    a[2, 2] = np.nan
    assert not band_factor(banded(a, 1), piv, 1)


def test_the_band_order_narrows_a_ring() -> None:
    # a ring of 200 nodes, each linked to the next two, numbered at random
    rng = np.random.default_rng(0)
    label = rng.permutation(200)
    ring = [(k, (k + 1) % 200) for k in range(200)] + [(k, (k + 2) % 200) for k in range(200)]
    pairs = np.sort(np.array([(label[a], label[b]) for a, b in ring]), axis=1)
    pos, width = band_order(200, pairs)
    assert sorted(pos) == list(range(200))
    assert width == np.abs(pos[pairs[:, 0]] - pos[pairs[:, 1]]).max()
    assert width <= 6  # a ring opened at one node: two strands side by side
    assert np.abs(pairs[:, 0] - pairs[:, 1]).max() > 100  # the given numbering was wide


def test_a_small_or_unlinked_set_keeps_its_order() -> None:
    pos, width = band_order(5, np.array([[0, 4], [1, 2]]))
    assert pos.tolist() == [0, 1, 2, 3, 4] and width == 4
    pos, width = band_order(3, np.empty((0, 2), dtype=np.int64))
    assert pos.tolist() == [0, 1, 2] and width == 0
