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
Profile-likelihood intervals (Raue et al. 2009, Bioinformatics 25:1923).

The profile of key k is the least cost C(θ) = ½ Σ r² with θ_k held and the other keys
re-optimised. With sigma the noise of one residual, 2 (C_k(θ_k) - C_min) / sigma² is, for a
model that is right, a likelihood-ratio statistic with one degree of freedom: the 95 %
interval is where it stays below chi^2_1(0.95) = 3.84, that is C_k - C_min below
1.92 sigma². Unlike ±1.96 standard errors from the Jacobian, the interval follows the cost
where the model is nonlinear, and a profile that stays below the threshold up to a bound
shows a key the data cannot identify in that direction.

One side of one key is one :class:`ProfileJob` (picklable: a process pool or a Dask worker
runs it). It walks out from the optimum: the first point at the Jacobian's 1.96 σ_θ (where a
quadratic profile crosses), the next ones where the square root of the profile, which is
linear in θ_k for a quadratic cost, extrapolates to the threshold (at most fourfold farther);
then the crossing is bracketed and refined by regula falsi on that square root, each point
cutting at least a tenth off the bracket (a cliff, where a piece starts to slide or leaves
elsewhere, bends the square root), until it is 5 % of the distance wide. A point within
25 % of the threshold ends the walk (the end found by the square root through it). The other
keys start from the previous point's optimum moved along the Jacobian's correlation.
"""

from dataclasses import dataclass, field
import math

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2

from .multistart import DIFF_STEP
from .problem import Residuals

__all__ = ['DELTA_CHI2', 'Profile', 'profile_side', 'ProfileJob', 'ProfileSide']

#: The 95 % threshold of 2 ΔC / sigma² (chi^2 with one degree of freedom).
DELTA_CHI2 = float(chi2.ppf(0.95, 1))
#: Points of one side of a profile before it gives up (the interval then reaches this far).
MAX_POINTS = 8
#: The crossing is refined until the bracket is this narrow relative to its distance.
BRACKET = 0.05
#: A point whose ΔC is this close to the threshold (relative) ends the walk: the end is
#: where √ΔC, taken as linear from the optimum through it, reaches the threshold (a few
#: per cent of the half width at most, for a profile that is quadratic to 25 % in ΔC).
CLOSE = 0.25
#: The inner fits' tolerance on the cost (relative): 1e-6 of a cost of m sigma² / 2 is far
#: below the threshold's 1.92 sigma².
INNER_FTOL = 1.0e-6
#: Refinements of the crossing at most.
MAX_REFINE = 8


@dataclass(frozen=True, eq=False)
class ProfileJob:
    """
    One side of one key's profile.

    task: the residuals; theta (n,) the optimum (θ), cost its ½ Σ r²; lb, ub (n,) the bounds;
    key its index; direction +1 (up) or -1 (down); step0 (> 0) the first distance in θ;
    threshold the ΔC of the interval's end (½ DELTA_CHI2 sigma²); slope (n,) how the other
    keys follow θ_k at the optimum (the covariance's column k over its diagonal entry).
    """

    task: Residuals
    theta: np.ndarray
    cost: float
    lb: np.ndarray
    ub: np.ndarray
    key: int
    direction: int
    step0: float
    threshold: float
    slope: np.ndarray


@dataclass(frozen=True)
class ProfileSide:
    """
    One side of a profile: the points walked, and where it crosses the threshold.

    thetas: θ_k of the points, deltas: their ΔC (≥ 0 up to round-off and the inner fits);
    end: θ_k where ΔC reaches the threshold, or the bound; flat: it did not reach the
    threshold before the bound (or in MAX_POINTS points): not identifiable that way, and
    the interval reaches the bound; lower: the lowest ΔC found (< 0: the
    profile found a better fit than the optimum) and better: the whole θ (n,) of that point
    where it is below 0 (a start for the fit to restart from), else None; simulations: the
    runs it took.
    """

    thetas: list[float] = field(default_factory=list)
    deltas: list[float] = field(default_factory=list)
    end: float = math.nan
    flat: bool = False
    lower: float = 0.0
    better: tuple[float, ...] | None = None
    simulations: int = 0


@dataclass(frozen=True)
class Profile:
    """A key's profile: θ_k and ΔC of its points in order, the interval in θ, flat sides."""

    thetas: np.ndarray
    deltas: np.ndarray
    low: float
    high: float
    flat_low: bool
    flat_high: bool

    @classmethod
    def of(cls, theta_k: float, down: ProfileSide, up: ProfileSide) -> 'Profile':
        """Return the profile from its two sides, with the optimum in the middle."""
        thetas = [*reversed(down.thetas), theta_k, *up.thetas]
        deltas = [*reversed(down.deltas), 0.0, *up.deltas]
        return cls(np.array(thetas), np.array(deltas), down.end, up.end, down.flat, up.flat)


def profile_side(job: ProfileJob) -> ProfileSide:
    """Walk one side of a profile (module docs); return its points and its end."""
    k, sign = job.key, float(job.direction)
    limit = (job.ub[k] - job.theta[k]) if sign > 0 else (job.theta[k] - job.lb[k])
    others = [i for i in range(len(job.theta)) if i != k]
    runs = [0]
    warm = {0.0: np.array(job.theta, dtype=float)}

    def delta_at(distance: float) -> float:
        nearest = max(d for d in warm if d <= distance)
        theta = warm[nearest].copy()
        theta[k] = job.theta[k] + sign * distance
        if others:
            theta[others] += job.slope[others] * sign * (distance - nearest)
            theta[others] = np.clip(theta[others], job.lb[others], job.ub[others])

            def inner(phi: np.ndarray) -> np.ndarray:
                full = theta.copy()
                full[others] = phi
                runs[0] += 1
                return job.task(full)

            result = least_squares(inner, theta[others], bounds=(job.lb[others],
                                                                 job.ub[others]),
                                   diff_step=DIFF_STEP, x_scale='jac', ftol=INNER_FTOL,
                                   xtol=INNER_FTOL)
            theta[others] = result.x
            cost = float(result.cost)
        else:
            runs[0] += 1
            r = job.task(theta)
            cost = 0.5 * float(r @ r)
        warm[distance] = theta
        return cost - job.cost

    root = math.sqrt(job.threshold)
    distances: list[float] = []
    deltas: list[float] = []
    below = (0.0, 0.0)
    above = None
    trial = min(job.step0, limit)
    while len(distances) < MAX_POINTS and trial > 0.0:
        delta = delta_at(trial)
        distances.append(trial)
        deltas.append(delta)
        if abs(delta - job.threshold) <= CLOSE * job.threshold:
            end = trial * root / math.sqrt(delta)
            return _side(job, distances, deltas, job.theta[k] + sign * end, False, runs[0], warm)
        if delta >= job.threshold:
            above = (trial, math.sqrt(delta))
            break
        below = (trial, math.sqrt(max(delta, 0.0)))
        if trial >= limit:
            break
        guess = trial * 4.0 if below[1] <= 0.0 else 1.2 * trial * root / below[1]
        trial = min(max(guess, 1.5 * trial), 4.0 * trial, limit)
    if above is None:  # below the threshold up to the bound (or as far as it walked)
        return _side(job, distances, deltas, job.ub[k] if sign > 0 else job.lb[k], True,
                     runs[0], warm)
    for _ in range(MAX_REFINE):
        width = above[0] - below[0]
        cross = below[0] + (root - below[1]) * width / (above[1] - below[1])
        if width <= BRACKET * cross:
            break
        # a cliff (a piece that starts to slide, or leaves elsewhere) bends the square root:
        # each point cuts at least a tenth off the bracket
        cross = min(max(cross, below[0] + 0.1 * width), above[0] - 0.1 * width)
        delta = delta_at(cross)
        distances.append(cross)
        deltas.append(delta)
        if abs(delta - job.threshold) <= BRACKET * job.threshold:
            return _side(job, distances, deltas, job.theta[k] + sign * cross, False, runs[0], warm)
        if delta >= job.threshold:
            above = (cross, math.sqrt(delta))
        else:
            below = (cross, math.sqrt(max(delta, 0.0)))
    cross = below[0] + (root - below[1]) * (above[0] - below[0]) / (above[1] - below[1])
    return _side(job, distances, deltas, job.theta[k] + sign * cross, False, runs[0], warm)


def _side(job: ProfileJob, distances: list[float], deltas: list[float], end: float,
          flat: bool, simulations: int, warm: dict[float, np.ndarray]) -> ProfileSide:
    order = np.argsort(distances)
    thetas = [float(job.theta[job.key] + job.direction * distances[i]) for i in order]
    lowest = int(np.argmin(deltas)) if deltas else -1
    better = (tuple(float(v) for v in warm[distances[lowest]])
              if lowest >= 0 and deltas[lowest] < 0.0 else None)
    return ProfileSide(thetas=thetas, deltas=[float(deltas[i]) for i in order], end=float(end),
                       flat=flat, lower=float(min(deltas, default=0.0)), better=better,
                       simulations=simulations)
