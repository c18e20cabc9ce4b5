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
:class:`ConeFeederEnv`: the cone feeder as a Gymnasium environment, on :class:`FeederEngine`.

One **step** is one control period (``control_period``, default 0.1 s = 5 ticks of 0.02 s):
the action's target angular velocity is commanded at its start and held (the drive follows
it within ``max_angular_acceleration``), the feed drops pieces, and the engine ticks.

**Actions** (``action``):

* ``omega`` (default): ``Box([-w_max], [w_max])`` float32, the target in rad/s (w_max =
  ``drive.max_angular_velocity``; values outside are clipped). With ``feed_amplitudes``
  (weigher on) the Box has ``1 + channels`` entries: the target, then each dosing channel's
  feed amplitude in [0, 2] (1 = nominal, 0 = stopped). With ``normalize_actions`` every
  entry is in [-1, 1] instead: omega / w_max, and amplitude - 1.
* ``discrete``: ``Discrete(3)``: 0 turns clockwise seen from above (-``discrete_omega``),
  1 stops, 2 turns counter-clockwise (+``discrete_omega``).

**Observations** (float32, fixed size whatever the number of pieces; every entry is scaled and
then clipped into the declared Box; ``m`` is the default product's mass, ``model.m``):

* ``omega / w_max`` in [-1, 1], then ``sin(angle)``, ``cos(angle)`` of the cone's angle;
* the channel deficits ``(target_i * t - M_i) / m`` (``t`` the episode time, ``M_i`` the mass
  that fell into channel i since the episode began), in [-obs_clip, obs_clip];
* with the weigher on, the weigh hoppers' readings / m (0: not weighed yet), in
  [0, obs_clip];
* the mass on the cone in a polar grid of ``grid.radial`` x ``grid.angular`` bins in the
  cone's frame (radial bins of equal width from the axis to the rim, angular bins from the
  cone's x axis counter-clockwise), row-major (radial outer), / m, in [0, obs_clip].

``observation: dict`` gives ``Dict(features=that Box, pieces=Box((P, 7)), mask=MultiBinary(P))``
with P = ``max_pieces_observed``: the first P pieces by id, a row each: position (m) and
velocity relative to the cone (m/s) in the cone's frame, mass (kg); rows past the pieces on
the cone are 0 with mask 0.

**Reward** of a step (every term is also in ``info``, under ``reward_<term>``):

    r = - w_distribution * mean_i((target_i * t - M_i)^2) / m^2 * control_period
        + w_packs * (packs made in the step)
        - w_giveaway * (giveaway of those packs, kg) / m

so that the distribution term is the integral over the episode of the mean squared deficit in
piece masses. The episode is truncated (``truncated=True``) after ``episode_time``; it is never
terminated (the feeder has no terminal state).

**Seeding**: ``reset(seed=s)`` seeds ``np_random``; each reset draws the engine's feed seed
and the weigher's noise seed from it, so an episode is reproduced bit for bit from its seed,
and ``reset(seed=s)`` followed by ``reset()`` gives the same two episodes every time. At
every reset the feed drops ``initial_pieces`` pieces on the still cone (a few ticks at a
high rate) before the episode's clock starts.
"""

from collections.abc import Mapping
from dataclasses import replace
import math
from pathlib import Path
from typing import Any

import gymnasium
from gymnasium import spaces
import numpy as np

from .config import EnvConfig, load_env_config
from ..errors import EnvConfigError
from ..feeder.engine import ChannelFeed, FeederEngine
from ..physics.params import P_M, PRODUCT_LIMITS

__all__ = ['ConeFeederEnv', 'observation_space', 'action_space']

#: Largest fill rate (pieces per tick, mean) of the drop of the initial pieces.
FILL_TICKS = 4
#: Most ticks the initial drop may take before a reset gives up.
MAX_FILL_TICKS = 10_000
#: Bounds of the padded piece rows (observation: dict): |x|, |y| (m), z (m), |v| (m/s).
PIECE_XY = 1.0
PIECE_Z = (-1.0, 20.0)
PIECE_SPEED = 50.0
#: Columns of a piece row.
PIECE_COLUMNS = ('x', 'y', 'z', 'vx', 'vy', 'vz', 'm')


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


class ConeFeederEnv(gymnasium.Env):
    """
    The cone feeder as a Gymnasium environment (see the module documentation).

    The arguments:

    config: the configuration: None (``config/rl.yaml``), the path of a YAML file with
    keys of ``config/rl.yaml`` (the rest keep the defaults), a mapping of such keys,
    or an :class:`~cone_feeder_sim.rl.config.EnvConfig`.
    render_mode: None (no rendering yet: issue 22 brings the view).
    **overrides: keys of ``config/rl.yaml`` merged over ``config`` (sections key by
    key), e.g. ``episode_time=10.0, interactions={'enabled': True}``.

    Raises EnvConfigError naming the key of a bad configuration.
    """

    metadata: dict[str, Any] = {'render_modes': []}

    def __init__(self, config: str | Path | Mapping[str, Any] | EnvConfig | None = None,
                 render_mode: str | None = None, **overrides: Any) -> None:
        """Validate the configuration and build the spaces; the engine starts at reset."""
        if isinstance(config, EnvConfig):
            if overrides:
                raise EnvConfigError('overrides need a file or a mapping, not an EnvConfig')
            self.config = config
        else:
            self.config = load_env_config(config, overrides)
        if render_mode is not None:
            raise EnvConfigError(f'render_mode {render_mode!r} is not available; '
                                 'render modes: none yet')
        self.render_mode = render_mode
        self.observation_space = observation_space(self.config)
        self.action_space = action_space(self.config)
        model = self.config.engine.model
        self._m_ref = model.product.m
        self._targets = np.array(self.config.channel_targets)
        self._low, self._high = feature_bounds(self.config)
        self._plow, self._phigh = piece_bounds(self.config)
        self._engine: FeederEngine | None = None
        self._steps = 0
        self._t0 = 0.0
        self._mass0 = np.zeros(model.channels.count)

    @property
    def engine(self) -> FeederEngine:
        """Return the engine of the current episode (after reset)."""
        if self._engine is None:
            raise gymnasium.error.ResetNeeded('call reset() before step()')
        return self._engine

    # ------------------------------------------------------------------ episodes

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Start an episode: a new engine seeded from np_random, the initial pieces dropped."""
        super().reset(seed=seed)
        engine_seed, weigher_seed = (int(v) for v in self.np_random.integers(
            0, 2 ** 62, size=2))
        base = self.config.engine
        count = self.config.initial_pieces
        weigher = (replace(base.weigher, seed=weigher_seed) if base.weigher is not None
                   else None)
        fill = base.feed
        if count:
            fill = replace(base.feed, rate=count / (FILL_TICKS * base.dt), max_pieces=count)
        engine = FeederEngine(replace(base, seed=engine_seed, weigher=weigher, feed=fill))
        engine.command(0.0)
        if count:
            for _ in range(MAX_FILL_TICKS):
                if engine.piece_count >= count:
                    break
                engine.tick()
            else:
                raise EnvConfigError(f'initial_pieces = {count}: the feed dropped only '
                                     f'{engine.piece_count} pieces')
            engine.reconfigure(feed=base.feed)
        self._engine = engine
        self._steps = 0
        self._t0 = engine.t
        self._mass0 = engine.channel_mass
        self._packs0 = 0
        return self._observation(), self._info(np.zeros(3), 0, 0.0, 0, 0)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Hold the action's target for a control period; return (obs, r, False, trunc, info)."""
        engine = self.engine
        omega, amplitudes = self._decode(action)
        engine.command(omega)
        if amplitudes is not None:
            engine.submit(ChannelFeed(amplitudes))
        packs, giveaway, exits, failures = 0, 0.0, 0, 0
        for _ in range(self.config.ticks):
            result = engine.tick()
            packs += len(result.packs)
            giveaway += sum(pack.giveaway for pack in result.packs)
            exits += len(result.exits)
            failures += len(result.failures)
        self._steps += 1
        terms = self._reward_terms(packs, giveaway)
        truncated = self._steps >= self.config.episode_steps
        info = self._info(terms, packs, giveaway, exits, failures)
        return self._observation(), float(terms.sum()), False, truncated, info

    def _decode(self, action: Any) -> tuple[float, tuple[float, ...] | None]:
        if self.config.action == 'discrete':
            index = int(np.asarray(action).reshape(()))
            if index not in (0, 1, 2):
                raise ValueError(f'a discrete action is 0 (cw), 1 (stop) or 2 (ccw), got '
                                 f'{action!r}')
            return (index - 1) * self.config.discrete_omega, None
        values = np.asarray(action, dtype=np.float64).reshape(-1)
        if values.shape != self.action_space.shape or not np.all(np.isfinite(values)):
            raise ValueError(f'an action is {self.action_space.shape[0]} finite numbers, got '
                             f'{action!r}')
        values = np.clip(values, self.action_space.low, self.action_space.high)
        if self.config.normalize_actions:
            values = values + 1.0
            values[0] = (values[0] - 1.0) * self.config.engine.drive.max_angular_velocity
        if self.config.feed_amplitudes:
            return float(values[0]), tuple(float(v) for v in values[1:])
        return float(values[0]), None

    # ------------------------------------------------------------------ reward and info

    def deficit(self) -> np.ndarray:
        """Return the channel deficits target_i * t - M_i (channels,) kg now."""
        engine = self.engine
        return self._targets * (engine.t - self._t0) - (engine.channel_mass - self._mass0)

    def _reward_terms(self, packs: int, giveaway: float) -> np.ndarray:
        weights = self.config.reward
        scaled = self.deficit() / self._m_ref
        return np.array([
            -weights.distribution * float(np.mean(scaled * scaled)) * self.config.control_period,
            weights.packs * packs,
            -weights.giveaway * giveaway / self._m_ref])

    def _info(self, terms: np.ndarray, packs: int, giveaway: float, exits: int,
              failures: int) -> dict[str, Any]:
        engine = self.engine
        return {
            't': engine.t - self._t0, 'omega': engine.omega, 'pieces': engine.piece_count,
            'channel_mass': engine.channel_mass - self._mass0, 'deficit': self.deficit(),
            'reward_distribution': float(terms[0]), 'reward_packs': float(terms[1]),
            'reward_giveaway': float(terms[2]), 'packs': packs, 'giveaway': giveaway,
            'exits': exits, 'failures': failures}

    # ------------------------------------------------------------------ observations

    def features(self) -> np.ndarray:
        """Return the feature vector (F,) float32 of the current state (see the module)."""
        engine = self.engine
        config = self.config
        m = self._m_ref
        parts = [np.array([engine.omega / config.engine.drive.max_angular_velocity,
                           math.sin(engine.angle), math.cos(engine.angle)]),
                 self.deficit() / m]
        if engine.weigher is not None:
            parts.append(engine.weigher.hopper_readings() / m)
        parts.append(self.mass_grid().reshape(-1) / m)
        values = np.concatenate(parts)
        return np.clip(values, self._low, self._high).astype(np.float32)

    def mass_grid(self) -> np.ndarray:
        """Return the mass on the cone (radial, angular) kg in the cone's frame."""
        state = self.engine.state
        radial, angular = self.config.grid
        x, y = state.y[:, 0], state.y[:, 1]
        rim = self.config.engine.model.r
        i = np.minimum((np.hypot(x, y) / rim * radial).astype(np.int64), radial - 1)
        phase = np.mod(np.arctan2(y, x), 2.0 * math.pi) / (2.0 * math.pi)
        j = np.minimum((phase * angular).astype(np.int64), angular - 1)
        cells = np.bincount(i * angular + j, weights=state.products[:, P_M],
                            minlength=radial * angular)
        return cells.reshape(radial, angular)

    def _observation(self) -> Any:
        features = self.features()
        if self.config.observation == 'grid':
            return features
        state = self.engine.state
        rows = self.config.max_pieces_observed
        count = min(rows, state.count)
        pieces = np.zeros((rows, len(PIECE_COLUMNS)), dtype=np.float32)
        pieces[:count, :6] = state.y[:count, :6]
        pieces[:count, 6] = state.products[:count, P_M]
        pieces[:count] = np.clip(pieces[:count], self._plow, self._phigh)
        mask = np.zeros(rows, dtype=np.int8)
        mask[:count] = 1
        return {'features': features, 'pieces': pieces, 'mask': mask}
