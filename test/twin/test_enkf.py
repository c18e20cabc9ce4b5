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
"""The ensemble Kalman filter's analysis against the Kalman filter's closed form."""

from cone_feeder_sim.twin.enkf import analyse
import numpy as np
import pytest

MEAN = np.array([0.10, -0.05, 0.30])
#: A prior covariance with correlations (m^2 and the like).
COVARIANCE = np.array([[4.0, 1.2, 0.8], [1.2, 2.0, -0.5], [0.8, -0.5, 3.0]]) * 1e-6
COLUMNS = np.array([0, 2])
SIGMA = np.array([1.0e-3, 2.0e-3])


def kalman(mean: np.ndarray, covariance: np.ndarray,
           values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the Kalman filter's posterior mean and covariance (H selects COLUMNS)."""
    h = np.eye(len(mean))[COLUMNS]
    s = h @ covariance @ h.T + np.diag(SIGMA ** 2)
    gain = covariance @ h.T @ np.linalg.inv(s)
    return mean + gain @ (values - h @ mean), (np.eye(len(mean)) - gain @ h) @ covariance


def test_a_large_ensemble_gives_the_kalman_filter() -> None:
    rng = np.random.default_rng(1)
    members = 20_000
    ensemble = rng.multivariate_normal(MEAN, COVARIANCE, members)
    values = np.array([0.1015, 0.2980])
    result = analyse(ensemble, COLUMNS, values, SIGMA, np.random.default_rng(2))
    # against the filter with the ensemble's own mean and covariance: the only difference
    # is the mean of the perturbations, sigma / sqrt(M) per observation, through the gain
    own_mean, own_cov = ensemble.mean(axis=0), np.cov(ensemble.T)
    expected, _ = kalman(own_mean, own_cov, values)
    h = np.eye(3)[COLUMNS]
    gain = own_cov @ h.T @ np.linalg.inv(h @ own_cov @ h.T + np.diag(SIGMA ** 2))
    bound = 4.0 * np.abs(gain) @ (SIGMA / np.sqrt(members))
    assert np.all(np.abs(result.ensemble.mean(axis=0) - expected) <= bound)
    # against the closed form: the mean within a tenth of the posterior's spread, the
    # covariance within 5 % of its scale (sampling error about 1 %)
    mean, covariance = kalman(MEAN, COVARIANCE, values)
    spread = np.sqrt(np.diag(covariance))
    assert np.all(np.abs(result.ensemble.mean(axis=0) - mean) < 0.1 * spread)
    scale = np.sqrt(np.outer(np.diag(covariance), np.diag(covariance)))
    assert np.all(np.abs(np.cov(result.ensemble.T) - covariance) < 0.05 * scale)
    np.testing.assert_allclose(result.spread, np.sqrt(np.diag(np.cov(result.ensemble.T))))
    assert result.observed == 2


def test_the_normalised_innovation_is_chi_square_when_consistent() -> None:
    # 400 trials: truth drawn from the prior, observed with the stated noise; the mean NIS
    # is the observations' count, 2, within 3 standard errors (chi-square's: 2 / sqrt(400)),
    # and a camera ten times noisier than stated is caught
    rng = np.random.default_rng(3)
    consistent, noisy = [], []
    for _ in range(400):
        truth = rng.multivariate_normal(MEAN, COVARIANCE)
        ensemble = rng.multivariate_normal(MEAN, COVARIANCE, 400)
        for out, noise in ((consistent, SIGMA), (noisy, 10.0 * SIGMA)):
            values = truth[COLUMNS] + rng.normal(0.0, 1.0, 2) * noise
            out.append(analyse(ensemble, COLUMNS, values, SIGMA, rng).nis)
    assert abs(np.mean(consistent) - 2.0) < 3.0 * 2.0 / np.sqrt(400)
    assert np.mean(noisy) > 20.0


def test_the_same_seed_gives_the_same_analysis() -> None:
    ensemble = np.random.default_rng(4).multivariate_normal(MEAN, COVARIANCE, 30)
    values = np.array([0.1, 0.3])
    first = analyse(ensemble, COLUMNS, values, SIGMA, np.random.default_rng(5))
    again = analyse(ensemble, COLUMNS, values, SIGMA, np.random.default_rng(5))
    np.testing.assert_array_equal(first.ensemble, again.ensemble)
    assert first.nis == again.nis


def test_nothing_observed_leaves_the_ensemble() -> None:
    ensemble = np.random.default_rng(6).multivariate_normal(MEAN, COVARIANCE, 10)
    result = analyse(ensemble, np.array([], dtype=int), np.array([]), np.array([]),
                     np.random.default_rng(0))
    np.testing.assert_array_equal(result.ensemble, ensemble)
    assert (result.nis, result.observed) == (0.0, 0)


def test_localized_groups_are_analysed_apart() -> None:
    # two pieces (components 0-1 and 2-3) that a small ensemble makes look correlated, and a
    # parameter (4, no group): observing piece 0 moves piece 0 and the parameter exactly as
    # an analysis of them alone would, and leaves piece 1 as it was
    rng = np.random.default_rng(8)
    ensemble = rng.standard_normal((6, 5)) * 1e-3
    ensemble[:, 2] += 0.9 * ensemble[:, 0]  # a spurious correlation between the pieces
    groups = np.array([0, 0, 1, 1, -1])
    columns, values, sigma = np.array([0]), np.array([2e-3]), np.array([1e-3])
    local = analyse(ensemble, columns, values, sigma, np.random.default_rng(1), groups)
    alone = analyse(ensemble[:, [0, 1, 4]], columns, values, sigma, np.random.default_rng(1))
    np.testing.assert_allclose(local.ensemble[:, [0, 1, 4]], alone.ensemble, rtol=1e-12)
    np.testing.assert_array_equal(local.ensemble[:, 2:4], ensemble[:, 2:4])
    assert local.nis == pytest.approx(alone.nis, rel=1e-12)
    # unlocalized, the spurious correlation moves piece 1
    everything = analyse(ensemble, columns, values, sigma, np.random.default_rng(1))
    assert np.abs(everything.ensemble[:, 2] - ensemble[:, 2]).max() > 1e-4
    # two observations of different groups: their innovations are weighed apart
    both = analyse(ensemble, np.array([0, 2]), np.array([2e-3, -1e-3]), np.array([1e-3] * 2),
                   np.random.default_rng(1), groups)
    first = analyse(ensemble[:, :2], np.array([0]), np.array([2e-3]), np.array([1e-3]),
                    np.random.default_rng(2))
    second = analyse(ensemble[:, 2:4], np.array([0]), np.array([-1e-3]), np.array([1e-3]),
                     np.random.default_rng(2))
    assert both.nis == pytest.approx(first.nis + second.nis, rel=1e-12)
    with pytest.raises(ValueError, match='one entry per state component'):
        analyse(ensemble, columns, values, sigma, np.random.default_rng(1), groups[:3])


@pytest.mark.parametrize(('members', 'columns', 'message'), [
    (1, COLUMNS, 'at least 2 members, got 1'),
    (5, np.array([0]), 'one entry per observation'),
])
def test_bad_input_is_named(members: int, columns: np.ndarray, message: str) -> None:
    ensemble = np.zeros((members, 3))
    with pytest.raises(ValueError, match=message):
        analyse(ensemble, columns, np.zeros(2), SIGMA, np.random.default_rng(0))
