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
"""The parameters' particle step (tempering, resampling, jitter); the twin identifying d, mu_C."""

from dataclasses import replace

from cone_feeder_sim.physics.params import ModelParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    add_particles, advance, resting_height, SimParams, SimState, world_from_cone)
from cone_feeder_sim.twin.estimator import Twin, TwinSettings
from cone_feeder_sim.twin.particles import resample_parameters, tempering
import numpy as np
import pytest


def test_tempering_keeps_the_effective_sample_size() -> None:
    rng = np.random.default_rng(0)
    log_likelihood = -0.5 * rng.chisquare(150, 64) * 10.0  # differences of hundreds
    beta, w = tempering(log_likelihood, 0.5)
    assert 0.0 < beta < 1.0
    assert 1.0 / (w @ w) == pytest.approx(32.0, rel=1e-3)
    flat_beta, flat = tempering(np.zeros(64), 0.5)
    assert flat_beta == 1.0 and np.allclose(flat, 1.0 / 64)


def test_a_flat_likelihood_keeps_the_mean_and_the_covariance() -> None:
    rng = np.random.default_rng(1)
    prior = rng.multivariate_normal([5.4, 0.85], [[0.25, 0.01], [0.01, 0.0225]], 20_000)
    after, beta = resample_parameters(prior, np.zeros(len(prior)), rng)
    assert beta == 1.0
    assert np.allclose(after.mean(axis=0), prior.mean(axis=0), atol=0.01)
    assert np.allclose(np.cov(after.T), np.cov(prior.T), rtol=0.05, atol=2e-4)


def test_a_threshold_likelihood_keeps_the_members_above_it() -> None:
    # a piece that stuck: every mu_C above 0.75 explains it alike, below it does not (the
    # case that drives a linear update along one regression line and off)
    rng = np.random.default_rng(2)
    prior = np.column_stack([rng.normal(5.4, 0.5, 4000), rng.normal(0.85, 0.15, 4000)])
    log_likelihood = np.where(prior[:, 1] > 0.75, 0.0, -200.0)
    after, _ = resample_parameters(prior, log_likelihood, rng)
    above = prior[prior[:, 1] > 0.75, 1]
    assert after[:, 1].mean() == pytest.approx(above.mean(), abs=0.02)
    assert np.mean(after[:, 1] < 0.7) < 0.05
    assert after[:, 0].std() == pytest.approx(0.5, rel=0.1)  # d untouched by the data


MODEL = ModelParams()
PARAMS = SimParams(model=MODEL)
PLACES = [[0.10, 0.02], [-0.08, 0.09], [0.03, -0.13], [-0.12, -0.05], [0.06, 0.11],
          [-0.02, -0.07], [0.07, -0.02]]


def follow(twin: Twin, plant: SimState, profile: RotationProfile, seconds: float,
           sigma: float, rng: np.random.Generator) -> SimState:
    """Give the twin the plant's x, y with noise sigma (m) at 30 frames/s; return the plant."""
    for k in range(1, int(round(30 * seconds)) + 1):
        t = k / 30.0
        plant = advance(plant, PARAMS, profile, t).state
        twin.cone_speed(t, profile.omega(t))
        seen, _, _ = world_from_cone(plant.y, plant.angle, profile.omega(t))
        twin.update(t, seen[:, :2] + rng.normal(0.0, sigma, (plant.count, 2)))
    return plant


def test_d_and_mu_c_are_identified_where_the_pieces_slide() -> None:
    # the plant's d and mu_C are 2x and -0.15 from the twin's prior (d 225 +- 50 % on the
    # log scale, mu_C 0.85 +- 0.15); the cone reverses at 8 rad/s, the outer pieces slide.
    # The particle step over 0.5-s windows has both within three of its spreads after 3 s
    profile = RotationProfile.from_table([[0.0, 0.0], [0.5, 8.0], [1.5, 8.0], [2.0, -8.0]])
    product = replace(MODEL.product, d=450.0, mu_C=0.7)
    q = np.array([[x, y, resting_height(MODEL, product, x, y)] for x, y in PLACES])
    plant, _ = add_particles(SimState(), PARAMS, q, products=[product] * len(q))
    twin = Twin(PARAMS, TwinSettings(members=32, sigma=0.001, mu_C_spread=0.15, seed=1))
    follow(twin, plant, profile, 3.0, 0.001, np.random.default_rng(0))
    found = twin.parameters()
    z = {key: (found[key][0] - truth) / found[key][1]
         for key, truth in (('d', 450.0), ('mu_C', 0.7))}
    assert all(abs(v) < 3.0 for v in z.values()), (found, z)
    # it learned: spreads below the prior's (the random walk of 5 % per s keeps them up)
    assert found['mu_C'][1] < 0.15 and found['d'][1] < 0.5 * found['d'][0]


def test_where_every_piece_sticks_the_pieces_stay_on_the_cone_and_d_and_mu_c_where_they_were(
        ) -> None:
    # on a cone reversing at 3 rad/s every piece sticks and nothing identifies d or mu_C:
    # the twin's pieces must stay on the cone's surface and d, mu_C near the truth (the
    # prior's centre). An analysis that updated the height and the friction force's normal
    # part through sampled correlations took them off the surface (10 cm in these 20 s),
    # and d and mu_C with them (benchmarks/twin_sticking.py)
    table = [[0.0, 0.0], [0.5, 3.0]]
    for k in range(10):
        sign = 1.0 if k % 2 == 0 else -1.0
        table += [[2.0 * k + 1.5, sign * 3.0], [2.0 * k + 2.0, -sign * 3.0]]
    profile = RotationProfile.from_table(table)
    places = PLACES + [[-0.14, 0.06], [0.12, -0.09], [0.0, 0.15]]
    q = np.array([[x, y, resting_height(MODEL, MODEL.product, x, y)] for x, y in places])
    plant, _ = add_particles(SimState(), PARAMS, q)
    twin = Twin(PARAMS, TwinSettings(members=8, sigma=0.002))
    plant = follow(twin, plant, profile, 20.0, 0.002, np.random.default_rng(30))
    assert np.all(np.abs(plant.y[:, 3:6]) < 0.01)  # they stuck (relative speed < 1 cm/s)
    for state in twin.states:
        x, y, z = state.y[:, 0:3].T
        height = np.array([resting_height(MODEL, MODEL.product, a, b) for a, b in zip(x, y)])
        assert np.max(np.abs(z - height)) < 1.0e-3
    # nothing identifies d: it stays within two of its spreads of the truth, its spread near
    # the prior's (0.5 on the log scale) and below that grown by the random walk alone
    # (5 % per sqrt(s): 0.55 after 20 s); mu_C within two spreads, below the walk's 0.23
    settings = twin.settings
    walk = settings.drift ** 2 * 20.0
    log_d = (np.mean(twin.log_d), np.std(twin.log_d, ddof=1))
    mu_c = twin.parameters()['mu_C']
    assert abs(log_d[0] - np.log(225.0)) < 2.0 * log_d[1], log_d
    assert 0.5 * settings.d_spread < log_d[1] < 1.1 * np.sqrt(settings.d_spread ** 2 + walk)
    assert abs(mu_c[0] - 0.85) < 2.0 * mu_c[1], mu_c
    assert mu_c[1] < 1.1 * np.sqrt(settings.mu_C_spread ** 2 + walk), mu_c
