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
The twin's estimates as standard messages (mappings the CDR codec encodes; no ROS here).

- ``twin/pieces``: sensor_msgs/PointCloud2 of :data:`~..formats.pointcloud.TWIN_PIECE_DTYPE`
  (each piece's position, spread, most likely channel, its probability, time to the exit,
  the camera's track id last associated with it);
- ``twin/channel_forecast``: std_msgs/Float64MultiArray, dimensions horizon x channel x
  (mass, spread) (kg), the horizons in the first dimension's label;
- ``twin/parameters``: std_msgs/Float64MultiArray, d, its spread, mu_C, its spread, the keys
  in the label.
"""

from typing import Any

import numpy as np

from .forecast import Forecast
from ..formats.messages import cloud_message
from ..formats.pointcloud import NO_TRACK, TWIN_PIECE_DTYPE
from ..physics.params import ModelParams
from ..physics.simulation import resting_height

__all__ = ['channel_forecast_message', 'parameters_message', 'pieces_message']


def pieces_message(head: dict[str, Any], model: ModelParams, ids: np.ndarray,
                   mean: np.ndarray, covariance: np.ndarray, masses: np.ndarray,
                   outlook: Forecast | None, tracks: dict[int, int] | None = None
                   ) -> dict[str, Any]:
    """
    Return the ``twin/pieces`` cloud.

    ids (n,); mean (n, 2) m; covariance (n, 2, 2) m^2; masses (n,) kg; outlook: the last
    forecast (its pieces matched by id; channel 0 and NaN where it has none); tracks: the
    camera's track id of each piece (``Twin.tracks``; NO_TRACK where it has none).
    """
    points = np.zeros(len(ids), dtype=TWIN_PIECE_DTYPE)
    points['x'], points['y'] = mean[:, 0], mean[:, 1]
    points['z'] = [resting_height(model, model.product, x, y) for x, y in mean]
    points['id'] = ids & 0xFFFFFFFF
    points['mass'] = masses
    points['sigma_x'] = np.sqrt(covariance[:, 0, 0])
    points['sigma_y'] = np.sqrt(covariance[:, 1, 1])
    points['time_to_exit'] = np.nan
    points['track_id'] = [(tracks or {}).get(int(i), NO_TRACK) for i in ids]
    if outlook is not None and len(outlook.ids):
        best, probability = outlook.most_likely()
        row = {int(i): k for k, i in enumerate(outlook.ids)}
        for k, i in enumerate(ids.tolist()):
            if i in row:
                points['channel'][k] = best[row[i]]
                points['probability'][k] = probability[row[i]]
                points['time_to_exit'][k] = outlook.exit_time[row[i]] - outlook.t
    return cloud_message(head, points)


def channel_forecast_message(outlook: Forecast) -> dict[str, Any]:
    """Return ``twin/channel_forecast``: (horizon, channel, [mass, spread]) in kg."""
    h, c = outlook.mass.shape
    data = np.stack([outlook.mass, outlook.mass_spread], axis=-1).ravel()
    label = 'horizon ' + ' '.join(f'{x:g}' for x in outlook.horizons) + ' s'
    return {'layout': {'dim': [{'label': label, 'size': h, 'stride': h * c * 2},
                               {'label': 'channel', 'size': c, 'stride': c * 2},
                               {'label': 'mass spread', 'size': 2, 'stride': 2}],
                       'data_offset': 0},
            'data': data}


def parameters_message(parameters: dict[str, tuple[float, float]]) -> dict[str, Any]:
    """Return ``twin/parameters``: each key's estimate and spread, in the label's order."""
    keys = list(parameters)
    data = np.array([v for key in keys for v in parameters[key]], dtype=float)
    label = ' '.join(f'{key} {key}_spread' for key in keys)
    return {'layout': {'dim': [{'label': label, 'size': len(data), 'stride': len(data)}],
                       'data_offset': 0},
            'data': data}
