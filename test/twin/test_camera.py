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

"""Tests of cone_feeder_sim.twin.camera: the camera's errors at the rates it is set to."""

from cone_feeder_sim.errors import ParameterError
from cone_feeder_sim.formats.pointcloud import NO_TRACK
from cone_feeder_sim.twin.camera import CameraSettings, observe
import numpy as np
import pytest
from scipy.stats import binom, chi2

#: 20 pieces on a ring, far apart (12 cm between neighbours: no detection is near another).
ANGLES = np.linspace(0.0, 2.0 * np.pi, 20, endpoint=False)
TRUTH = np.column_stack([0.4 * np.cos(ANGLES), 0.4 * np.sin(ANGLES), np.full(20, 0.03)])
IDS = np.arange(100, 120, dtype=np.uint32)
FRAMES = 2000
SETTINGS = CameraSettings(sigma=0.002, miss=0.1, false_rate=0.3, radius=0.225, swap=0.2)


def frames(settings: CameraSettings, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    return [observe(settings, rng, TRUTH, IDS) for _ in range(FRAMES)]


def bounds(n: int, p: float) -> tuple[float, float]:
    """Return the binomial count's 1e-4 and 1 - 1e-4 quantiles."""
    return binom.ppf(1e-4, n, p), binom.ppf(1.0 - 1e-4, n, p)


def test_the_errors_come_at_the_rates_set() -> None:
    missed = false = swapped = 0
    residuals = []
    for seen, track in frames(SETTINGS, 0):
        assert seen.shape == (len(track), 3) and track.dtype == np.uint32
        real = np.hypot(seen[:, 0], seen[:, 1]) > 0.3  # the ring is at 0.4 m, the disc 0.225
        false += int(np.sum(~real))
        assert np.all(seen[~real, 2] == 0.0)  # a false detection is at height 0
        # each real detection's nearest true piece (the pieces are 12 cm apart)
        nearest = np.argmin(np.linalg.norm(seen[real, None, :2] - TRUTH[None, :, :2], axis=2),
                            axis=1)
        assert len(set(nearest.tolist())) == len(nearest)  # no piece detected twice
        missed += 20 - len(nearest)
        residuals.append(seen[real, :2] - TRUTH[nearest, :2])
        assert np.all(seen[real, 2] == TRUTH[nearest, 2])  # z as given, no noise
        expected = np.full(len(track), NO_TRACK, dtype=np.uint32)
        expected[real] = IDS[nearest]
        wrong = int(np.sum(track != expected))
        swapped += wrong > 0
        assert wrong in (0, 2)  # one swap at most, of two detections' ids
    low, high = bounds(20 * FRAMES, 0.1)
    assert low <= missed <= high
    low, high = bounds(FRAMES, 0.3)
    assert low <= false <= high
    low, high = bounds(FRAMES, 0.2)
    assert low <= swapped <= high
    residual = np.concatenate(residuals)
    statistic = np.sum(residual ** 2) / 0.002 ** 2  # chi-square with 2 n degrees of freedom
    assert chi2.ppf(1e-4, residual.size) < statistic < chi2.ppf(1.0 - 1e-4, residual.size)


def test_an_exact_camera_gives_the_truth_in_another_order() -> None:
    exact = CameraSettings(sigma=0.0, miss=0.0, false_rate=0.0, swap=0.0)
    rng = np.random.default_rng(1)
    seen, track = observe(exact, rng, TRUTH, IDS)
    order = np.argsort(track)
    assert np.array_equal(track[order], IDS)
    assert np.array_equal(seen[order], TRUTH)
    assert not np.array_equal(track, IDS)  # shuffled (20 pieces: by chance 1 in 20!)


def test_the_same_seed_gives_the_same_frames() -> None:
    ours, again, other = frames(SETTINGS, 3)[:50], frames(SETTINGS, 3)[:50], frames(SETTINGS, 4)
    assert all(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
               for a, b in zip(ours, again))
    assert not all(len(a[0]) == len(b[0]) and np.array_equal(a[0], b[0])
                   for a, b in zip(ours, other[:50]))


def test_two_dimensional_positions_are_taken() -> None:
    seen, track = observe(CameraSettings(false_rate=1.0), np.random.default_rng(2),
                          TRUTH[:, :2], IDS)
    assert seen.shape[1] == 2 and NO_TRACK in track.tolist()


@pytest.mark.parametrize(('change', 'name'), [
    ({'miss': 1.5}, 'miss'), ({'sigma': -0.001}, 'sigma'), ({'radius': 0.0}, 'radius'),
    ({'delay': float('nan')}, 'delay'), ({'seed': 1.5}, 'seed'), ({'swap': '0.1'}, 'swap')])
def test_a_setting_out_of_its_range_is_named(change: dict, name: str) -> None:
    with pytest.raises(ParameterError, match=f"'{name}'"):
        CameraSettings(**change)
