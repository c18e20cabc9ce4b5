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
A fit: multistart least squares, a test of fit, profile-likelihood intervals, warnings.

The search scale is θ: log p for a parameter whose range is positive, p otherwise.

1. **Starts.** The file's start values and seeded Latin-hypercube points of the box
   (:mod:`multistart`): by default (``starts: auto``) in batches of 8 until 3 starts reach
   the lowest cost, 32 at most; ``starts: N`` for N in all, ``--quick`` for one.
   With ``method: global``, differential evolution replaces the file's start by the best
   point it finds; with ``segments``, a multiple-shooting fit (:mod:`shooting`) from that
   start is one more start. Each start is a bounded least-squares fit (trust-region
   reflective, forward-difference Jacobian); the starts run on processes (``processes``,
   one per numba thread by default, so every core unless ``NUMBA_NUM_THREADS`` or
   ``numba.set_num_threads`` says fewer; a Dask cluster's workers with
   ``--workers``/``--scheduler``),
   a single start in this process with ``workers`` threads for its Jacobian's columns.
   The lowest cost wins; the result says how many starts reached it (inside its joint 95 %
   confidence region).
2. **Test of fit** (:mod:`goodness`): the residuals against the tracks' noise sigma
   (``noise:``, or estimated from the tracks, :mod:`noise`), whole and piece by piece. A fit
   that fails it has ``success: false`` and a warning naming the pieces.
3. **Intervals** (:mod:`profiles`; ``profiles: false``: ±1.96 standard errors in θ from the
   Jacobian instead): the 95 % profile-likelihood interval of every key, from
   2 ΔC / sigma² = chi^2_1(0.95). A fit that failed its test gets no intervals: its low
   and high are the free range, and ``interval`` says so.
   A profile flat to a bound names the key as not identifiable that way.
4. **Restarts.** A profile point whose cost is below the optimum's by more than
   :data:`RESTART_CHI2` in 2 ΔC / sigma² shows that the local fit stopped short of the
   minimum: the fit restarts least squares from the lowest such point, takes what it
   reaches as the optimum, and tests and profiles again, :data:`MAX_RESTARTS` times at
   most; only then does it warn and fail. ``restarts`` records each.

