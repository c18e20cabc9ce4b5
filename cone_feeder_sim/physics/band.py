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

"""
Banded LU with partial pivoting (compiled), for the linear systems of large contact islands.

A contact island's velocity system couples a piece only with the pieces it touches. Put in
an order where touching pieces are close (reverse Cuthill-McKee, :func:`band_order`), the
system is banded, and factoring it costs O(N kl^2) instead of O(N^3).

Storage: a square matrix of order N with kl sub- and kl super-diagonals is held in ``ab``,
shape (N, 3 kl + 1): row r keeps columns r - kl ... r + 2 kl at ``ab[r, c - r + kl]``; the
extra kl columns on the right take the fill-in of the row interchanges. This is LAPACK's
``gbtrf``/``gbtrs`` scheme (interchanges applied to the columns right of the pivot; the
multipliers stay where they were computed), with rows instead of columns as the unit.
"""

import numba
import numpy as np
from scipy.sparse import coo_array
from scipy.sparse.csgraph import reverse_cuthill_mckee

__all__ = ['band_factor', 'band_order', 'band_solve']

jit = numba.njit(cache=True, error_model='numpy', nogil=True)


@jit
def band_factor(ab, piv, kl):
    """
    Factor the banded matrix in ``ab`` (N, 3 kl + 1) in place; piv (N,) receives the rows.

    Returns False when a pivot is zero or not finite (the step is then rejected). With
    kl >= N - 1 this is dense LU with partial pivoting, at the same cost.
    """
    n = ab.shape[0]
    for j in range(n):
        last_row = min(j + kl, n - 1)
        last_col = min(j + 2 * kl, n - 1)
        p = j
        big = abs(ab[j, kl])
        for r in range(j + 1, last_row + 1):
            v = abs(ab[r, j - r + kl])
            if v > big:
                big = v
                p = r
        piv[j] = p
        if not big > 0.0 or not np.isfinite(big):
            return False
        if p != j:
            for c in range(j, last_col + 1):
                tmp = ab[j, c - j + kl]
                ab[j, c - j + kl] = ab[p, c - p + kl]
                ab[p, c - p + kl] = tmp
        inv = 1.0 / ab[j, kl]
        for r in range(j + 1, last_row + 1):
            f = ab[r, j - r + kl] * inv
            ab[r, j - r + kl] = f
            if f != 0.0:
                for c in range(j + 1, last_col + 1):
                    ab[r, c - r + kl] -= f * ab[j, c - j + kl]
    return True


@jit
def band_solve(ab, piv, kl, b):
    """Solve A x = b in place in b (N,) with the factors of :func:`band_factor`."""
    n = ab.shape[0]
    for j in range(n):
        p = piv[j]
        if p != j:
            tmp = b[j]
            b[j] = b[p]
            b[p] = tmp
        bj = b[j]
        if bj != 0.0:
            for r in range(j + 1, min(j + kl, n - 1) + 1):
                b[r] -= ab[r, j - r + kl] * bj
    for j in range(n - 1, -1, -1):
        acc = b[j]
        for c in range(j + 1, min(j + 2 * kl, n - 1) + 1):
            acc -= ab[j, c - j + kl] * b[c]
        b[j] = acc / ab[j, kl]


def band_order(count: int, pairs: np.ndarray) -> tuple[np.ndarray, int]:
    """
    Return an order of ``count`` nodes linked by ``pairs`` (M, 2) that keeps links close.

    Returns (pos, width): pos (count,) int64, the place of each node in the order, and the
    largest |pos_i - pos_j| over the pairs. The reverse Cuthill-McKee order is taken when
    it is narrower than the given order (it is for all but the smallest sets).
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    natural = np.arange(count, dtype=np.int64)
    if not len(pairs):
        return natural, 0
    width = int(np.abs(pairs[:, 0] - pairs[:, 1]).max())
    if count <= 8:
        return natural, width
    ones = np.ones(len(pairs), dtype=np.int8)
    graph = coo_array((ones, (pairs[:, 0], pairs[:, 1])), shape=(count, count)).tocsr()
    order = reverse_cuthill_mckee(graph, symmetric_mode=False)
    pos = np.empty(count, dtype=np.int64)
    pos[order] = natural
    rcm_width = int(np.abs(pos[pairs[:, 0]] - pos[pairs[:, 1]]).max())
    if rcm_width < width:
        return pos, rcm_width
    return natural, width
