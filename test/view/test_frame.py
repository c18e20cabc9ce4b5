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

"""Tests of the top view: size, type, and a scripted scene whose pieces show where they are."""

import math

from cone_feeder_sim.physics.params import ChannelLayout
from cone_feeder_sim.view.frame import (
    BACKGROUND, BOUNDARY, CONE, MARK, PALETTE, pixel_of, RIM_SHARE, top_view)
import numpy as np

RADIUS = 0.2


def colour_at(image: np.ndarray, x: float, y: float) -> tuple[int, ...]:
    """Return the colour of the pixel that holds the world point (x, y) (m)."""
    row, column = pixel_of(x, y, RADIUS, image.shape[0])
    return tuple(int(v) for v in image[int(row), int(column)])


def test_a_scripted_scene_shows_its_pieces_where_they_are() -> None:
    positions = np.array([[0.1, 0.0], [0.0, -0.1], [0.21, 0.21]])  # the last off the cone
    image = top_view(positions, np.array([0.025, 0.025, 0.025]), np.array([0, 1, 9]),
                     RADIUS, ChannelLayout(), math.pi / 2, 200)
    assert image.shape == (200, 200, 3) and image.dtype == np.uint8
    assert colour_at(image, 0.1, 0.0) == PALETTE[0]
    assert colour_at(image, 0.12, 0.0) == PALETTE[0]  # a disc of radius s0 = 25 mm
    assert colour_at(image, 0.0, -0.1) == PALETTE[1]
    assert colour_at(image, 0.0, 0.0) == CONE
    assert colour_at(image, -0.1, 0.1) == CONE
    assert colour_at(image, 0.0, 0.18) == MARK  # the cone's angle: pi/2, straight up
    assert colour_at(image, -0.18, 0.0) == CONE
    edge = math.radians(108.0)  # channel 1's boundary, just outside the rim
    assert colour_at(image, 0.21 * math.cos(edge), 0.21 * math.sin(edge)) == BOUNDARY
    assert colour_at(image, -0.21, 0.0) == BACKGROUND
    assert tuple(image[0, 0]) == BACKGROUND
    assert colour_at(image, 0.21, 0.21) == PALETTE[9 % len(PALETTE)]  # clipped, drawn


def test_the_rim_fills_its_share_and_an_empty_cone_is_drawn() -> None:
    image = top_view(np.zeros((0, 2)), np.zeros(0), np.zeros(0, dtype=int), RADIUS,
                     ChannelLayout(count=4, boundary=45.0), 0.0, 100)
    cone = np.all(image == CONE, axis=2) | np.all(image == MARK, axis=2)
    # the cone's disc covers pi (RIM_SHARE * 50)^2 pixels
    assert abs(cone.sum() / (math.pi * (RIM_SHARE * 50) ** 2) - 1.0) < 0.02
    assert np.all(image == BOUNDARY, axis=2).sum() >= 4
