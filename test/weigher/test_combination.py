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

"""Combination selection against brute force, and its refusals."""

from itertools import combinations
import math

from cone_feeder_sim.errors import ParameterError
from cone_feeder_sim.weigher import MAX_SUBSETS, select_combination, subset_count
import numpy as np
import pytest


def brute(weights, target, max_over=None, min_heads=1, max_heads=None, ages=None):
    """Return the rule's choice by listing every subset (the specification, in Python)."""
    ages = [0.0] * len(weights) if ages is None else list(ages)
    avail = [i for i, w in enumerate(weights) if w > 0.0]
    max_heads = len(weights) if max_heads is None else max_heads
    best = None
    for k in range(min_heads, min(max_heads, len(avail)) + 1):
        for subset in combinations(avail, k):
            total = 0.0
            age = 0.0
            for i in subset:
                total += float(weights[i])
                age += float(ages[i])
            if total < target or (max_over is not None and total > target + max_over):
                continue
            key = (total, -age, subset)
            if best is None or key < best:
                best = key
    return None if best is None else best[2]


def random_case(rng: np.random.Generator) -> dict:
    heads = int(rng.integers(1, 15))
    kind = rng.integers(4)
    if kind == 0:  # continuous weights
        weights = rng.uniform(0.05, 0.3, heads)
    elif kind == 1:  # coarse grid: many exact ties
        weights = rng.integers(1, 6, heads) * 0.05
    elif kind == 2:  # some empty hoppers
        weights = rng.uniform(0.05, 0.3, heads) * (rng.random(heads) > 0.4)
    else:  # equal weights: ties everywhere
        weights = np.full(heads, 0.1)
    case = {'weights': weights.tolist(), 'target': float(rng.uniform(0.0, 1.5))}
    if rng.random() < 0.4:
        case['max_over'] = float(rng.uniform(0.0, 0.1))
    if rng.random() < 0.4:
        case['min_heads'] = int(rng.integers(1, 4))
    if rng.random() < 0.5:
        case['max_heads'] = int(rng.integers(case.get('min_heads', 1), 8))
    if rng.random() < 0.5:
        ages = rng.integers(0, 3, heads).astype(float) if rng.random() < 0.5 else \
            rng.uniform(0.0, 10.0, heads)
        case['ages'] = ages.tolist()
    return case


def test_the_choice_is_that_of_brute_force_on_thousands_of_cases() -> None:
    rng = np.random.default_rng(12)
    outcomes = {'none': 0, 'chosen': 0}
    for _ in range(3000):
        case = random_case(rng)
        weights, target = case.pop('weights'), case.pop('target')
        got = select_combination(weights, target, **case)
        assert got == brute(weights, target, **case), (weights, target, case)
        outcomes['none' if got is None else 'chosen'] += 1
    assert min(outcomes.values()) > 200  # both answers were exercised


def test_hand_cases() -> None:
    w = [0.10, 0.12, 0.15, 0.0, 0.20]
    assert select_combination(w, 0.25) == (0, 2)  # 0.25 exactly
    assert select_combination(w, 0.25, max_heads=1) is None
    assert select_combination(w, 0.25, min_heads=3) == (0, 1, 2)  # 0.37
    assert select_combination(w, 0.30, max_over=0.01) == (0, 4)  # 0.30
    assert select_combination(w, 0.60, max_over=0.01) is None  # 0.57 or 0.67: none fits
    assert select_combination(w, 0.0) == (0,)  # the lightest single hopper
    # a tie on the total goes to the older product, then to the smaller indices
    assert select_combination([0.1, 0.1, 0.1], 0.1) == (0,)
    assert select_combination([0.1, 0.1, 0.1], 0.1, ages=[1.0, 3.0, 3.0]) == (1,)
    assert select_combination([0.0, 0.0], 0.1) is None  # all empty
    assert select_combination([], 0.1) is None


@pytest.mark.parametrize('kwargs, name', [
    ({'weights': [0.1, np.nan], 'target': 0.1}, 'weights'),
    ({'weights': [0.1, -0.2], 'target': 0.1}, 'weights'),
    ({'weights': [[0.1]], 'target': 0.1}, 'weights'),
    ({'weights': ['a'], 'target': 0.1}, 'weights'),
    ({'weights': [0.1], 'target': math.inf}, 'target'),
    ({'weights': [0.1], 'target': -1.0}, 'target'),
    ({'weights': [0.1], 'target': '1'}, 'target'),
    ({'weights': [0.1], 'target': 0.1, 'max_over': -0.1}, 'max_over'),
    ({'weights': [0.1], 'target': 0.1, 'max_over': math.nan}, 'max_over'),
    ({'weights': [0.1], 'target': 0.1, 'min_heads': 0}, 'min_heads'),
    ({'weights': [0.1], 'target': 0.1, 'max_heads': 2.5}, 'max_heads'),
    ({'weights': [0.1], 'target': 0.1, 'min_heads': 3, 'max_heads': 2}, 'max_heads'),
    ({'weights': [0.1], 'target': 0.1, 'ages': [math.inf]}, 'ages'),
    ({'weights': [0.1], 'target': 0.1, 'ages': [-1.0]}, 'ages'),
    ({'weights': [0.1], 'target': 0.1, 'ages': [1.0, 2.0]}, 'ages'),
])
def test_bad_input_is_refused_naming_the_argument(kwargs: dict, name: str) -> None:
    weights, target = kwargs.pop('weights'), kwargs.pop('target')
    with pytest.raises(ParameterError, match=name):
        select_combination(weights, target, **kwargs)


def test_large_machines_are_exact_within_a_head_limit() -> None:
    # 32 heads, at most 4 per pack: 41,448 subsets, against brute force
    rng = np.random.default_rng(3)
    for _ in range(3):
        weights = rng.uniform(0.05, 0.3, 32).tolist()
        got = select_combination(weights, 0.7, max_heads=4)
        assert got == brute(weights, 0.7, max_heads=4)
    assert subset_count(32, 1, 6) < MAX_SUBSETS < subset_count(32, 1, 32)
    with pytest.raises(ParameterError, match='max_heads'):
        select_combination([0.1] * 32, 0.5)
