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

* ``omega`` (default): ``Box([-1], [1])`` float32, the target over w_max
  (``drive.max_angular_velocity``; values outside are clipped). With ``feed_amplitudes``
  (weigher on) the Box has ``1 + channels`` entries: the target, then each dosing channel's
  feed amplitude minus 1, also in [-1, 1] (amplitude 1 = nominal, 0 = stopped). With
  ``normalize_actions: false`` the entries are the target in rad/s, in [-w_max, w_max],
  and the amplitudes in [0, 2].
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
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np

from .config import EnvConfig, load_env_config
from .spaces import (
    action_space, decode_action, features, mass_grid, observation, observation_space)
from ..errors import EnvConfigError
from ..feeder.engine import ChannelFeed, FeederEngine, TickResult
from ..feeder.realtime import RealTime
from ..physics.params import P_M, P_S0
from ..physics.simulation import world_from_cone
from ..view.frame import top_view
from ..view.live import DEFAULT_PORT, LiveView

__all__ = ['ConeFeederEnv']

#: Largest fill rate (pieces per tick, mean) of the drop of the initial pieces.
FILL_TICKS = 4
#: Side (pixels) of the frames of render_mode 'rgb_array'.
FRAME_SIZE = 256
#: Most ticks the initial drop may take before a reset gives up.
MAX_FILL_TICKS = 10_000


class ConeFeederEnv(gymnasium.Env):
    """
    The cone feeder as a Gymnasium environment (see the module documentation).

    The arguments:

    config: the configuration: None (``config/rl.yaml``), the path of a YAML file with
    keys of ``config/rl.yaml`` (the rest keep the defaults), a mapping of such keys,
    or an :class:`~cone_feeder_sim.rl.config.EnvConfig`.
    render_mode: None; 'rgb_array': :meth:`render` returns a top view of the cone
    (FRAME_SIZE x FRAME_SIZE x 3 uint8, :func:`~cone_feeder_sim.view.frame.top_view`);
    'human': the episodes are served live on a Foxglove WebSocket
    (:class:`~cone_feeder_sim.view.live.LiveView`, needs foxglove-sdk) on ``view_port``
    (0: any free one; :attr:`view`), paced to real time; :meth:`close` stops it.
    **overrides: keys of ``config/rl.yaml`` merged over ``config`` (sections key by
    key), e.g. ``episode_time=10.0, interactions={'enabled': True}``.

    Raises EnvConfigError naming the key of a bad configuration.
    """

    metadata: dict[str, Any] = {'render_modes': ['rgb_array', 'human']}

    def __init__(self, config: str | Path | Mapping[str, Any] | EnvConfig | None = None,
                 render_mode: str | None = None, *, view_port: int = DEFAULT_PORT,
                 **overrides: Any) -> None:
        """Validate the configuration and build the spaces; the engine starts at reset."""
        if isinstance(config, EnvConfig):
            if overrides:
                raise EnvConfigError('overrides need a file or a mapping, not an EnvConfig')
            self.config = config
        else:
            self.config = load_env_config(config, overrides)
        if render_mode not in (None, *self.metadata['render_modes']):
            raise EnvConfigError(f'render_mode {render_mode!r} is not available; render '
                                 f'modes: {", ".join(self.metadata["render_modes"])}')
        self.render_mode = render_mode
        self.view: LiveView | None = None
        if render_mode == 'human':
            self.view = LiveView(self.config.engine.model, port=view_port)
        self._pace = RealTime(1.0)
        self.metadata = {**self.metadata, 'render_fps': 1.0 / self.config.control_period}
        self.observation_space = observation_space(self.config)
        self.action_space = action_space(self.config)
        model = self.config.engine.model
        self._m_ref = model.product.m
        self._targets = np.array(self.config.channel_targets)
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
        if self.view is not None:
            self.view.watch(engine)  # shows every tick of the episode
            self._pace.restart()
            self.render()
        return self._observation(), self._info(np.zeros(3), 0, 0.0, 0, 0)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Hold the action's target for a control period; return (obs, r, False, trunc, info)."""
        self.act(action)
        return self.outcome([self.engine.tick() for _ in range(self.config.ticks)])

    def act(self, action: Any) -> None:
        """Queue the action's inputs for the next tick (the first half of :meth:`step`)."""
        engine = self.engine
        omega, amplitudes = decode_action(self.config, self.action_space, action)
        engine.command(omega)
        if amplitudes is not None:
            engine.submit(ChannelFeed(amplitudes))

    def outcome(self, results: list[TickResult]) -> tuple[Any, float, bool, bool,
                                                          dict[str, Any]]:
        """Return the step's (obs, r, False, trunc, info) from its ticks' results."""
        packs = sum(len(result.packs) for result in results)
        giveaway = sum(pack.giveaway for result in results for pack in result.packs)
        exits = sum(len(result.exits) for result in results)
        failures = sum(len(result.failures) for result in results)
        self._steps += 1
        if self.render_mode == 'human':
            self.render()
        terms = self._reward_terms(packs, giveaway)
        truncated = self._steps >= self.config.episode_steps
        info = self._info(terms, packs, giveaway, exits, failures)
        return self._observation(), float(terms.sum()), False, truncated, info

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

    def render(self) -> np.ndarray | None:
        """
        Return the top view (FRAME_SIZE, FRAME_SIZE, 3) uint8 with 'rgb_array', else None.

        With 'human' the live view shows every tick by itself; this waits for the wall
        clock (called by reset and step).
        """
        if self.view is not None:
            self._pace(self.engine.t)
            return None
        if self.render_mode != 'rgb_array':
            return None
        engine = self.engine
        state = engine.state
        model = self.config.engine.model
        positions = world_from_cone(state.y, engine.angle, engine.omega)[0][:, :2]
        return top_view(positions, state.products[:, P_S0], np.zeros(state.count, dtype=int),
                        model.r, model.channels, engine.angle, FRAME_SIZE)

    def close(self) -> None:
        """Stop the live view of render_mode 'human' (nothing else to release)."""
        if self.view is not None:
            self.view.close()
        super().close()

    def features(self) -> np.ndarray:
        """Return the feature vector (F,) float32 of the current state (see the module)."""
        engine = self.engine
        state = engine.state
        hoppers = engine.weigher.hopper_readings() if engine.weigher is not None else None
        return features(self.config, engine.omega, engine.angle, self.deficit(), hoppers,
                        state.y[:, 0:2], state.products[:, P_M])

    def mass_grid(self) -> np.ndarray:
        """Return the mass on the cone (radial, angular) kg in the cone's frame."""
        state = self.engine.state
        return mass_grid(self.config, state.y[:, 0:2], state.products[:, P_M])

    def _observation(self) -> Any:
        engine = self.engine
        state = engine.state
        hoppers = engine.weigher.hopper_readings() if engine.weigher is not None else None
        return observation(self.config, engine.omega, engine.angle, self.deficit(), hoppers,
                           state.y[:, 0:6], state.products[:, P_M])
