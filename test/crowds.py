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

"""Crowds of touching pieces that the contact tests share."""

import math

from cone_feeder_sim.physics.params import ModelParams
from cone_feeder_sim.physics.simulation import resting_height
import numpy as np


def crowd_in_layers(layers: int = 3, lift: float = 0.02) -> np.ndarray:
    """
    Return a lattice of pieces 51 mm apart in layers 51 mm apart, lift (m) up: (N, 3) m.

    35 pieces a layer, within 0.19 m of the axis; with contact on they form one island.
    """
    model = ModelParams()
    grid = [(x, y) for x in np.arange(-0.153, 0.16, 0.051)
            for y in np.arange(-0.102, 0.11, 0.051) if math.hypot(x, y) < 0.19]
    return np.array([(x, y, resting_height(model, model.product, x, y) + lift + 0.051 * k)
                     for k in range(layers) for x, y in grid])
