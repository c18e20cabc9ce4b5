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
A camera standing in for the real one: a plant's true pieces made into detections.

What a camera over a feeder gives the twin (issue 39): positions with noise, pieces missed
in a frame, false detections, track ids that swap, frames that arrive late and out of
order. :func:`observe` makes one frame's detections from the true positions;
``camera_node`` (:mod:`..ros.camera_node`) holds each frame back by :attr:`CameraSettings.
delay` plus up to :attr:`CameraSettings.jitter` before it passes it on. Seeded: the same
plant and seed give the same detections.
"""

from dataclasses import dataclass, fields

import numpy as np

from ..formats.pointcloud import NO_TRACK
from ..physics.params import check_integer, check_number, Limit

__all__ = ['CAMERA_LIMITS', 'CameraSettings', 'observe']

#: The ranges of :class:`CameraSettings` (camera_node's parameters of the same names).
CAMERA_LIMITS: dict[str, Limit] = {
    'sigma': Limit(0.0, 1.0, 'm'),
    'miss': Limit(0.0, 1.0, ''),
    'false_rate': Limit(0.0, 1.0, ''),
    'radius': Limit(0.0, 10.0, 'm', lo_open=True),
    'swap': Limit(0.0, 1.0, ''),
    'delay': Limit(0.0, 10.0, 's'),
    'jitter': Limit(0.0, 10.0, 's'),
    'seed': Limit(0, 2 ** 31 - 1, ''),
}


@dataclass(frozen=True)
class CameraSettings:
    """
    What the camera does to the truth.

    sigma: the noise of x and y (m, each, normal); miss: the probability that a piece is
    not detected in a frame; false_rate: the probability of one false detection in a frame,
    uniform over the disc of ``radius`` (m) about the cone's axis; swap: the probability
    that two detections exchange their track ids in a frame; delay: how late every frame
    arrives (s); jitter: up to this much later again (s, uniform: frames then arrive out of
    order); seed: of the camera's random numbers. The defaults are a fair camera (2 mm, a
    piece in twenty missed, a false detection in ten frames, 50-100 ms late).
    """

    sigma: float = 0.002
    miss: float = 0.05
    false_rate: float = 0.1
    radius: float = 0.225
    swap: float = 0.05
    delay: float = 0.05
    jitter: float = 0.05
    seed: int = 0

    def __post_init__(self) -> None:
        """Validate every field against :data:`CAMERA_LIMITS`; name the key on failure."""
        for item in fields(self):
            check = check_integer if item.name == 'seed' else check_number
            object.__setattr__(self, item.name, check(item.name, getattr(self, item.name),
                                                      CAMERA_LIMITS[item.name]))


def observe(settings: CameraSettings, rng: np.random.Generator, positions: np.ndarray,
            ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Return one frame's detections of the true pieces: positions (k, d) and track ids (k,).

    positions: (n, d) the true positions (m; x and y first, d >= 2: noise is added to x and
    y only, a false detection's other coordinates are 0); ids (n,): the pieces' ids
    (uint32 track ids; a false detection has none: :data:`~..formats.pointcloud.NO_TRACK`).
    The detections come in a random order.
    """
    positions = np.asarray(positions, dtype=float)
    kept = rng.random(len(positions)) > settings.miss
    seen = positions[kept].copy()
    seen[:, :2] += rng.normal(0.0, settings.sigma, (len(seen), 2))
    track = np.asarray(ids)[kept].astype(np.uint32)
    if rng.random() < settings.false_rate:
        r = settings.radius * np.sqrt(rng.random())
        a = 2.0 * np.pi * rng.random()
        false = np.zeros((1, positions.shape[1]))
        false[0, :2] = r * np.cos(a), r * np.sin(a)
        seen = np.vstack([seen, false])
        track = np.append(track, np.uint32(NO_TRACK))
    order = rng.permutation(len(seen))
    seen, track = seen[order], track[order]
    if settings.swap > 0.0 and len(track) > 1 and rng.random() < settings.swap:
        a, b = rng.choice(len(track), 2, replace=False)
        track[[a, b]] = track[[b, a]]
    return seen, track
