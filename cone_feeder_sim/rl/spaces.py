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
The environment's spaces, and the conversions between them and plain arrays.

The one place where observations are computed and actions decoded:
:class:`~cone_feeder_sim.rl.env.ConeFeederEnv` feeds them from its engine, the ROS node
``policy_controller`` from ``sim_node``'s topics, so that a policy trained on the
environment sees the same numbers in the ROS system. The layout and the scaling are in
:mod:`cone_feeder_sim.rl.env`.
"""

import math
from typing import Any

from gymnasium import spaces
import numpy as np

from .config import EnvConfig
from ..physics.params import PRODUCT_LIMITS

__all__ = ['action_space', 'decode_action', 'feature_bounds', 'features', 'mass_grid',
           'observation', 'observation_space', 'piece_rows', 'PIECE_COLUMNS']


def feature_bounds(config: EnvConfig) -> tuple[np.ndarray, np.ndarray]:
    """Return the low and high bounds of the feature vector (F,) float32."""
    channels = config.engine.model.channels.count
    heads = channels if config.engine.weigher is not None else 0
    clip = config.obs_clip
    cells = config.grid[0] * config.grid[1]
    low = np.concatenate([[-1.0, -1.0, -1.0], np.full(channels, -clip), np.zeros(heads),
                          np.zeros(cells)])
    high = np.concatenate([[1.0, 1.0, 1.0], np.full(channels, clip), np.full(heads, clip),
                           np.full(cells, clip)])
    return low.astype(np.float32), high.astype(np.float32)


def mass_grid(config: EnvConfig, xy: np.ndarray, masses: np.ndarray) -> np.ndarray:
    """
    Return the mass on the cone in the polar grid (radial, angular) kg.

    xy (N, 2) the pieces' positions in the cone's frame (m); masses (N,) kg. Radial bins
    of equal width from the axis to the rim (a piece beyond the rim counts in the last),
    angular bins from the cone's x axis counter-clockwise.
    """
    radial, angular = config.grid
    x, y = xy[:, 0], xy[:, 1]
    rim = config.engine.model.r
    i = np.minimum((np.hypot(x, y) / rim * radial).astype(np.int64), radial - 1)
    phase = np.mod(np.arctan2(y, x), 2.0 * math.pi) / (2.0 * math.pi)
    j = np.minimum((phase * angular).astype(np.int64), angular - 1)
    cells = np.bincount(i * angular + j, weights=masses, minlength=radial * angular)
    return cells.reshape(radial, angular)


def features(config: EnvConfig, omega: float, angle: float, deficit: np.ndarray,
             hoppers: np.ndarray | None, xy: np.ndarray, masses: np.ndarray) -> np.ndarray:
    """
    Return the feature vector (F,) float32, scaled and clipped into its bounds.

    omega (rad/s) and angle (rad) of the cone; deficit (channels,) kg; hoppers (heads,) kg
    (None without the weigher); xy (N, 2) m in the cone's frame and masses (N,) kg of the
    pieces on the cone.
    """
    m = config.engine.model.product.m
    parts = [np.array([omega / config.engine.drive.max_angular_velocity, math.sin(angle),
                       math.cos(angle)]), np.asarray(deficit) / m]
    if config.engine.weigher is not None:
        if hoppers is None:
            raise ValueError('the weigher is on: the hoppers readings are needed')
        parts.append(np.asarray(hoppers) / m)
    parts.append(mass_grid(config, xy, masses).reshape(-1) / m)
    low, high = feature_bounds(config)
    return np.clip(np.concatenate(parts), low, high).astype(np.float32)


#: Bounds of the padded piece rows (observation: dict): |x|, |y| (m), z (m), |v| (m/s).
PIECE_XY = 1.0
PIECE_Z = (-1.0, 20.0)
PIECE_SPEED = 50.0
#: Columns of a piece row.
PIECE_COLUMNS = ('x', 'y', 'z', 'vx', 'vy', 'vz', 'm')


def piece_bounds(config: EnvConfig) -> tuple[np.ndarray, np.ndarray]:
    """Return the low and high bounds of one piece row (7,) float32."""
    low = [-PIECE_XY, -PIECE_XY, PIECE_Z[0]] + [-PIECE_SPEED] * 3 + [0.0]
    high = [PIECE_XY, PIECE_XY, PIECE_Z[1]] + [PIECE_SPEED] * 3 + [PRODUCT_LIMITS['m'].hi]
    return np.array(low, dtype=np.float32), np.array(high, dtype=np.float32)


def observation_space(config: EnvConfig) -> spaces.Space:
    """Return the observation space of a configuration."""
    low, high = feature_bounds(config)
    features = spaces.Box(low, high, dtype=np.float32)
    if config.observation == 'grid':
        return features
    rows = config.max_pieces_observed
    plow, phigh = piece_bounds(config)
    return spaces.Dict({
        'features': features,
        'pieces': spaces.Box(np.tile(plow, (rows, 1)), np.tile(phigh, (rows, 1)),
                             dtype=np.float32),
        'mask': spaces.MultiBinary(rows)})


def action_space(config: EnvConfig) -> spaces.Space:
    """Return the action space of a configuration."""
    if config.action == 'discrete':
        return spaces.Discrete(3)
    limit = config.engine.drive.max_angular_velocity
    size = 1 + (config.engine.model.channels.count if config.feed_amplitudes else 0)
    if config.normalize_actions:
        return spaces.Box(-1.0, 1.0, shape=(size,), dtype=np.float32)
    low = np.concatenate([[-limit], np.zeros(size - 1)]).astype(np.float32)
    high = np.concatenate([[limit], np.full(size - 1, 2.0)]).astype(np.float32)
    return spaces.Box(low, high, dtype=np.float32)


def piece_rows(config: EnvConfig, states: np.ndarray, masses: np.ndarray) -> dict[str, Any]:
    """
    Return the padded piece rows and their mask (observation: dict).

    states (N, 6): position (m) and velocity relative to the cone (m/s) in the cone's frame,
    in id order; masses (N,) kg. The first max_pieces_observed pieces fill the rows.
    """
    rows = config.max_pieces_observed
    count = min(rows, states.shape[0])
    low, high = piece_bounds(config)
    pieces = np.zeros((rows, len(PIECE_COLUMNS)), dtype=np.float32)
    pieces[:count, :6] = states[:count]
    pieces[:count, 6] = masses[:count]
    pieces[:count] = np.clip(pieces[:count], low, high)
    mask = np.zeros(rows, dtype=np.int8)
    mask[:count] = 1
    return {'pieces': pieces, 'mask': mask}


def decode_action(config: EnvConfig, space: spaces.Space,
                  action: Any) -> tuple[float, tuple[float, ...] | None]:
    """
    Return the target omega (rad/s) and the feed amplitudes (or None) of an action.

    Box actions are clipped into the space; a malformed action raises ValueError.
    """
    if config.action == 'discrete':
        index = int(np.asarray(action).reshape(()))
        if index not in (0, 1, 2):
            raise ValueError(f'a discrete action is 0 (cw), 1 (stop) or 2 (ccw), got '
                             f'{action!r}')
        return (index - 1) * config.discrete_omega, None
    values = np.asarray(action, dtype=np.float64).reshape(-1)
    if values.shape != space.shape or not np.all(np.isfinite(values)):
        raise ValueError(f'an action is {space.shape[0]} finite numbers, got {action!r}')
    values = np.clip(values, space.low, space.high)
    if config.normalize_actions:
        values = values + 1.0
        values[0] = (values[0] - 1.0) * config.engine.drive.max_angular_velocity
    if config.feed_amplitudes:
        return float(values[0]), tuple(float(v) for v in values[1:])
    return float(values[0]), None


def observation(config: EnvConfig, omega: float, angle: float, deficit: np.ndarray,
                hoppers: np.ndarray | None, states: np.ndarray, masses: np.ndarray) -> Any:
    """
    Return what the environment observes: a Box's array, or the Dict's mapping.

    omega (rad/s), angle (rad); deficit (channels,) kg; hoppers (heads,) kg or None;
    states (N, 6): positions (m) and velocities relative to the cone (m/s) in the cone's
    frame, in id order; masses (N,) kg.
    """
    obs = features(config, omega, angle, deficit, hoppers, states[:, 0:2], masses)
    if config.observation == 'grid':
        return obs
    return {'features': obs, **piece_rows(config, states, masses)}
