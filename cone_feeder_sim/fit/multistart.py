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
Multistart: local least-squares fits from many starts, as picklable jobs for processes.

A fit's starts are the file's start values and ``starts - 1`` points of a seeded Latin
hypercube over the box of bounds (in the search scale θ), so that every key's range is cut
into ``starts`` strata and each stratum holds one start. Each start is one
:class:`LocalJob`: bounded least squares (trust-region reflective, the forward-difference
Jacobian of :mod:`jacobian`) from its θ0, which a process pool, a Dask worker or the caller
runs (:func:`local_fit`). The outcomes, sorted by cost, are the waterfall of pyPESTO and
Data2Dynamics: a plateau of starts at the lowest cost says the global minimum was found
from many sides.
"""

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2, qmc

from .jacobian import forward_jacobian, forward_steps, Mapper
from .problem import Residuals

__all__ = ['DIFF_STEP', 'local_fit', 'LocalJob', 'LocalOutcome', 'same_minimum',
           'start_points', 'STARTS_SEED']

#: Relative finite-difference step in θ (the simulation's adaptive steps make smaller
#: differences noisy).
DIFF_STEP = 1.0e-3
#: Seed of the extra starting points.
STARTS_SEED = 0


def start_points(count: int, lb: np.ndarray, ub: np.ndarray,
                 batch: int = 0) -> list[np.ndarray]:
    """
    Return ``count`` seeded Latin-hypercube points (n,) in the box [lb, ub] (θ).

    batch: the batch of starts (0 the first); each batch is a hypercube of its own seed.
    """
    if count <= 0:
        return []
    sample = qmc.LatinHypercube(d=len(lb), seed=STARTS_SEED + batch).random(count)
    return list(qmc.scale(sample, lb, ub))


@dataclass(frozen=True, eq=False)
class LocalJob:
    """One local fit: the residuals, its start θ0 (n,), the bounds lb, ub (n,) in θ."""

    task: Residuals
    theta0: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    loss: str = 'linear'


@dataclass(frozen=True, eq=False)
class LocalOutcome:
    """
    Where a local fit ended: θ (n,), cost ½ Σ ρ(r²), residuals (m,), Jacobian (m, n) in θ.

    simulations: the runs it took; success and message: least_squares'; theta0 its start.
    """

    theta0: np.ndarray
    x: np.ndarray
    cost: float
    fun: np.ndarray
    jac: np.ndarray
    simulations: int
    success: bool
    message: str


def local_fit(job: LocalJob, mapper: Mapper = map) -> LocalOutcome:
    """Run one local fit; the Jacobian's columns go through ``mapper`` (the builtin: here)."""
    last: dict[bytes, np.ndarray] = {}
    runs = [0]

    def counted(function: Any, items: Any) -> list[Any]:
        items = list(items)
        runs[0] += len(items)
        return list(mapper(function, items))

    def residuals(theta: np.ndarray) -> np.ndarray:
        key = theta.tobytes()
        if key not in last:
            last.clear()
            runs[0] += 1
            last[key] = job.task(theta)
        return last[key]

    def jacobian(theta: np.ndarray) -> np.ndarray:
        steps = forward_steps(theta, DIFF_STEP, job.lb, job.ub)
        return forward_jacobian(job.task, theta, residuals(theta), steps, counted)

    theta0 = np.clip(np.asarray(job.theta0, dtype=float), job.lb, job.ub)
    result = least_squares(residuals, theta0, jac=jacobian, bounds=(job.lb, job.ub),
                           loss=job.loss, x_scale='jac')
    return LocalOutcome(theta0=theta0, x=np.asarray(result.x), cost=float(result.cost),
                        fun=np.asarray(result.fun), jac=np.asarray(result.jac),
                        simulations=runs[0], success=bool(result.success),
                        message=str(result.message))


def same_minimum(costs: np.ndarray, sigma: float, free: int) -> np.ndarray:
    """
    Return which costs (½ Σ r²) reached the lowest: inside its joint 95 % confidence region.

    That is 2 (cost - lowest) / sigma² ≤ chi^2 with ``free`` degrees of freedom at 0.95:
    starts that stopped there are indistinguishable from the best with these data (the
    simulator's adaptive steps leave the cost slightly rough, so starts that converge to
    one minimum stop a few units of χ² apart). sigma: the noise of one residual.
    """
    costs = np.asarray(costs, dtype=float)
    return 2.0 * (costs - costs.min()) / (sigma * sigma) <= chi2.ppf(0.95, free)
