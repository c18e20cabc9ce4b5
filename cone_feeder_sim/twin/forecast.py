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
What the twin says will happen next: each piece's channel and exit time, each channel's mass.

Every member of the twin's ensemble is advanced on its own (a copy: the twin is not moved)
over the longest horizon, under the cone speed held at its last measured value (or a
rotation the caller gives, such as the controller's command). Each member's exits are one
sample of the future; over the members:

- per piece on the cone: the probability of each channel (the share of members in which it
  leaves into that channel within the horizon; the rest: it stays) and the expected exit
  time over the members in which it leaves;
- per channel and horizon h: the mass (kg) that falls into it during [t, t + h], its mean
  and its spread (standard deviation) over the members.
"""

from dataclasses import dataclass

import numpy as np

from .estimator import Twin
from ..physics.rotation import RotationProfile

__all__ = ['Forecast', 'forecast']


@dataclass(frozen=True)
class Forecast:
    """
    A forecast made at t (s).

    ids: (n,) the pieces on the cone; channel_probability: (n, C + 1) per piece, column 0
    staying on the cone over the longest horizon and column c channel c (1-based);
    exit_time: (n,) the expected exit time (s; NaN where no member lets it leave);
    horizons: (H,) s; mass: (H, C) expected mass per channel (kg), mass_spread: (H, C) its
    standard deviation over the members.
    """

    t: float
    ids: np.ndarray
    channel_probability: np.ndarray
    exit_time: np.ndarray
    horizons: np.ndarray
    mass: np.ndarray
    mass_spread: np.ndarray

    def most_likely(self) -> tuple[np.ndarray, np.ndarray]:
        """Return per piece the most likely outcome (0: stays, c: channel c), its probability."""
        best = np.argmax(self.channel_probability, axis=1)
        return best, self.channel_probability[np.arange(len(best)), best]


def forecast(twin: Twin, horizons: tuple[float, ...] = (0.5, 1.0, 2.0),
             rotation: RotationProfile | None = None) -> Forecast:
    """
    Forecast from the twin's members over horizons (s); the twin is not changed.

    rotation: the cone speed to forecast under (absolute time); default: the measured speed,
    held at its last value.
    """
    t0 = twin.t
    ids = twin.pieces()[0]
    channels = twin.params.model.channels.count
    h = np.asarray(sorted(horizons), dtype=float)
    m = len(twin.states)
    profile = rotation or twin.profile()
    results = twin.advance(twin.states, t0 + h[-1], profile)
    index = {int(i): k for k, i in enumerate(ids)}
    counts = np.zeros((len(ids), channels + 1))
    times = np.zeros(len(ids))
    left = np.zeros(len(ids))
    mass = np.zeros((m, len(h), channels))
    for member, result in enumerate(results):
        exits = result.exits
        for i, t, c, w in zip(exits.ids.tolist(), exits.t.tolist(), exits.channel.tolist(),
                              exits.mass.tolist()):
            k = index.get(i)
            if k is None:  # a tentative piece (twin.pieces): not counted until confirmed
                continue
            mass[member, :, c - 1] += w * (t <= t0 + h)
            counts[k, c] += 1
            times[k] += t
            left[k] += 1
    counts[:, 0] = m - left
    exit_time = np.where(left > 0, times / np.maximum(left, 1), np.nan)
    return Forecast(t=t0, ids=ids, channel_probability=counts / m, exit_time=exit_time,
                    horizons=h, mass=mass.mean(axis=0), mass_spread=mass.std(axis=0, ddof=1))
