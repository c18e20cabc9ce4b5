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
A top view of the cone as an RGB array (H, W, 3) uint8, drawn with numpy alone.

The picture is the world frame seen from above: x to the right, y up, the cone's axis in the
middle and its rim at :data:`RIM_SHARE` of the half-width. It shows the cone, the channel
boundaries (fixed in the world) outside the rim, a mark that turns with the cone (its angle
phi), and every piece as a disc of its outer radius s0, coloured by its product. It needs no
display. The background (cone, channel boundaries) is drawn once per size and layout.
"""

import functools
import math
from typing import Any

import numpy as np

from ..physics.params import ChannelLayout

__all__ = ['PALETTE', 'pixel_of', 'top_view']

#: Where the rim lies, as a share of the half-width of the picture.
RIM_SHARE = 0.9
#: Colours (RGB): the background, the cone, the channel boundaries, the turning mark.
BACKGROUND = (255, 255, 255)
CONE = (205, 205, 205)
BOUNDARY = (90, 90, 90)
MARK = (40, 40, 40)
#: Piece colours by product, in order of first appearance (cycled).
PALETTE = ((214, 39, 40), (31, 119, 180), (44, 160, 44), (255, 127, 14), (148, 103, 189),
           (140, 86, 75), (227, 119, 194), (23, 190, 207))


def pixels_per_metre(radius: float, size: int) -> float:
    """Return the scale of a picture of ``size`` whose rim (radius, m) is at RIM_SHARE."""
    return RIM_SHARE * 0.5 * size / radius


def pixel_of(x: Any, y: Any, radius: float, size: int) -> tuple[Any, Any]:
    """Return the (row, column) of the world point (x, y) (m) in a picture of ``size``."""
    scale = pixels_per_metre(radius, size)
    return 0.5 * size - y * scale, 0.5 * size + x * scale


def top_view(positions: np.ndarray, radii: np.ndarray, kinds: np.ndarray, radius: float,
             channels: ChannelLayout, angle: float, size: int = 256) -> np.ndarray:
    """
    Return the top view (size, size, 3) uint8.

    positions (N, 2) m: the pieces' x, y in the world frame; radii (N,) m: their outer
    radius s0; kinds (N,) int: a product index per piece (its colour, PALETTE cycled);
    radius (m): the cone's; channels: the channel layout (world frame); angle (rad): the
    cone's angle phi.
    """
    image = _background(size, float(radius), channels).copy()
    scale = pixels_per_metre(radius, size)
    along = np.linspace(0.6 * radius, radius, max(2, int(0.8 * radius * scale)))
    for side in (-0.5, 0.5):  # the mark: a radial line two pixels wide at the angle phi
        row, column = pixel_of(along * math.cos(angle) - side / scale * math.sin(angle),
                               along * math.sin(angle) + side / scale * math.cos(angle),
                               radius, size)
        inside = (row >= 0) & (row < size) & (column >= 0) & (column < size)
        image[row[inside].astype(int), column[inside].astype(int)] = MARK
    for (px, py), r, kind in zip(np.asarray(positions, dtype=float), radii, kinds):
        row, column = pixel_of(px, py, radius, size)
        reach = r * scale
        top, bottom = max(int(row - reach), 0), min(int(row + reach) + 2, size)
        left, right = max(int(column - reach), 0), min(int(column + reach) + 2, size)
        if top >= bottom or left >= right:
            continue
        rows, columns = np.ogrid[top:bottom, left:right]
        inside = (rows + 0.5 - row) ** 2 + (columns + 0.5 - column) ** 2 <= reach * reach
        image[top:bottom, left:right][inside] = PALETTE[int(kind) % len(PALETTE)]
    return image


@functools.lru_cache(maxsize=8)
def _background(size: int, radius: float, channels: ChannelLayout) -> np.ndarray:
    """Return the picture without pieces and mark (read-only): it is drawn once."""
    image = np.empty((size, size, 3), dtype=np.uint8)
    image[:] = BACKGROUND
    rows, columns = np.mgrid[0:size, 0:size] + 0.5
    scale = pixels_per_metre(radius, size)
    x = (columns - 0.5 * size) / scale
    y = (0.5 * size - rows) / scale
    rho = np.hypot(x, y)
    image[rho < radius] = CONE
    bearing = np.arctan2(y, x)
    outside = (rho >= radius) & (rho < radius / RIM_SHARE)
    for k in range(channels.count):
        edge = math.radians(channels.boundary + 360.0 * k / channels.count)
        gap = np.abs(np.angle(np.exp(1j * (bearing - edge))))
        image[outside & (gap * rho < 1.0 / scale)] = BOUNDARY
    image.setflags(write=False)
    return image
