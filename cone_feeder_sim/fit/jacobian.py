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
Forward-difference Jacobians whose columns run side by side.

``scipy.optimize.least_squares`` evaluates a finite-difference Jacobian one column after
another. A fit's columns are independent simulations, so :func:`forward_jacobian` hands them
to a ``map`` (a thread pool's: the compiled kernels release the GIL) and takes the steps
scipy takes (:func:`forward_steps`), so a fit gives the same result on any number of
threads.
"""

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

__all__ = ['forward_jacobian', 'forward_steps', 'Mapper']

#: ``map(function, items)``: the builtin, a thread pool's, a Dask client's gathered map.
Mapper = Callable[[Callable[[Any], Any], Iterable[Any]], Iterable[Any]]


def forward_steps(x0: np.ndarray, relative: float, lb: np.ndarray,
                  ub: np.ndarray) -> np.ndarray:
    """
    Return the forward steps (n,) scipy's 2-point scheme takes at ``x0`` (n,).

    h = relative * sign(x0) * max(1, |x0|), rounded to a representable difference, and turned
    back where x0 + h would leave the bounds [lb, ub] while x0 - h does not.
    """
    sign = np.where(x0 >= 0.0, 1.0, -1.0)
    h = relative * sign * np.maximum(1.0, np.abs(x0))
    h = (x0 + h) - x0
    outside = (x0 + h < lb) | (x0 + h > ub)
    back = outside & (x0 - h >= lb) & (x0 - h <= ub)
    return np.where(back, -h, h)


def forward_jacobian(function: Callable[[np.ndarray], np.ndarray], x0: np.ndarray,
                     f0: np.ndarray, steps: np.ndarray, mapper: Mapper = map) -> np.ndarray:
    """
    Return the Jacobian (m, n) of ``function`` at ``x0`` (n,) by forward differences.

    f0 (m,): function(x0); steps (n,): the step of each column. The n evaluations go through
    ``mapper``, in column order.
    """
    points = []
    for j, h in enumerate(steps):
        x = np.array(x0, dtype=float)
        x[j] += h
        points.append(x)
    columns = list(mapper(function, points))
    jac = np.empty((f0.shape[0], len(points)))
    for j, (column, h) in enumerate(zip(columns, steps)):
        jac[:, j] = (np.asarray(column) - f0) / h
    return jac
