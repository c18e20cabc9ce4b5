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
The tracks' noise sigma (m), from the fit file's ``noise:`` or from the tracks themselves.

Estimated from fourth differences of each track, coordinate by coordinate, over consecutive
frames: d4_k = x_k - 4 x_(k+1) + 6 x_(k+2) - 4 x_(k+3) + x_(k+4). White noise of sigma gives
d4 a variance of 70 sigma^2 (1 + 16 + 36 + 16 + 1), while a smooth motion contributes about
rho (omega dt)^4: 0.8 mm for a piece turning with the cone at 8 rad/s, 0.15 m from the
axis, tracked at 30 frames/s, against 8.4 mm of d4 noise for sigma = 1 mm (a 0.4 % bias of
sigma). The estimate is robust, sigma = 1.4826 median |d4| / sqrt(70), so the kinks of a
reversal, a landing or an exit are outliers and do not count. Its relative standard error
is 1.6 / sqrt(N) for N differences (measured on white noise: overlapping differences are
correlated, so this is above a median's 1.17 / sqrt(N)).

Tracks whose noise is far below the motion's fourth difference (sub-millimetre tracking at a
low frame rate) make the estimate too large: give ``noise:`` there.
"""

from dataclasses import dataclass

import numpy as np

from .tracks import Tracks

__all__ = ['estimate_noise', 'Noise', 'noise_of']

#: Variance of a fourth difference of unit white noise.
D4_VARIANCE = 70.0
#: Normal consistency factor of the median absolute value.
MAD_SCALE = 1.4826
#: Relative standard error of the estimate times sqrt(number of differences) (measured).
REL_SE_FACTOR = 1.6
#: Fewer differences than this are not an estimate.
MIN_DIFFERENCES = 20


@dataclass(frozen=True)
class Noise:
    """
    The noise of one coordinate of a tracked position.

    sigma (m); source: 'noise' (given in the fit file) or 'tracks' (estimated);
    rel_se: the estimate's relative standard error (0 when given); count: the fourth
    differences it came from (0 when given).
    """

    sigma: float
    source: str
    rel_se: float = 0.0
    count: int = 0


def estimate_noise(tracks: Tracks) -> Noise:
    """
    Return sigma (m) estimated from the fourth differences of every track (module docs).

    Raises ValueError when the tracks hold fewer than MIN_DIFFERENCES of them (pieces with
    five or more frames): give ``noise:`` then.
    """
    differences = []
    for piece in np.unique(tracks.particle):
        rows = np.flatnonzero(tracks.particle == piece)
        rows = rows[np.argsort(tracks.t[rows], kind='stable')]
        if rows.size < 5:
            continue
        x = tracks.xyz[rows, :tracks.columns]
        differences.append(x[4:] - 4.0 * x[3:-1] + 6.0 * x[2:-2] - 4.0 * x[1:-3] + x[:-4])
    d4 = np.concatenate(differences).reshape(-1) if differences else np.zeros(0)
    if d4.size < MIN_DIFFERENCES:
        raise ValueError(f'the tracks are too short to estimate their noise ({d4.size} fourth '
                         f'differences, at least {MIN_DIFFERENCES} needed): give noise: (m)')
    sigma = MAD_SCALE * float(np.median(np.abs(d4))) / np.sqrt(D4_VARIANCE)
    return Noise(sigma=sigma, source='tracks', rel_se=REL_SE_FACTOR / np.sqrt(d4.size),
                 count=int(d4.size))


def noise_of(given: float | None, tracks: Tracks) -> Noise:
    """Return the given sigma (m), or the one estimated from ``tracks``."""
    if given is not None:
        return Noise(sigma=float(given), source='noise')
    return estimate_noise(tracks)
