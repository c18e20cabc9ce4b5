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

"""Tests of the forward differences: scipy's steps, exact on a linear map, any map."""

from concurrent.futures import ThreadPoolExecutor

from cone_feeder_sim.fit.jacobian import forward_jacobian, forward_steps
import numpy as np
from scipy.optimize import approx_fprime


def test_the_steps_are_scipys_and_turn_back_at_a_bound() -> None:
    x0 = np.array([2.0, -0.5, 0.0, 0.9995])
    steps = forward_steps(x0, 1e-3, np.full(4, -10.0), np.array([10.0, 10.0, 10.0, 1.0]))
    np.testing.assert_allclose(steps, [2e-3, -1e-3, 1e-3, -1e-3], rtol=1e-12)


def test_a_linear_map_is_differentiated_exactly_on_any_map() -> None:
    matrix = np.arange(12.0).reshape(4, 3) - 5.0

    def linear(x: np.ndarray) -> np.ndarray:
        return matrix @ x

    x0 = np.array([0.3, -1.2, 4.0])
    steps = forward_steps(x0, 1e-3, np.full(3, -np.inf), np.full(3, np.inf))
    with ThreadPoolExecutor(2) as pool:
        jac = forward_jacobian(linear, x0, linear(x0), steps, pool.map)
    np.testing.assert_allclose(jac, matrix, rtol=1e-9, atol=1e-9)
    # and a curved one agrees with scipy's forward differences at the same steps
    curved = np.array([np.sin(x0[0]) * x0[1], np.exp(x0[2] / 4.0)])
    ours = forward_jacobian(lambda x: np.array([np.sin(x[0]) * x[1], np.exp(x[2] / 4.0)]),
                            x0, curved, steps)
    rows = (lambda x: np.sin(x[0]) * x[1], lambda x: np.exp(x[2] / 4.0))
    for row, function in zip(ours, rows):
        np.testing.assert_allclose(row, approx_fprime(x0, function, steps), rtol=1e-12)
