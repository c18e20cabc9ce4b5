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
Bounded least squares of a fit, with standard errors, correlations and warnings.

``scipy.optimize.least_squares`` (trust-region reflective, bounds, finite-difference
Jacobian) searches θ: log p for a parameter whose range is positive, p otherwise. With
``method: global``, ``scipy.optimize.differential_evolution`` first searches the whole box
of bounds for the least sum of squares (seeded, a generation's simulations side by side),
and least squares then starts from its best point: for multimodal cases, where a local
search stops in the wrong valley. With ``segments``, a multiple-shooting fit
(:mod:`shooting`) runs first, and least squares starts both from its estimate and from where
it started; the lower cost wins. At the optimum, with J the Jacobian in θ and
s² = |r|² / (m - n) the residual variance, the covariance of θ is s² (JᵀJ)⁻¹; the delta
method carries it to p (dp/dθ = p in log scale). The 95 % interval is θ ± 1.96 σ_θ mapped
back (so it stays positive in log scale).

Parameters the data cannot identify are named in the warnings, never silently reported: a
near-singular Jacobian (condition number above :data:`CONDITION_LIMIT`, naming the keys of
the weakest direction), a correlation above :data:`CORRELATION_LIMIT` in magnitude, a
standard error larger than the estimate, or a 95 % interval wider than
:data:`INTERVAL_SHARE` of the key's free range (in θ: the data hardly narrow it).
"""

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
import math
import os
from typing import Any

import numpy as np
from scipy.optimize import differential_evolution, least_squares

from .jacobian import forward_jacobian, forward_steps, Mapper
from .problem import FitProblem, Residuals, SumOfSquares
from .shooting import initial_starts, Shooting, split

__all__ = ['CONDITION_LIMIT', 'CORRELATION_LIMIT', 'dask_mapper', 'fit', 'FitResult']

#: Above this condition number of the scaled Jacobian the fit warns of a near-singular one.
CONDITION_LIMIT = 1.0e6
#: Above this |correlation| two parameters are reported as not separately identifiable.
CORRELATION_LIMIT = 0.95
#: A 95 % interval wider than this share of the free range (in θ) is reported: the data
#: did not narrow the range fourfold.
INTERVAL_SHARE = 0.25
#: Relative finite-difference step in θ (the simulation's adaptive steps make smaller
#: differences noisy).
DIFF_STEP = 1.0e-3
#: Seed of the extra starting points.
STARTS_SEED = 0


@dataclass
class FitResult:
    """
    The fit: keys, estimates, standard errors, 95 % intervals, correlation, cost, warnings.

    cost: half the sum of squared residuals (m²) at the optimum; simulations: how many runs
    of the whole tracked time; window_simulations: how many runs of one window (multiple
    shooting); piece_rms (m) per tracked piece; success and message from least_squares.
    """

    keys: tuple[str, ...]
    estimate: np.ndarray
    stderr: np.ndarray
    low: np.ndarray
    high: np.ndarray
    correlation: np.ndarray
    cost: float
    simulations: int
    piece_rms: dict[int, float]
    window_simulations: int = 0
    warnings: list[str] = field(default_factory=list)
    success: bool = True
    message: str = ''

    def as_mapping(self) -> dict[str, Any]:
        """Return the result as RESULT.yaml holds it (plain numbers)."""
        return {
            'parameters': {k: {'estimate': float(e), 'stderr': float(s), 'low': float(lo),
                               'high': float(hi)}
                           for k, e, s, lo, hi in zip(self.keys, self.estimate, self.stderr,
                                                      self.low, self.high)},
            'correlation': {a: {b: float(self.correlation[i, j])
                                for j, b in enumerate(self.keys)}
                            for i, a in enumerate(self.keys)},
            'cost': float(self.cost),
            'simulations': int(self.simulations),
            'window_simulations': int(self.window_simulations),
            'piece_rms': {int(p): float(v) for p, v in self.piece_rms.items()},
            'warnings': list(self.warnings),
            'success': bool(self.success),
            'message': self.message,
        }


def fit(problem: FitProblem, mapper: Mapper | None = None) -> FitResult:
    """
    Fit the problem's free keys; see the module documentation.

    mapper: runs a batch of simulations (a global search's generation, the Jacobian's
    columns, multiple shooting's windows), for example a Dask client's (:func:`dask_mapper`);
    by default ``spec.workers`` threads.
    """
    spec = problem.spec
    bounds = np.array(spec.bounds)
    logs = bounds[:, 0] > 0.0
    column = logs[:, None]
    to_theta = np.where(column, np.log(np.where(column, bounds, 1.0)), bounds)
    lb, ub = to_theta[:, 0], to_theta[:, 1]
    task = Residuals(spec, tuple(bool(v) for v in logs))

    def theta_of(p: np.ndarray) -> np.ndarray:
        return np.where(logs, np.log(np.where(logs, p, 1.0)), p)

    workers = spec.workers or os.cpu_count() or 1
    with ThreadPoolExecutor(workers) as pool:
        batch = mapper or (pool.map if workers > 1 else map)

        def counted(function: Any, items: Any) -> list[Any]:
            items = list(items)
            problem.count(len(items))
            return list(batch(function, items))

        starts = [np.clip(theta_of(np.array(spec.start)), lb, ub)]
        if spec.method == 'global':
            starts = [_global_search(problem, task, lb, ub, counted)]
        if spec.segments is not None:  # its estimate, and where it started: the best wins
            starts.insert(0, _multiple_shooting(problem, task.values, starts[0], lb, ub, batch))
        rng = np.random.default_rng(STARTS_SEED)
        starts += [rng.uniform(lb, ub) for _ in range(spec.starts - 1)]
        last: dict[bytes, np.ndarray] = {}

        def residuals(theta: np.ndarray) -> np.ndarray:
            key = theta.tobytes()
            if key not in last:
                last.clear()
                last[key] = problem.residuals(task.values(theta))
            return last[key]

        def jacobian(theta: np.ndarray) -> np.ndarray:
            steps = forward_steps(theta, DIFF_STEP, lb, ub)
            return forward_jacobian(task, theta, residuals(theta), steps, counted)

        best = None
        for theta0 in starts:
            result = least_squares(residuals, theta0, jac=jacobian, bounds=(lb, ub),
                                   loss=spec.loss, x_scale='jac')
            if best is None or result.cost < best.cost:
                best = result
    assert best is not None
    return _statistics(problem, best, task.values(best.x), logs)


def dask_mapper(client: Any) -> Mapper:
    """Return a map over a Dask client: a batch's simulations on the cluster's workers."""
    def mapped(function: Any, items: Any) -> list[Any]:
        return client.gather(client.map(function, list(items), pure=False))
    return mapped


def _multiple_shooting(problem: FitProblem, values: Any, theta0: np.ndarray, lb: np.ndarray,
                       ub: np.ndarray, mapper: Mapper) -> np.ndarray:
    """Return θ from a multiple-shooting fit started at θ0 (:mod:`shooting`)."""
    spec = problem.spec
    assert spec.segments is not None
    start = problem.scenario(values(theta0))
    windows = split(spec.tracks, len(start.particles), spec.segments)
    shooting = Shooting(spec, windows, problem.scenario, values, start, mapper)
    z0 = np.concatenate([theta0, *(block.reshape(-1)
                                   for block in initial_starts(spec.tracks, windows, start))])
    n = len(theta0)
    free = np.full(len(z0) - n, np.inf)
    result = least_squares(
        shooting.residuals, z0,
        jac=lambda z: shooting.jacobian(z, forward_steps(z[:n], DIFF_STEP, lb, ub)),
        bounds=(np.concatenate([lb, -free]), np.concatenate([ub, free])), loss=spec.loss,
        x_scale='jac')
    problem.window_simulations += shooting.simulations
    return np.clip(result.x[:n], lb, ub)


def _global_search(problem: FitProblem, task: Residuals, lb: np.ndarray, ub: np.ndarray,
                   mapper: Mapper) -> np.ndarray:
    """Return the best θ of a differential evolution over the box [lb, ub]."""
    options = dict(problem.spec.global_options)
    result = differential_evolution(
        SumOfSquares(task), list(zip(lb, ub)), popsize=options['popsize'],
        maxiter=options['maxiter'], seed=options['seed'], polish=False, updating='deferred',
        workers=mapper, tol=1e-8)
    return np.asarray(result.x)


def _statistics(problem: FitProblem, result: Any, estimate: np.ndarray,
                logs: np.ndarray) -> FitResult:
    keys = problem.spec.keys
    bounds = np.array(problem.spec.bounds)
    column = logs[:, None]
    span = np.ptp(np.where(column, np.log(np.where(column, bounds, 1.0)), bounds), axis=1)
    jac = np.asarray(result.jac, dtype=float)
    residuals = np.asarray(result.fun, dtype=float)
    m, n = jac.shape
    s2 = float(residuals @ residuals) / max(m - n, 1)
    scale = np.linalg.norm(jac, axis=0)
    scale[scale == 0.0] = 1.0
    scaled = jac / scale
    u, sv, vt = np.linalg.svd(scaled, full_matrices=False)
    condition = float(sv[0] / sv[-1]) if sv[-1] > 0.0 else math.inf
    inverse = np.where(sv > sv[0] * 1e-12, 1.0 / np.where(sv > 0, sv, 1.0) ** 2, 0.0)
    cov_theta = (vt.T * inverse) @ vt / np.outer(scale, scale) * s2
    sigma_theta = np.sqrt(np.maximum(np.diag(cov_theta), 0.0))
    gradient = np.where(logs, estimate, 1.0)
    cov = cov_theta * np.outer(gradient, gradient)
    stderr = np.sqrt(np.maximum(np.diag(cov), 0.0))
    with np.errstate(invalid='ignore', divide='ignore'):
        correlation = cov / np.outer(stderr, stderr)
    correlation = np.nan_to_num(correlation)
    np.fill_diagonal(correlation, 1.0)
    theta = np.where(logs, np.log(np.where(logs, estimate, 1.0)), estimate)
    with np.errstate(over='ignore'):  # an unidentified key's interval may reach infinity
        low = np.where(logs, np.exp(theta - 1.96 * sigma_theta), estimate - 1.96 * stderr)
        high = np.where(logs, np.exp(theta + 1.96 * sigma_theta), estimate + 1.96 * stderr)
    warnings = []
    if condition > CONDITION_LIMIT or not np.all(np.isfinite(stderr)) or sv[-1] == 0.0:
        weak = [keys[i] for i in np.flatnonzero(np.abs(vt[-1]) > 0.3)]
        warnings.append(f'near-singular Jacobian (condition number {condition:.3g}): the data '
                        f'cannot identify {", ".join(weak)}')
    for i in range(n):
        for j in range(i + 1, n):
            if abs(correlation[i, j]) > CORRELATION_LIMIT:
                warnings.append(f'{keys[i]} and {keys[j]} are correlated '
                                f'({correlation[i, j]:+.3f}): not separately identifiable')
    for i in range(n):
        if not stderr[i] < abs(estimate[i]):
            warnings.append(f'{keys[i]}: standard error {stderr[i]:.3g} is not smaller than '
                            f'the estimate {estimate[i]:.3g}: not identified')
        elif 2.0 * 1.96 * sigma_theta[i] > INTERVAL_SHARE * span[i]:
            warnings.append(f'{keys[i]}: the 95 % interval [{low[i]:.3g}, {high[i]:.3g}] '
                            f'covers more than {INTERVAL_SHARE:.0%} of the free range '
                            f'[{bounds[i, 0]:g}, {bounds[i, 1]:g}]: poorly identified')
    return FitResult(keys=keys, estimate=estimate, stderr=stderr, low=low, high=high,
                     correlation=correlation, cost=float(result.cost),
                     simulations=problem.simulations, piece_rms=problem.piece_rms(estimate),
                     window_simulations=problem.window_simulations,
                     warnings=warnings, success=bool(result.success),
                     message=str(result.message))
