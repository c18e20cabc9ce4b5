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
The parameters' particle step: tempered importance resampling with kernel jitter.

Where the model's response to a parameter has a threshold (a piece sticks to the cone for
every mu_C above the value that lets it slide), a linear (Kalman) update moves every member
along one regression line and drifts; weighting the members by their likelihood does not.
With many observations the likelihoods differ by hundreds in their logarithm and one member
would take every weight, so the likelihood is tempered: raised to the largest power beta in
(0, 1] that keeps the effective sample size at ``min_ess`` of the members (adaptive
tempering, Jasra et al. 2011; the information left unused makes the step conservative).
The members are resampled (systematic resampling) and jittered by a kernel shrunk towards
their mean (Liu & West 2001), so that the parameters' mean and covariance are kept.
"""

import math

import numpy as np

__all__ = ['resample_parameters', 'tempering']


def tempering(log_likelihood: np.ndarray, min_ess: float = 0.5) -> tuple[float, np.ndarray]:
    """
    Return beta and the normalised weights (M,) of the tempered likelihoods.

    beta is the largest in (0, 1] with an effective sample size 1 / sum(w^2) of at least
    min_ess * M (bisection to 1e-6).
    """
    members = len(log_likelihood)
    centred = log_likelihood - np.max(log_likelihood)

    def weights(beta: float) -> np.ndarray:
        w = np.exp(beta * centred)
        return w / w.sum()

    def ess(beta: float) -> float:
        w = weights(beta)
        return 1.0 / float(w @ w)

    if ess(1.0) >= min_ess * members:
        return 1.0, weights(1.0)
    low, high = 0.0, 1.0
    while high - low > 1e-6:
        mid = 0.5 * (low + high)
        low, high = (mid, high) if ess(mid) >= min_ess * members else (low, mid)
    return low, weights(low)


def resample_parameters(parameters: np.ndarray, log_likelihood: np.ndarray,
                        rng: np.random.Generator, min_ess: float = 0.5,
                        shrink: float = 0.95) -> tuple[np.ndarray, float]:
    """
    Return the members' parameters (M, q) after the particle step, and the tempering beta.

    parameters: (M, q) each member's; log_likelihood: (M,) of each member's predictions
    of the observations; shrink: Liu & West's a (the jitter's variance is 1 - a^2 of the
    weighted covariance).
    """
    members = len(parameters)
    beta, w = tempering(log_likelihood, min_ess)
    positions = (rng.uniform() + np.arange(members)) / members
    index = np.minimum(np.searchsorted(np.cumsum(w), positions), members - 1)
    mean = w @ parameters
    centred = parameters - mean
    covariance = (centred * w[:, None]).T @ centred
    kept = shrink * parameters[index] + (1.0 - shrink) * mean
    jitter = rng.multivariate_normal(np.zeros(parameters.shape[1]), covariance,
                                     size=members, method='eigh')
    return kept + math.sqrt(1.0 - shrink ** 2) * jitter, beta
