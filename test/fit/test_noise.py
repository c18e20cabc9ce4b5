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

"""Tests of the tracks' noise: estimated from the tracks of a reversing cone, or given."""

from pathlib import Path

from cone_feeder_sim.fit.noise import estimate_noise, noise_of
from cone_feeder_sim.fit.tracks import read_tracks_csv, Tracks
from cone_feeder_sim.formats.scenario_file import set_scenario_key
import numpy as np
import pytest
from test_fit import BASE, write_tracks


@pytest.mark.parametrize('sigma', [0.0005, 0.001, 0.003])
def test_the_noise_of_tracks_on_a_reversing_cone_is_estimated(tmp_path: Path,
                                                              sigma: float) -> None:
    # five pieces over 3 s (sticking, sliding, a reversal, exits), 30 frames/s
    truth = set_scenario_key(BASE, 'model.d', 315.0)
    tracks = read_tracks_csv(write_tracks(tmp_path / 't.csv', truth, 30.0, sigma, 2,
                                          lose_exits=True))
    noise = estimate_noise(tracks)
    assert noise.source == 'tracks' and noise.count > 500
    # the estimate is within three of its standard errors of the truth
    assert abs(noise.sigma / sigma - 1.0) < 3.0 * noise.rel_se, (noise.sigma, noise.rel_se)


def test_white_noise_alone_gives_its_sigma_and_its_scatter() -> None:
    rng = np.random.default_rng(0)
    estimates = []
    for _ in range(200):
        xyz = rng.normal(0.0, 0.002, (400, 3))
        tracks = Tracks(np.repeat(np.arange(4), 100), np.tile(np.arange(100) / 30.0, 4), xyz)
        estimates.append(estimate_noise(tracks))
    sigma = np.array([e.sigma for e in estimates])
    assert sigma.mean() == pytest.approx(0.002, rel=0.01)
    # the stated relative standard error is the scatter seen (within 20 %)
    assert sigma.std() / 0.002 == pytest.approx(estimates[0].rel_se, rel=0.2)


def test_a_given_noise_is_used_and_short_tracks_are_refused() -> None:
    short = Tracks(np.zeros(6, dtype=np.int64), np.arange(6.0), np.zeros((6, 3)))
    given = noise_of(0.002, short)
    assert (given.sigma, given.source, given.rel_se) == (0.002, 'noise', 0.0)
    with pytest.raises(ValueError, match='too short to estimate their noise'):
        noise_of(None, short)
