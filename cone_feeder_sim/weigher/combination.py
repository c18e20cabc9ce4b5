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
Combination selection of a multihead weigher: which weigh hoppers go into the next pack.

:func:`select_combination` enumerates every subset of the available hoppers with an
allowed number of heads, exactly (compiled): for 14 heads that is 16,383 subsets, for the
common 10-16 heads at most 65,535. Larger machines (24-32 heads) are enumerated exactly
too as long as ``max_heads`` keeps the count of subsets within
:data:`MAX_SUBSETS` (32 heads, at most 6 heads per pack: 1.2 million subsets); beyond that
the call is refused with a message that says so, rather than answered approximately.
"""

from collections.abc import Sequence
import math
from typing import Any

import numba
import numpy as np

from ..errors import ParameterError

__all__ = ['MAX_SUBSETS', 'select_combination', 'subset_count']

#: Most subsets one call enumerates (about 0.2 s compiled).
MAX_SUBSETS = 1 << 24

jit = numba.njit(cache=True, error_model='numpy', nogil=True)


@jit
def _better(total, age, idx, k, best_total, best_age, best, best_k):
    """Tell whether subset idx[:k] beats best[:best_k] by the rule of select_combination."""
    if best_k == 0:
        return True
    if total != best_total:
        return total < best_total
    if age != best_age:
        return age > best_age
    for m in range(min(k, best_k)):
        if idx[m] != best[m]:
            return idx[m] < best[m]
    return k < best_k


@jit
def _select(weights, ages, avail, target, upper, k_min, k_max):
    """Return (chosen count, chosen indices) over subsets of ``avail``; count 0 = none."""
    n = avail.shape[0]
    best = np.zeros(max(k_max, 1), dtype=np.int64)
    best_k = 0
    best_total = 0.0
    best_age = 0.0
    pick = np.zeros(max(k_max, 1), dtype=np.int64)  # positions into avail
    idx = np.zeros(max(k_max, 1), dtype=np.int64)
    for k in range(k_min, k_max + 1):
        for m in range(k):
            pick[m] = m
        while True:
            total = 0.0
            age = 0.0
            for m in range(k):  # summed in ascending index order: one value per subset
                idx[m] = avail[pick[m]]
                total += weights[idx[m]]
                age += ages[idx[m]]
            if total >= target and total <= upper:
                if _better(total, age, idx, k, best_total, best_age, best, best_k):
                    best_total = total
                    best_age = age
                    best_k = k
                    for m in range(k):
                        best[m] = idx[m]
            # next k-combination in lexicographic order
            m = k - 1
            while m >= 0 and pick[m] == n - k + m:
                m -= 1
            if m < 0:
                break
            pick[m] += 1
            for r in range(m + 1, k):
                pick[r] = pick[r - 1] + 1
    return best_k, best


def subset_count(heads: int, min_heads: int, max_heads: int) -> int:
    """Return how many subsets of ``heads`` hoppers have min_heads..max_heads heads."""
    return sum(math.comb(heads, k) for k in range(min_heads, min(max_heads, heads) + 1))


def _array(name: str, values: Any) -> np.ndarray:
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f'{name} must be a sequence of numbers: {exc}') from None
    if array.ndim != 1:
        raise ParameterError(f'{name} must be one-dimensional, got shape {array.shape}')
    if not np.isfinite(array).all():
        raise ParameterError(f'{name} must be finite, got {array.tolist()}')
    if (array < 0.0).any():
        raise ParameterError(f'{name} must not be negative, got {array.tolist()}')
    return array


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ParameterError(f'{name} must be a number, got {type(value).__name__} {value!r}')
    number = float(value)
    if not math.isfinite(number) or number < 0.0:
        raise ParameterError(f'{name} must be finite and not negative, got {number!r}')
    return number


def _count(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ParameterError(f'{name} must be an integer >= 1, got {value!r}')
    return int(value)


def select_combination(weights: Sequence[float], target: float, *,
                       max_over: float | None = None, min_heads: int = 1,
                       max_heads: int | None = None,
                       ages: Sequence[float] | None = None) -> tuple[int, ...] | None:
    """
    Return the weigh hoppers to discharge into one pack, or None when no subset will do.

    weights (H,) kg, the weigh hoppers' weights (<= 0: empty, not available); target
    (kg) the pack's target weight. Among the subsets of available hoppers with a total
    >= target (and <= target + max_over when given) and min_heads <= heads <= max_heads,
    the smallest total wins; ties go to the subset with the oldest product (the largest
    summed ``ages``, (H,) s, default all 0), then to the lexicographically smallest index
    tuple. Totals are summed in ascending index order, so equal subsets compare equal.
    Returns the chosen indices, ascending. Non-finite or negative inputs raise
    :class:`ParameterError` naming the argument; so does a machine whose subsets would
    exceed :data:`MAX_SUBSETS` (lower max_heads).
    """
    w = _array('weights', weights)
    target = _number('target', target)
    upper = math.inf if max_over is None else target + _number('max_over', max_over)
    min_heads = _count('min_heads', min_heads)
    max_heads = (max(w.shape[0], min_heads) if max_heads is None
                 else _count('max_heads', max_heads))
    if max_heads < min_heads:
        raise ParameterError(f'max_heads ({max_heads}) must not be below min_heads '
                             f'({min_heads})')
    if ages is None:
        a = np.zeros_like(w)
    else:
        a = _array('ages', ages)
        if a.shape != w.shape:
            raise ParameterError(f'ages has {a.shape[0]} values for {w.shape[0]} weights')
    avail = np.flatnonzero(w > 0.0).astype(np.int64)
    k_max = min(max_heads, avail.shape[0])
    if k_max < min_heads:
        return None
    count = subset_count(avail.shape[0], min_heads, k_max)
    if count > MAX_SUBSETS:
        raise ParameterError(
            f'max_heads: {avail.shape[0]} available hoppers with {min_heads}..{k_max} heads '
            f'are {count:,} subsets, more than {MAX_SUBSETS:,} (MAX_SUBSETS); lower '
            'max_heads')
    k, best = _select(w, a, avail, target, upper, min_heads, k_max)
    if k == 0:
        return None
    return tuple(int(i) for i in best[:k])


def warm_up() -> None:
    """Compile (or load from numba's cache) the selection kernel now, not inside a tick."""
    select_combination([0.2, 0.3, 0.25], 0.45)
