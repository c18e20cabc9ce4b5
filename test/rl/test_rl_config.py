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

"""Tests of rl.config: the defaults load, bad configuration is refused with the key named."""

from pathlib import Path

from cone_feeder_sim.errors import EnvConfigError
from cone_feeder_sim.rl.config import load_env_config
import pytest


def test_defaults_and_overrides() -> None:
    config = load_env_config()
    assert (config.ticks, config.episode_steps, config.engine.dt) == (5, 300, 0.02)
    assert config.engine.drive.cmd_timeout == 0.0  # the action is held, never timed out
    assert len(config.channel_targets) == config.engine.model.channels.count == 14
    assert config.engine.weigher is None and not config.engine.model.interactions.enabled
    changed = load_env_config({'feed': {'rate': 8.0}, 'weigher': {'target': 0.5}},
                              {'control_period': 0.2, 'episode_time': 1.0})
    assert changed.engine.feed.rate == 8.0 and changed.engine.feed.rho_max == 0.15  # merged
    assert changed.engine.weigher.target == 0.5
    assert (changed.ticks, changed.episode_steps) == (10, 5)
    assert load_env_config(None, {'channel_targets': [0.01] * 14}).channel_targets[3] == 0.01


def test_a_file_with_some_keys(tmp_path: Path) -> None:
    path = tmp_path / 'my_rl.yaml'
    path.write_text('episode_time: 2.0\ninteractions: {enabled: true}\n')
    config = load_env_config(path)
    assert config.episode_time == 2.0 and config.engine.model.interactions.enabled
    assert config.engine.feed.rate == 5.0  # the rest from config/rl.yaml
    path.write_text('episode_tme: 2.0\n')
    with pytest.raises(EnvConfigError, match="'episode_tme'"):
        load_env_config(path)


@pytest.mark.parametrize('overrides, fragment', [
    ({'episode_tme': 1.0}, "unknown configuration key(s) 'episode_tme'"),
    ({'feed': {'speed': 1.0}}, "unknown feed key(s) 'speed'"),
    ({'reward': {'pack': 1.0}}, "unknown reward key(s) 'pack'"),
    ({'grid': {'rings': 3}}, "unknown grid key(s) 'rings'"),
    ({'drive': {'cmd_timeout': 1.0}}, "unknown drive key(s) 'cmd_timeout'"),
    ({'channel_targets': []}, 'channel_targets must not be empty'),
    ({'channel_targets': [0.1, 0.2]}, 'channel_targets needs 14 numbers'),
    ({'channel_targets': 0.0}, 'channel_targets are all 0'),
    ({'channel_targets': -0.1}, "'channel_targets'"),
    ({'control_period': 0.01}, 'control_period = 0.01 s is shorter than a tick (dt = 0.02 s)'),
    ({'control_period': 0.05}, 'control_period = 0.05 s must be a whole number of ticks'),
    ({'dt': 0.0}, "'dt'"),
    ({'episode_time': -1.0}, "'episode_time'"),
    ({'feed': {'seed': 3}}, 'feed.seed is not a setting here'),
    ({'weigher': {'seed': 3}}, 'weigher.seed is not a setting here'),
    ({'weigher': 'yes'}, 'weigher must be false'),
    ({'feed': {'rho_max': 0.3}}, 'feed.rho_max = 0.3 m must be inside the cone'),
    ({'action': 'torque'}, 'action must be one of omega, discrete'),
    ({'observation': 'image'}, 'observation must be one of grid, dict'),
    ({'feed_amplitudes': True}, 'feed_amplitudes needs the weigher'),
    ({'feed_amplitudes': True, 'weigher': True, 'action': 'discrete'},
     'feed_amplitudes needs action: omega'),
    ({'normalize_actions': 1}, 'normalize_actions must be true or false'),
    ({'grid': {'radial': 0}}, "'grid.radial'"),
    ({'reward': {'packs': -1.0}}, "'reward.packs'"),
    ({'initial_pieces': 500}, 'initial_pieces = 500 exceeds feed.max_pieces = 200'),
    ({'model': {'d': -1.0}}, "'d' = -1 is out of range"),
    ({'interactions': {'coupling': 'loose'}}, 'interactions.coupling'),
])
def test_bad_configuration_names_the_key(overrides: dict, fragment: str) -> None:
    with pytest.raises(EnvConfigError) as info:
        load_env_config(overrides)
    assert fragment in str(info.value)
