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
The configuration of the reinforcement-learning environment: ``config/rl.yaml``, validated.

Every key and its meaning is in ``config/rl.yaml`` (the defaults) and in
:class:`EnvConfig`. A configuration is a mapping with the file's keys; a mapping given to the
environment is merged over the default file (sections key by key), so that
``ConeFeederEnv(episode_time=10.0, feed={'rate': 8.0})`` changes two values. Unknown keys,
wrong types and values out of range raise :class:`~cone_feeder_sim.errors.EnvConfigError`
naming the key (``feed.rate``, ``reward.packs``, ``control_period``).
"""

from collections.abc import Mapping
from dataclasses import dataclass, replace
import math
from pathlib import Path
from typing import Any

from ..errors import ConeFeederError, EnvConfigError
from ..feeder.engine import DriveParams, EngineConfig
from ..feeder.feed import check_feed_fits, feed_from_mapping, FEED_KEYS
from ..formats.parameter_file import config_dir, load_model_params, load_weigher_params, read_yaml
from ..physics.params import (
    check_integer, check_number, check_section, interaction_params_from_mapping, Limit,
    solver_params_from_mapping)
from ..weigher.machine import check_machine

__all__ = ['ACTIONS', 'DEFAULT_ENV_FILE', 'EnvConfig', 'env_config_from_mapping',
           'load_env_config', 'OBSERVATIONS', 'RewardWeights']

#: The file of the defaults, in the package's config directory.
DEFAULT_ENV_FILE = 'rl.yaml'
#: The action variants: a target omega (Box, rad/s) or cw / stop / ccw (Discrete(3)).
ACTIONS = ('omega', 'discrete')
#: The observation variants: one Box, or a Dict with the padded pieces and their mask.
OBSERVATIONS = ('grid', 'dict')

#: The top-level keys of a configuration, and those of its sections.
ENV_KEYS = ('parameters', 'model', 'interactions', 'solver', 'dt', 'control_period',
            'episode_time', 'initial_pieces', 'drive', 'feed', 'weigher', 'channel_targets',
            'action', 'discrete_omega', 'feed_amplitudes', 'normalize_actions', 'observation',
            'grid',
            'max_pieces_observed', 'obs_clip', 'reward')
DRIVE_KEYS = ('max_angular_velocity', 'max_angular_acceleration')
GRID_KEYS = ('radial', 'angular')
REWARD_KEYS = ('distribution', 'packs', 'giveaway')

#: Allowed ranges of the environment's own settings.
ENV_LIMITS: dict[str, Limit] = {
    'dt': Limit(0.0, 1.0, 's', lo_open=True),
    'control_period': Limit(0.0, 60.0, 's', lo_open=True),
    'episode_time': Limit(0.0, 1.0e6, 's', lo_open=True),
    'initial_pieces': Limit(0, 10 ** 5, ''),
    'channel_target': Limit(0.0, 100.0, 'kg/s'),
    'discrete_omega': Limit(0.0, 100.0, 'rad/s', lo_open=True),
    'grid': Limit(1, 1000, ''),
    'max_pieces_observed': Limit(1, 10 ** 5, ''),
    'obs_clip': Limit(0.0, 1.0e9, '', lo_open=True),
    'reward': Limit(0.0, 1.0e9, ''),
}
#: Relative slack within which control_period counts as a multiple of dt.
PERIOD_TOLERANCE = 1.0e-9


@dataclass(frozen=True)
class RewardWeights:
    """
    The weights of the reward's terms (all >= 0; a term with weight 0 is still in info).

    distribution: of the mean squared channel deficit (in piece masses squared) integrated
    over the control period (s); packs: per pack made; giveaway: per piece mass of
    giveaway (mass of the packs above the target). See :mod:`cone_feeder_sim.rl.env`.
    """

    distribution: float = 1.0
    packs: float = 0.0
    giveaway: float = 0.0


@dataclass(frozen=True, eq=False)
class EnvConfig:
    """
    A validated environment configuration.

    engine: the feeder (model with contact settings, solver, dt, drive with cmd_timeout 0,
    feed; its seed and the weigher's seed are replaced at every reset from the
    environment's ``np_random``); control_period (s) the time a target is held, a whole
    number ``ticks`` of dt; episode_time (s) after which an episode is truncated;
    initial_pieces dropped by the feed at every reset before the episode starts;
    channel_targets (channels,) kg/s; action 'omega' or 'discrete'; discrete_omega (rad/s)
    the speed of the discrete cw / ccw actions; feed_amplitudes: the channel feed amplitudes
    are actions too (weigher on, action 'omega'); normalize_actions: the Box is [-1, 1] in
    every entry (omega / max_angular_velocity, amplitude - 1) instead of rad/s; observation
    'grid' or 'dict'; grid (radial, angular) bins of the mass grid; max_pieces_observed:
    rows of the padded piece array ('dict'); obs_clip: bound of the scaled observations;
    reward: the weights.
    """

    engine: EngineConfig
    control_period: float = 0.1
    episode_time: float = 30.0
    initial_pieces: int = 0
    channel_targets: tuple[float, ...] = ()
    action: str = 'omega'
    discrete_omega: float = 5.0
    feed_amplitudes: bool = False
    normalize_actions: bool = True
    observation: str = 'grid'
    grid: tuple[int, int] = (4, 8)
    max_pieces_observed: int = 64
    obs_clip: float = 100.0
    reward: RewardWeights = RewardWeights()

    @property
    def ticks(self) -> int:
        """Return the engine ticks per control period."""
        return int(round(self.control_period / self.engine.dt))

    @property
    def episode_steps(self) -> int:
        """Return the control periods of an episode (the last ends at or after episode_time)."""
        return max(1, math.ceil(self.episode_time / self.control_period * (1.0 - 1e-12)))


def _section(content: Mapping[str, Any], key: str, keys: tuple[str, ...]) -> Mapping[str, Any]:
    value = content.get(key)
    return {} if value is None else check_section(key, value, keys)


def _choice(key: str, value: Any, choices: tuple[str, ...]) -> str:
    if value not in choices:
        raise EnvConfigError(f'{key} must be one of {", ".join(choices)}, got {value!r}')
    return str(value)


def _flag(key: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise EnvConfigError(f'{key} must be true or false, got {value!r}')
    return value


def _targets(value: Any, channels: int) -> tuple[float, ...]:
    if isinstance(value, (list, tuple)):
        if not value:
            raise EnvConfigError(f'channel_targets must not be empty: one number (kg/s, every '
                                 f'channel) or {channels} numbers (one per channel)')
        if len(value) != channels:
            raise EnvConfigError(f'channel_targets needs {channels} numbers (one per channel) '
                                 f'or one number, got {len(value)}')
        values = [check_number(f'channel_targets[{i}]', v, ENV_LIMITS['channel_target'])
                  for i, v in enumerate(value)]
    elif value is None:
        raise EnvConfigError('channel_targets must be given: kg/s per channel')
    else:
        values = [check_number('channel_targets', value, ENV_LIMITS['channel_target'])] * channels
    if not any(values):
        raise EnvConfigError('channel_targets are all 0: give at least one channel a target '
                             '(kg/s)')
    return tuple(values)


def merged(base: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Return base with overrides: sections (mappings) merged key by key, others replaced."""
    result = dict(base)
    for key, value in overrides.items():
        if isinstance(value, Mapping) and isinstance(result.get(key), Mapping):
            result[key] = {**result[key], **value}
        else:
            result[key] = value
    return result


def env_config_from_mapping(content: Any, base_dir: Path | None = None) -> EnvConfig:
    """Validate a whole configuration mapping; raise EnvConfigError naming the key."""
    _check_top(content, 'the configuration')
    try:
        return _build(content, base_dir)
    except EnvConfigError:
        raise
    except ConeFeederError as exc:
        raise EnvConfigError(str(exc)) from exc


def _build(content: Mapping[str, Any], base_dir: Path | None) -> EnvConfig:
    param_file = content.get('parameters')
    if param_file is not None:
        param_file = Path(str(param_file))
        if not param_file.is_absolute() and base_dir is not None:
            param_file = base_dir / param_file
    overrides = content.get('model') or {}
    if not isinstance(overrides, Mapping):
        raise EnvConfigError(f'model must be a mapping of parameter overrides, got '
                             f'{overrides!r}')
    model = load_model_params(param_file, overrides)
    if content.get('interactions') is not None:
        model = replace(model, interactions=interaction_params_from_mapping(
            content['interactions'], model.interactions))
    solver = solver_params_from_mapping(content.get('solver'))
    dt = check_number('dt', content.get('dt', 0.02), ENV_LIMITS['dt'])
    period = check_number('control_period', content.get('control_period', 0.1),
                          ENV_LIMITS['control_period'])
    ticks = round(period / dt)
    if period < dt * (1.0 - PERIOD_TOLERANCE):
        raise EnvConfigError(f'control_period = {period:g} s is shorter than a tick '
                             f'(dt = {dt:g} s)')
    if abs(ticks * dt - period) > PERIOD_TOLERANCE * period:
        raise EnvConfigError(f'control_period = {period:g} s must be a whole number of ticks '
                             f'(dt = {dt:g} s)')
    drive_section = _section(content, 'drive', DRIVE_KEYS)
    drive = DriveParams(cmd_timeout=0.0, **drive_section)
    for section in ('feed', 'weigher'):
        if isinstance(content.get(section), Mapping) and 'seed' in content[section]:
            raise EnvConfigError(f'{section}.seed is not a setting here: every seed comes '
                                 "from reset(seed=...) (the environment's np_random)")
    feed = feed_from_mapping(_section(content, 'feed', FEED_KEYS[:-1]))[0]
    check_feed_fits(model, feed)
    weigher = None
    section = content.get('weigher')
    if section is True or isinstance(section, Mapping):
        weigher = load_weigher_params(overrides=section if section is not True else {})
        check_machine(weigher, model.channels.count)
    elif section not in (None, False):
        raise EnvConfigError(f'weigher must be false (off), true (the default machine of '
                             f'config/weigher.yaml) or a mapping of its keys, got {section!r}')
    initial = check_integer('initial_pieces', content.get('initial_pieces', 0),
                            ENV_LIMITS['initial_pieces'])
    if initial > feed.max_pieces:
        raise EnvConfigError(f'initial_pieces = {initial} exceeds feed.max_pieces = '
                             f'{feed.max_pieces}')
    engine = EngineConfig(model=model, solver=solver, dt=dt, drive=drive, feed=feed,
                          weigher=weigher)
    action = _choice('action', content.get('action', 'omega'), ACTIONS)
    amplitudes = _flag('feed_amplitudes', content.get('feed_amplitudes', False))
    if amplitudes and weigher is None:
        raise EnvConfigError('feed_amplitudes needs the weigher (weigher: true is the default '
                             "machine): the amplitudes are its dosing channels'")
    if amplitudes and action != 'omega':
        raise EnvConfigError('feed_amplitudes needs action: omega (a Box of omega and the '
                             'amplitudes)')
    grid_section = _section(content, 'grid', GRID_KEYS)
    grid = (check_integer('grid.radial', grid_section.get('radial', 4), ENV_LIMITS['grid']),
            check_integer('grid.angular', grid_section.get('angular', 8), ENV_LIMITS['grid']))
    reward_section = _section(content, 'reward', REWARD_KEYS)
    reward = RewardWeights(**{k: check_number(f'reward.{k}', v, ENV_LIMITS['reward'])
                              for k, v in reward_section.items()})
    return EnvConfig(
        engine=engine, control_period=ticks * dt, initial_pieces=initial,
        episode_time=check_number('episode_time', content.get('episode_time', 30.0),
                                  ENV_LIMITS['episode_time']),
        channel_targets=_targets(content.get('channel_targets'), model.channels.count),
        action=action,
        discrete_omega=check_number('discrete_omega', content.get('discrete_omega', 5.0),
                                    ENV_LIMITS['discrete_omega']),
        feed_amplitudes=amplitudes,
        normalize_actions=_flag('normalize_actions', content.get('normalize_actions', True)),
        observation=_choice('observation', content.get('observation', 'grid'), OBSERVATIONS),
        grid=grid,
        max_pieces_observed=check_integer('max_pieces_observed',
                                          content.get('max_pieces_observed', 64),
                                          ENV_LIMITS['max_pieces_observed']),
        obs_clip=check_number('obs_clip', content.get('obs_clip', 100.0), ENV_LIMITS['obs_clip']),
        reward=reward)


def load_env_config(source: str | Path | Mapping[str, Any] | None = None,
                    overrides: Mapping[str, Any] | None = None) -> EnvConfig:
    """
    Return the configuration: the default file, or a file, or a mapping over the defaults.

    source: a path to a YAML file with the keys of ``config/rl.yaml`` (keys it leaves out
    keep the defaults of that file), a mapping of such keys, or None (the defaults);
    overrides: keys merged over it (sections key by key).
    """
    default_path = config_dir() / DEFAULT_ENV_FILE
    content = read_yaml(default_path)
    base_dir = default_path.parent
    if isinstance(source, (str, Path)):
        path = Path(source)
        try:
            loaded = read_yaml(path)
        except ConeFeederError as exc:
            raise EnvConfigError(str(exc)) from exc
        _check_top(loaded, str(path))
        content, base_dir = merged(content, loaded), path.parent
    elif isinstance(source, Mapping):
        _check_top(source, 'the configuration')
        content = merged(content, source)
    elif source is not None:
        raise EnvConfigError(f'config must be a file name, a mapping or None, got {source!r}')
    if overrides:
        _check_top(overrides, 'the arguments')
        content = merged(content, overrides)
    return env_config_from_mapping(content, base_dir)


def _check_top(content: Any, where: str) -> None:
    """Refuse a configuration (from ``where``) that is no mapping or has unknown keys."""
    try:
        check_section('configuration', content, ENV_KEYS)
    except ConeFeederError as exc:
        raise EnvConfigError(f'{where}: {exc}') from None
