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
The test of fit: the residuals against the tracks' noise, whole and piece by piece.

With sigma the noise of one residual (m; exits: residuals are already in sigmas, sigma = 1),
a model that fits leaves X = sum r^2 / sigma^2 distributed as chi^2 with m - n degrees of
freedom (m residuals, n free keys), and each piece's X_p = sum over its residuals as
chi^2 with m_p. The fit fails its test where X is above the chi^2 quantile 1 - ALPHA, or a
piece's X_p above the quantile 1 - ALPHA / P (Bonferroni over the P pieces). Where sigma was
estimated, the thresholds are widened by its uncertainty: multiplied by
(1 + 3 rel_se)^2, so that a fit that is right is not failed by a low estimate of sigma.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from .noise import Noise

__all__ = ['ALPHA', 'FitTest', 'goodness_of_fit']

#: The test's size: a fit that is right fails it with this probability (or less).
ALPHA = 1.0e-3


@dataclass(frozen=True)
class FitTest:
    """
    The outcome of the test of fit.

    chi2 = sum r^2 / sigma^2 over dof = m - n, its threshold, and passed; pieces: per piece
    (id: (rms / sigma, passed)); failing: the ids of the pieces that did not pass.
    """

    noise: Noise
    chi2: float
    dof: int
    threshold: float
    passed: bool
    pieces: dict[int, tuple[float, bool]] = field(default_factory=dict)

    @property
    def failing(self) -> list[int]:
        """Return the ids of the pieces that fail their test."""
        return [p for p, (_, ok) in self.pieces.items() if not ok]

    @property
    def reduced(self) -> float:
        """Return chi2 / dof (about 1 for a fit that is right)."""
        return self.chi2 / max(self.dof, 1)

    def as_mapping(self) -> dict[str, object]:
        """Return the test as RESULT.yaml holds it (plain numbers)."""
        return {'noise': float(self.noise.sigma), 'noise_source': self.noise.source,
                'noise_rel_se': float(self.noise.rel_se), 'chi2': float(self.chi2),
                'dof': int(self.dof), 'threshold': float(self.threshold),
                'passed': bool(self.passed),
                'piece_rms_over_noise': {int(p): float(v) for p, (v, _) in self.pieces.items()},
                'failing_pieces': [int(p) for p in self.failing]}


def goodness_of_fit(residuals: np.ndarray, owner: np.ndarray, noise: Noise,
                    free: int) -> FitTest:
    """
    Return the test of fit of ``residuals`` (m,) whose pieces are ``owner`` (m,) ids.

    noise: sigma of one residual (in the residuals' unit); free: the number of free keys.
    """
    widen = (1.0 + 3.0 * noise.rel_se) ** 2
    scaled = np.asarray(residuals, dtype=float) / noise.sigma
    total = float(scaled @ scaled)
    dof = max(scaled.size - free, 1)
    threshold = float(chi2.ppf(1.0 - ALPHA, dof)) * widen
    ids = np.unique(owner)
    pieces = {}
    for piece in ids:
        mine = scaled[owner == piece]
        x_p = float(mine @ mine)
        limit = float(chi2.ppf(1.0 - ALPHA / len(ids), mine.size)) * widen
        pieces[int(piece)] = (float(np.sqrt(x_p / mine.size)), bool(x_p <= limit))
    passed = total <= threshold and all(ok for _, ok in pieces.values())
    return FitTest(noise=noise, chi2=total, dof=dof, threshold=threshold, passed=passed,
                   pieces=pieces)
