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
Neighbour search for piece-piece contact: a hashed cell list, compiled, O(N).

Pieces are binned into cubic cells of edge ``cell``, twice the reach of nine pieces in ten,
so a pair of those lies in the same or an adjacent cell; cells are hashed into a table of
about twice as many buckets as pieces, so the cost does not depend on how far the pieces
are spread (a piece dropped from a metre up costs no more than one at the tip). Buckets
are filled by a counting sort; a query scans the 27 cells around a piece and keeps the
pairs closer than the sum of their reaches. The few pieces with a larger reach (fast ones:
the reach is widened by how far a piece can move in the interval) scan as many cells as
their reach needs, and are checked against each other directly, so one falling piece does
not make every cell large. The pairs come out sorted (i < j, by i,
then j), so whatever sums over them does so in an order that depends on the positions
only.
"""

import math

import numba
import numpy as np

__all__ = ['contact_pairs', 'contact_pairs_brute']

jit = numba.njit(cache=True, error_model='numpy', nogil=True)


@jit
def _cell_hash(ix, iy, iz, mask):
    h = (ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791)
    return h & mask


@jit
def _within(x, reach, p, q):
    """Tell whether pieces p and q are closer than the sum of their reaches."""
    d0 = x[p, 0] - x[q, 0]
    d1 = x[p, 1] - x[q, 1]
    d2 = x[p, 2] - x[q, 2]
    r = reach[p] + reach[q]
    return d0 * d0 + d1 * d1 + d2 * d2 < r * r


@jit
def _append(found, total, p, q):
    if total == found.shape[0]:
        grown = np.empty((2 * total, 2), dtype=np.int64)
        grown[:total] = found
        found = grown
    found[total, 0] = min(p, q)
    found[total, 1] = max(p, q)
    return found, total + 1


@jit
def _contact_pairs(x, reach, cell):
    count = x.shape[0]
    size = 1
    while size < 2 * count:
        size *= 2
    mask = size - 1
    ix = np.empty(count, dtype=np.int64)
    iy = np.empty(count, dtype=np.int64)
    iz = np.empty(count, dtype=np.int64)
    bucket = np.empty(count, dtype=np.int64)
    start = np.zeros(size + 1, dtype=np.int64)
    half = 0.5 * cell
    big = np.empty(count, dtype=np.int64)
    n_big = 0
    for p in range(count):
        ix[p] = math.floor(x[p, 0] / cell)
        iy[p] = math.floor(x[p, 1] / cell)
        iz[p] = math.floor(x[p, 2] / cell)
        bucket[p] = _cell_hash(ix[p], iy[p], iz[p], mask)
        start[bucket[p] + 1] += 1
        if reach[p] > half:
            big[n_big] = p
            n_big += 1
    for b in range(size):
        start[b + 1] += start[b]
    members = np.empty(count, dtype=np.int64)
    fill = start[:-1].copy()
    for p in range(count):  # in index order: members of a bucket stay sorted
        members[fill[bucket[p]]] = p
        fill[bucket[p]] += 1
    found = np.empty((max(8 * count, 16), 2), dtype=np.int64)
    total = 0
    for p in range(count):
        if reach[p] > half:
            continue
        for ax in range(-1, 2):  # two small pieces within reach are in adjacent cells
            for ay in range(-1, 2):
                for az in range(-1, 2):
                    cx, cy, cz = ix[p] + ax, iy[p] + ay, iz[p] + az
                    b = _cell_hash(cx, cy, cz, mask)
                    for k in range(start[b], start[b + 1]):
                        q = members[k]
                        if (q <= p or reach[q] > half or ix[q] != cx or iy[q] != cy
                                or iz[q] != cz):
                            continue
                        if _within(x, reach, p, q):
                            found, total = _append(found, total, p, q)
    for a in range(n_big):  # a large reach scans as many cells as it needs
        p = big[a]
        span = int(math.ceil((reach[p] + half) / cell))
        for ax in range(-span, span + 1):
            for ay in range(-span, span + 1):
                for az in range(-span, span + 1):
                    cx, cy, cz = ix[p] + ax, iy[p] + ay, iz[p] + az
                    b = _cell_hash(cx, cy, cz, mask)
                    for k in range(start[b], start[b + 1]):
                        q = members[k]
                        if reach[q] > half or ix[q] != cx or iy[q] != cy or iz[q] != cz:
                            continue
                        if _within(x, reach, p, q):
                            found, total = _append(found, total, p, q)
        for c in range(a + 1, n_big):  # large with large: all pairs
            if _within(x, reach, p, big[c]):
                found, total = _append(found, total, p, big[c])
    pairs = found[:total]
    order = np.argsort(pairs[:, 0] * count + pairs[:, 1])
    out = np.empty((total, 2), dtype=np.int64)
    for k in range(total):
        out[k] = pairs[order[k]]
    return out


def contact_pairs(x: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """
    Return the pairs of pieces within reach of each other, shape (M, 2) int64.

    x (N, 3) positions (m), reach (N,) contact reach of each piece (m; its outer radius
    s0, widened by how far it can move in the interval). A pair (i, j), i < j, is listed
    when |x_i - x_j| < reach_i + reach_j; rows are sorted by i, then j. Positions must be
    finite.
    """
    x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
    reach = np.ascontiguousarray(reach, dtype=np.float64).reshape(-1)
    if reach.shape[0] != x.shape[0]:
        raise ValueError(f'reach has {reach.shape[0]} values for {x.shape[0]} pieces')
    if x.shape[0] < 2:
        return np.empty((0, 2), dtype=np.int64)
    if not (np.isfinite(x).all() and np.isfinite(reach).all() and (reach > 0.0).all()):
        raise ValueError('positions must be finite and reaches finite and positive')
    # cells fit the bulk (9 pieces in 10); the few fast pieces beyond scan further
    typical = float(np.partition(reach, (9 * (reach.shape[0] - 1)) // 10)[
        (9 * (reach.shape[0] - 1)) // 10])
    return _contact_pairs(x, reach, 2.0 * typical)


def contact_pairs_brute(x: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """Return what :func:`contact_pairs` returns, by checking all pairs (O(N^2); tests)."""
    x = np.asarray(x, dtype=np.float64).reshape(-1, 3)
    reach = np.asarray(reach, dtype=np.float64).reshape(-1)
    i, j = np.triu_indices(x.shape[0], k=1)
    dist2 = ((x[i] - x[j]) ** 2).sum(axis=1)
    keep = dist2 < (reach[i] + reach[j]) ** 2
    return np.column_stack([i[keep], j[keep]]).astype(np.int64)