Standard errors and correlations come from s² (JᵀJ)⁻¹ at the optimum (s² = |r|² / (m - n),
the delta method to p). Warnings also name keys where the Jacobian is near-singular
(condition number above :data:`CONDITION_LIMIT`), two keys correlate above
:data:`CORRELATION_LIMIT`, a standard error is not smaller than its estimate, or an interval
covers more than :data:`INTERVAL_SHARE` of the key's free range (in θ).
"""

from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
import contextlib
from dataclasses import dataclass, field
from functools import partial
import math
import multiprocessing
import os
import time
from typing import Any

import numba
import numpy as np
from scipy.optimize import differential_evolution, least_squares

from .goodness import FitTest, goodness_of_fit
from .jacobian import forward_steps, Mapper
from .multistart import (
    DIFF_STEP, local_fit, LocalJob, LocalOutcome, same_minimum, start_points)
from .noise import Noise, noise_of
from .problem import FitProblem, Residuals, SumOfSquares
from .profiles import DELTA_CHI2, Profile, profile_side, ProfileJob, ProfileSide
from .shooting import initial_starts, Shooting, split
from .spec import AUTO_BATCH, AUTO_ENOUGH, AUTO_MAX

__all__ = ['CONDITION_LIMIT', 'CORRELATION_LIMIT', 'dask_mapper', 'fit', 'FitResult',
           'INTERVAL_SHARE']

#: Above this condition number of the scaled Jacobian the fit warns of a near-singular one.
CONDITION_LIMIT = 1.0e6
#: Above this |correlation| two parameters are reported as not separately identifiable.
CORRELATION_LIMIT = 0.95
#: A 95 % interval wider than this share of the free range (in θ) is reported: the data
#: did not narrow the range fourfold.
INTERVAL_SHARE = 0.25
#: The first step of a profile where the Jacobian gives none (a share of the range in θ).
PROFILE_STEP = 0.05
#: A profile point below the optimum by more than this in 2 ΔC / sigma² (the cost's own
#: roughness: the simulator's adaptive steps) makes the fit restart from it...
RESTART_CHI2 = 1.0
#: ... this many times at most; then the fit warns and fails.
MAX_RESTARTS = 3


@dataclass(frozen=True)
class Restart:
    """
    A restart of the local fit from a better point a profile found.

    found_by: which profile; start: the point (p, the keys' values); from_cost: the
    optimum's cost before, profile_cost: that point's ΔC below it; to_cost: the cost the
    restarted fit reached (½ Σ r²).
    """

    found_by: str
    start: np.ndarray
    from_cost: float
    profile_cost: float
    to_cost: float


@dataclass
class FitResult:
    """
    The fit: keys, estimates, standard errors, 95 % intervals, correlation, cost, warnings.

    cost: half the sum of squared residuals (m²) at the optimum; simulations: how many runs
    of the whole tracked time; window_simulations: how many runs of one window (multiple
    shooting); piece_rms (m) per tracked piece; success: least squares converged and the
    fit passed its test; message: least_squares'. low, high: the profile-likelihood
    interval (``interval`` names the method); profiles per key; start_costs: every start's
    final cost, lowest first (the waterfall); reached_best: how many reached the lowest;
    fit_test: the test of fit; flat: per key, (low side, high side) flat to the bound;
    restarts: the restarts from better points the profiles found; stages: where the time
    went, per stage that ran (global, segments, starts, profiles, restarts): (simulations,
    wall seconds).
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
    interval: str = ''
    profiles: dict[str, dict[str, list[float]]] = field(default_factory=dict)
    flat: dict[str, tuple[bool, bool]] = field(default_factory=dict)
    start_costs: list[float] = field(default_factory=list)
    reached_best: int = 1
    fit_test: FitTest | None = None
    restarts: list[Restart] = field(default_factory=list)
    stages: dict[str, tuple[int, float]] = field(default_factory=dict)

    def as_mapping(self) -> dict[str, Any]:
        """Return the result as RESULT.yaml holds it (plain numbers)."""
        parameters = {}
        for k, e, s, lo, hi in zip(self.keys, self.estimate, self.stderr, self.low,
                                   self.high):
            entry: dict[str, Any] = {'estimate': float(e), 'stderr': float(s),
                                     'low': float(lo), 'high': float(hi)}
            if k in self.flat:
                entry['identifiable'] = {'low': not self.flat[k][0],
                                         'high': not self.flat[k][1]}
            if k in self.profiles:
                entry['profile'] = self.profiles[k]
            parameters[k] = entry
        return {
            'parameters': parameters,
            'interval': self.interval,
            'correlation': {a: {b: float(self.correlation[i, j])
                                for j, b in enumerate(self.keys)}
                            for i, a in enumerate(self.keys)},
            'cost': float(self.cost),
            'test_of_fit': self.fit_test.as_mapping() if self.fit_test else None,
            'starts': {'count': len(self.start_costs), 'reached_best': int(self.reached_best),
                       'costs': [float(c) for c in self.start_costs]},
            'restarts': [{'found_by': r.found_by,
                          'from': {k: float(v) for k, v in zip(self.keys, r.start)},
                          'from_cost': float(r.from_cost + r.profile_cost),
                          'to_cost': float(r.to_cost)} for r in self.restarts],
            'simulations': int(self.simulations),
            'stages': {name: {'simulations': int(n), 'seconds': round(float(t), 3)}
                       for name, (n, t) in self.stages.items()},
            'window_simulations': int(self.window_simulations),
            'piece_rms': {int(p): float(v) for p, v in self.piece_rms.items()},
            'warnings': list(self.warnings),
            'success': bool(self.success),
            'message': self.message,
        }


def fit(problem: FitProblem, mapper: Mapper | None = None) -> FitResult:
    """
    Fit the problem's free keys; see the module documentation.

    mapper: runs a batch of jobs, for example a Dask client's (:func:`dask_mapper`): the
    starts and the profiles' sides, and a global search's generations and multiple
    shooting's windows. By default the starts and the profiles run on ``spec.processes``
    processes, and a single start's Jacobian columns on ``spec.workers`` threads.
    """
    spec = problem.spec
    bounds = np.array(spec.bounds)
    logs = bounds[:, 0] > 0.0
    column = logs[:, None]
    to_theta = np.where(column, np.log(np.where(column, bounds, 1.0)), bounds)
    lb, ub = to_theta[:, 0], to_theta[:, 1]
    task = Residuals(spec, tuple(bool(v) for v in logs))
    noise = (noise_of(spec.noise, spec.tracks) if spec.exits is None
             else Noise(sigma=1.0, source='exit_sigma'))

    def theta_of(p: np.ndarray) -> np.ndarray:
        return np.where(logs, np.log(np.where(logs, p, 1.0)), p)

    workers = spec.workers or os.cpu_count() or 1
    stages = _Stages(problem)
    with ThreadPoolExecutor(workers) as pool, _jobs(mapper, spec.processes) as run:
        batch = mapper or (pool.map if workers > 1 else map)

        def counted(function: Any, items: Any) -> list[Any]:
            items = list(items)
            problem.count(len(items))
            return list(batch(function, items))

        first = np.clip(theta_of(np.array(spec.start)), lb, ub)
        if spec.method == 'global':
            with stages.stage('global'):
                first = _global_search(problem, task, lb, ub, counted)
        starts = [first]
        if spec.segments is not None:  # its estimate, and where it started: the best wins
            with stages.stage('segments'):
                starts.insert(0, _multiple_shooting(problem, task.values, first, lb, ub,
                                                    batch))
        with stages.stage('starts'):
            outcomes = _starts(problem, task, starts, lb, ub, noise, run, batch)
        restarts: list[Restart] = []
        while True:
            best = min(outcomes, key=lambda o: o.cost)
            estimate = task.values(best.x)
            owners = problem.owners(estimate)
            result = _statistics(problem, best, estimate, logs, owners)
            test = goodness_of_fit(best.fun, owners, noise, len(spec.keys))
            sides = []
            if test.passed and spec.profiles:
                with stages.stage('profiles'):
                    sides = run(profile_side,
                                _profile_jobs(task, best, lb, ub, noise.sigma ** 2))
                    problem.count(sum(side.simulations for side in sides))
            better = _better_point(sides, spec.keys, noise.sigma ** 2)
            if better is None or len(restarts) >= MAX_RESTARTS:
                break
            found_by, theta, from_cost = better
            with stages.stage('restarts'):
                outcome = local_fit(LocalJob(task, np.array(theta), lb, ub, spec.loss), batch)
                problem.count(outcome.simulations)
            restarts.append(Restart(found_by=found_by, start=task.values(np.array(theta)),
                                    from_cost=best.cost, profile_cost=from_cost,
                                    to_cost=outcome.cost))
            outcomes.append(outcome)
    result.start_costs = sorted(o.cost for o in outcomes[:len(outcomes) - len(restarts)])
    result.reached_best = int(same_minimum(np.array(result.start_costs + [best.cost]),
                                           noise.sigma, len(spec.keys))[:-1].sum())
    result.fit_test = test
    result.restarts = restarts
    result.stages = stages.spent
    result.simulations = problem.simulations
    if test.passed and spec.profiles:
        _intervals(result, spec.keys, logs, lb, ub, sides, noise, len(restarts))
    elif test.passed:
        result.interval = ('Jacobian, 95 % (estimate ± 1.96 standard errors in the search '
                           'scale; profiles: false)')
    else:
        result.low, result.high = bounds[:, 0].copy(), bounds[:, 1].copy()
        result.interval = ('not estimated: the fit failed its test (low and high are the '
                           'free range)')
    _test_warnings(result, test, noise)
    if len(result.start_costs) > 1 and result.reached_best == 1:
        result.warnings.append(
            f'only 1 of {len(result.start_costs)} starts reached the lowest cost: the minimum '
            'may have a narrow basin; more starts would tell')
    return result


class _Stages:
    """The simulations and wall time (s) of each stage of a fit, summed over its runs."""

    def __init__(self, problem: FitProblem) -> None:
        self.problem = problem
        self.spent: dict[str, tuple[int, float]] = {}

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Add what runs inside to the stage ``name``."""
        simulations, start = self.problem.simulations, time.perf_counter()
        yield
        count, seconds = self.spent.get(name, (0, 0.0))
        self.spent[name] = (count + self.problem.simulations - simulations,
                            seconds + time.perf_counter() - start)


def _starts(problem: FitProblem, task: Residuals, first: list[np.ndarray], lb: np.ndarray,
            ub: np.ndarray, noise: Noise, run: Callable[..., list[Any]],
            batch: Mapper) -> list[LocalOutcome]:
    """
    Run the local fits from ``first`` and the seeded points; return their outcomes.

    ``starts: N``: N starts in all. ``starts: auto``: batches of AUTO_BATCH (the first with
    ``first``) until AUTO_ENOUGH starts reached the lowest cost, AUTO_MAX at most.
    """
    spec = problem.spec
    count = spec.starts if spec.starts is not None else AUTO_BATCH
    points = first + start_points(count - len(first) + (spec.segments is not None), lb, ub)
    outcomes: list[LocalOutcome] = []
    number = 0
    while True:
        jobs = [LocalJob(task, theta0, lb, ub, spec.loss) for theta0 in points]
        outcomes += ([local_fit(jobs[0], batch)] if len(jobs) == 1 else run(local_fit, jobs))
        problem.count(sum(o.simulations for o in outcomes[-len(jobs):]))
        if spec.starts is not None or len(outcomes) >= AUTO_MAX:
            return outcomes
        costs = np.array([o.cost for o in outcomes])
        if same_minimum(costs, noise.sigma, len(spec.keys)).sum() >= AUTO_ENOUGH:
            return outcomes
        number += 1
        points = start_points(min(AUTO_BATCH, AUTO_MAX - len(outcomes)), lb, ub, number)


def _better_point(sides: list[ProfileSide], keys: tuple[str, ...],
                  variance: float) -> tuple[str, tuple[float, ...], float] | None:
    """
    Return where a profile found the lowest cost below the optimum's, or None.

    Below by more than RESTART_CHI2 in 2 ΔC / sigma² (the cost's roughness): (which
    profile found it, its θ, its ΔC).
    """
    found = [(side.lower, k) for k, side in enumerate(sides)
             if side.better is not None and 2.0 * side.lower / variance < -RESTART_CHI2]
    if not found:
        return None
    lower, k = min(found)
    side = sides[k]
    assert side.better is not None
    return (f'the profile of {keys[k // 2]} ({"lower" if k % 2 == 0 else "upper"} side)',
            side.better, lower)


@contextlib.contextmanager
def _jobs(mapper: Mapper | None, processes: int) -> Iterator[Callable[..., list[Any]]]:
    """
    Yield ``run(function, jobs)``: on the mapper, on a process pool, or here.

    The pool (spawned processes: numba's threads do not survive a fork) starts at the first
    batch of more than one job and serves every batch after it.
    """
    executor: list[ProcessPoolExecutor] = []
    count = processes or numba.get_num_threads()

    def run(function: Callable[[Any], Any], jobs: Iterable[Any]) -> list[Any]:
        jobs = list(jobs)
        if mapper is not None:
            return list(mapper(function, jobs))
        if count <= 1 or len(jobs) <= 1:
            return [function(job) for job in jobs]
        if not executor:
            executor.append(ProcessPoolExecutor(
                count, mp_context=multiprocessing.get_context('spawn'),
                initializer=_one_thread))
        return list(executor[0].map(function, jobs))

    try:
        yield run
    finally:
        for pool in executor:
            pool.shutdown()


def _one_thread() -> None:
    """Run a pool process's kernels on one thread: the processes share the cores."""
    numba.set_num_threads(1)


def _profile_jobs(task: Residuals, best: LocalOutcome, lb: np.ndarray, ub: np.ndarray,
                  variance: float) -> list[ProfileJob]:
    """Return the two sides of every key's profile at the optimum, for noise ``variance``."""
    unit = _unit_covariance(best.jac)[0]
    n = len(best.x)
    span = ub - lb
    cost = 0.5 * float(best.fun @ best.fun)
    jobs = []
    for k in range(n):
        step = 1.96 * math.sqrt(variance * unit[k, k]) if unit[k, k] > 0.0 else math.nan
        if not math.isfinite(step) or step <= 0.0 or step > 0.5 * span[k]:
            step = PROFILE_STEP * span[k]
        step = max(step, 1.0e-6 * span[k])
        slope = unit[:, k] / unit[k, k] if unit[k, k] > 0.0 else np.zeros(n)
        for direction in (-1, 1):
            jobs.append(ProfileJob(task=task, theta=best.x, cost=cost, lb=lb, ub=ub, key=k,
                                   direction=direction, step0=step,
                                   threshold=0.5 * DELTA_CHI2 * variance,
                                   slope=np.nan_to_num(slope)))
    return jobs


def _intervals(result: FitResult, keys: tuple[str, ...], logs: np.ndarray, lb: np.ndarray,
               ub: np.ndarray, sides: list[ProfileSide], noise: Noise,
               restarts: int) -> None:
    """Put the profiles' intervals, points and flat sides into ``result``; warn."""
    for k, key in enumerate(keys):
        value = partial(_value_of, bool(logs[k]))
        down, up = sides[2 * k], sides[2 * k + 1]
        theta_k = float(np.log(result.estimate[k]) if logs[k] else result.estimate[k])
        profile = Profile.of(theta_k, down, up)
        result.low[k] = float(value(profile.low))
        result.high[k] = float(value(profile.high))
        variance = noise.sigma ** 2
        result.profiles[key] = {'values': [float(v) for v in value(profile.thetas)],
                                'delta_chi2': [float(2.0 * d / variance)
                                               for d in profile.deltas]}
        result.flat[key] = (profile.flat_low, profile.flat_high)
        for side, name, bound in ((down, 'lower', lb[k]), (up, 'upper', ub[k])):
            if side.flat:
                result.warnings.append(
                    f'{key}: its profile stays below the 95 % threshold up to the {name} '
                    f'bound {float(value(bound)):.4g}: not identifiable that way')
        lowest = min(down.lower, up.lower)
        if 2.0 * lowest / variance < -RESTART_CHI2:  # after MAX_RESTARTS restarts
            result.success = False
            result.warnings.append(
                f"{key}: its profile found a cost lower than the optimum's (Δχ² = "
                f'{2.0 * lowest / variance:.3g}) after {restarts} restarts from such points, '
                'the most the fit takes: the fit did not reach the minimum; try more starts '
                'or segments')
        if (not profile.flat_low and not profile.flat_high
                and profile.high - profile.low > INTERVAL_SHARE * (ub[k] - lb[k])):
            result.warnings.append(
                f'{key}: the 95 % interval [{result.low[k]:.4g}, {result.high[k]:.4g}] covers '
                f'more than {INTERVAL_SHARE:.0%} of the free range: poorly identified')
    source = {'noise': 'given (noise:)', 'tracks': 'estimated from the tracks',
              'exit_sigma': 'exit_sigma'}[noise.source]
    result.interval = (f'profile likelihood, 95 % (Δχ² = {DELTA_CHI2:.2f}), noise sigma '
                       f'{noise.sigma:.4g} {source}')


def _value_of(log: bool, theta: Any) -> Any:
    """Return the value of θ (exp θ in log scale)."""
    return np.exp(theta) if log else np.asarray(theta, dtype=float)


def _test_warnings(result: FitResult, test: FitTest, noise: Noise) -> None:
    """Fail the result and say why where the fit failed its test."""
    if test.passed:
        return
    result.success = False
    unit = 'mm' if noise.source != 'exit_sigma' else 'sigma'
    size = noise.sigma * (1e3 if unit == 'mm' else 1.0)
    pieces = ', '.join(f'{p} (rms {test.pieces[p][0]:.3g} sigma)' for p in test.failing)
    where = f'; pieces that do not fit: {pieces}' if pieces else ''
    result.warnings.insert(0, (
        f'the fit fails its test: chi2 = {test.chi2:.4g} for {test.dof} degrees of freedom '
        f'(threshold {test.threshold:.4g}) with noise sigma = {size:.3g} {unit} '
        f'({noise.source}){where}. Try: more starts or segments (a local minimum); the '
        'scenario against the experiment, e.g. its rotation history and start places (a '
        'model error); noise: (a wrong noise level). No intervals are given (low and high are '
        'the free range).'))


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


def _unit_covariance(jac: np.ndarray) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """
    Return (JᵀJ)⁻¹ (n, n) in θ, the scaled Jacobian's condition number, V and singular values.

    Columns are scaled to unit norm first; directions with a singular value below 1e-12 of
    the largest get no variance (the warnings name them).
    """
    jac = np.asarray(jac, dtype=float)
    scale = np.linalg.norm(jac, axis=0)
    scale[scale == 0.0] = 1.0
    _, sv, vt = np.linalg.svd(jac / scale, full_matrices=False)
    condition = float(sv[0] / sv[-1]) if sv[-1] > 0.0 else math.inf
    inverse = np.where(sv > sv[0] * 1e-12, 1.0 / np.where(sv > 0, sv, 1.0) ** 2, 0.0)
    return (vt.T * inverse) @ vt / np.outer(scale, scale), condition, vt, sv


def _statistics(problem: FitProblem, result: LocalOutcome, estimate: np.ndarray,
                logs: np.ndarray, owners: np.ndarray) -> FitResult:
    """
    Return the fit at ``result`` with standard errors, correlations and their warnings.

    owners (m,): the piece of each residual; each piece's RMS comes from the residuals the
    local fit ended with (no simulation of its own).
    """
    keys = problem.spec.keys
    residuals = np.asarray(result.fun, dtype=float)
    m, n = np.asarray(result.jac).shape
    s2 = float(residuals @ residuals) / max(m - n, 1)
    unit, condition, vt, sv = _unit_covariance(result.jac)
    cov_theta = unit * s2
    gradient = np.where(logs, estimate, 1.0)
    cov = cov_theta * np.outer(gradient, gradient)
    stderr = np.sqrt(np.maximum(np.diag(cov), 0.0))
    with np.errstate(invalid='ignore', divide='ignore'):
        correlation = cov / np.outer(stderr, stderr)
    correlation = np.nan_to_num(correlation)
    np.fill_diagonal(correlation, 1.0)
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
    sigma_theta = np.sqrt(np.maximum(np.diag(cov_theta), 0.0))
    theta = np.where(logs, np.log(np.where(logs, estimate, 1.0)), estimate)
    with np.errstate(over='ignore'):  # an unidentified key's interval may reach infinity
        low = np.where(logs, np.exp(theta - 1.96 * sigma_theta), estimate - 1.96 * stderr)
        high = np.where(logs, np.exp(theta + 1.96 * sigma_theta), estimate + 1.96 * stderr)
    return FitResult(keys=keys, estimate=estimate, stderr=stderr, low=low,
                     high=high, correlation=correlation, cost=float(result.cost),
                     simulations=problem.simulations,
                     piece_rms={int(p): float(np.sqrt(np.mean(residuals[owners == p] ** 2)))
                                for p in np.unique(owners)},
                     window_simulations=problem.window_simulations,
                     warnings=warnings, success=bool(result.success),
                     message=str(result.message))
