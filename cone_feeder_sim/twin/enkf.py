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
The analysis step of the ensemble Kalman filter (stochastic, with perturbed observations).

The twin's state is an ensemble of M simulations; each member's state is a vector (the
pieces' states and, augmented, the product's parameters). Observations are a linear
selection of state components (positions seen by a camera) with independent Gaussian noise.
The analysis (Evensen 1994; Burgers, van Leeuwen & Evensen 1998) moves every member by the
Kalman gain estimated from the ensemble's own covariances, against the observations
perturbed by noise of the observations' variance, so that the analysed spread is the
Kalman filter's in the limit of a large ensemble:

    K = P_xy (P_yy + R)^-1,   x_i <- x_i + K (y + e_i - H x_i),   e_i ~ N(0, R).

The normalised innovation squared of the ensemble mean, (y - H x)^T (P_yy + R)^-1 (y - H x),
is chi-square with as many degrees of freedom as observations when the filter is
consistent: the twin's consistency test.

Localization (Houtekamer & Mitchell 2001, with a taper of zeros and ones): the components
may be put in groups (the twin's pieces), and the covariances between groups are cut, so
that an observation moves only the components of its own group and those of no group (-1:
the product's parameters, moved by every observation). A finite ensemble's covariances
between pieces that do not touch are noise (sampling error of order 1/sqrt(M)): with 8
members and 30 pieces, every piece was moved by the other 29 pieces' innovations, the
spread shrank and a detection in twelve fell outside its gate (doc/twin.md).
"""

from dataclasses import dataclass

import numpy as np

__all__ = ['Analysis', 'analyse']


@dataclass(frozen=True)
class Analysis:
    """
    The result of one analysis.

    ensemble: (M, d) the analysed members; nis: the normalised innovation squared of the
    forecast mean (dimensionless); observed: the number of observations (its degrees of
    freedom); spread: (d,) the analysed ensemble's standard deviation per component.
    """

    ensemble: np.ndarray
    nis: float
    observed: int
    spread: np.ndarray


def analyse(ensemble: np.ndarray, columns: np.ndarray, values: np.ndarray, sigma: np.ndarray,
            rng: np.random.Generator, groups: np.ndarray | None = None) -> Analysis:
    """
    Return the analysis of ensemble (M, d) against observed components.

    columns: (p,) int, the observed state components (H selects them); values: (p,) what was
    observed, in the components' units; sigma: (p,) the observations' noise standard
    deviations (same units); rng: draws the perturbations (seeded by the caller, so a run
    replayed gives the same analysis); groups: (d,) int, the localization's group of each
    component (-1: none; see the module), or None: no localization. The forecast ensemble
    is not changed.
    """
    members = ensemble.shape[0]
    if members < 2:
        raise ValueError(f'an ensemble needs at least 2 members, got {members}')
    columns = np.asarray(columns, dtype=np.int64)
    values = np.asarray(values, dtype=float)
    sigma = np.asarray(sigma, dtype=float)
    if not (columns.shape == values.shape == sigma.shape):
        raise ValueError('columns, values and sigma must have one entry per observation')
    if columns.size == 0:
        return Analysis(ensemble.copy(), 0.0, 0, ensemble.std(axis=0, ddof=1))
    mean = ensemble.mean(axis=0)
    anomalies = ensemble - mean  # (M, d)
    seen = anomalies[:, columns]  # (M, p)
    scale = 1.0 / (members - 1)
    p_yy = scale * seen.T @ seen + np.diag(sigma ** 2)  # (p, p)
    p_xy = scale * anomalies.T @ seen  # (d, p)
    if groups is not None:
        groups = np.asarray(groups, dtype=np.int64)
        if groups.shape != (ensemble.shape[1],):
            raise ValueError('groups must have one entry per state component')
        seen_groups = groups[columns]
        p_yy *= seen_groups[:, None] == seen_groups[None, :]
        p_xy *= (groups[:, None] == seen_groups[None, :]) | (groups[:, None] == -1)
    innovation = values - mean[columns]
    factor = np.linalg.cholesky(p_yy)
    whitened = np.linalg.solve(factor, innovation)
    nis = float(whitened @ whitened)
    perturbed = values + rng.normal(0.0, 1.0, (members, columns.size)) * sigma  # (M, p)
    gain_input = np.linalg.solve(p_yy, (perturbed - ensemble[:, columns]).T)  # (p, M)
    analysed = ensemble + (p_xy @ gain_input).T
    return Analysis(analysed, nis, int(columns.size), analysed.std(axis=0, ddof=1))
