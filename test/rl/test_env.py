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

"""Tests of rl.env: the Gymnasium contract, seeding, observations and the reward."""

import math
import subprocess
import sys
import warnings

from cone_feeder_sim.errors import EnvConfigError
from cone_feeder_sim.physics.params import P_M
from cone_feeder_sim.rl import ConeFeederEnv, ENV_ID
from cone_feeder_sim.rl.env import FRAME_SIZE
from cone_feeder_sim.view.frame import PALETTE
import gymnasium
from gymnasium.utils.env_checker import check_env
import numpy as np
import pytest

#: The check_env advice for Box actions outside [-1, 1] (the rad/s action): not a defect.
NORMALIZE_ADVICE = 'we recommend using a symmetric and normalized space'
SHORT = {'episode_time': 0.5, 'initial_pieces': 6}


def caught(function, *args, **kwargs) -> list[str]:
    with warnings.catch_warnings(record=True) as found:
        warnings.simplefilter('always')
        function(*args, **kwargs)
    return [str(w.message) for w in found]


@pytest.mark.parametrize('variant', [
    {},
    {'action': 'discrete'},
    {'observation': 'dict', 'max_pieces_observed': 4},
    {'weigher': True, 'feed_amplitudes': True},
    {'weigher': True, 'feed_amplitudes': True, 'observation': 'dict'},
    {'interactions': {'enabled': True}},
    {'normalize_actions': False},
])
def test_check_env_passes_without_warnings(variant: dict) -> None:
    env = ConeFeederEnv(**SHORT, **variant)
    messages = caught(check_env, env, skip_render_check=True)
    rad_per_s_box = variant.get('action', 'omega') == 'omega' and not variant.get(
        'normalize_actions', True)
    if rad_per_s_box:  # the option of a Box in rad/s: only this advice
        assert len(messages) == 1 and NORMALIZE_ADVICE in messages[0], messages
    else:
        assert messages == []
    # the passive checker that gymnasium.make wraps around every environment: silent
    made = gymnasium.make(ENV_ID, **SHORT, **variant)
    made.action_space.seed(1)
    assert caught(lambda: [made.reset(seed=1), *[made.step(made.action_space.sample())
                                                 for _ in range(5)]]) == []
    assert made.observation_space == env.observation_space


def test_make_by_module_path_in_a_fresh_interpreter() -> None:
    code = '\n'.join([
        'import gymnasium',
        "env = gymnasium.make('cone_feeder_sim.rl:ConeFeeder-v0', episode_time=0.2)",
        'env.reset(seed=0)',
        "vector = gymnasium.make_vec('cone_feeder_sim/ConeFeeder-v0', num_envs=2)",
        'print(type(env.unwrapped).__name__, type(vector).__name__)'])
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=300, check=True).stdout.split()
    assert out == ['ConeFeederEnv', 'ConeFeederVectorEnv']


def run(env: ConeFeederEnv, seed: int | None, steps: int, action_seed: int) -> list:
    """Return every (obs, reward, terminated, truncated, info) of a seeded random run."""
    out = [env.reset(seed=seed)]
    env.action_space.seed(action_seed)
    for _ in range(steps):
        out.append(env.step(env.action_space.sample()))
    return out


def same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return np.array_equal(np.asarray(a), np.asarray(b))


def test_seeded_episodes_are_identical_and_seeds_matter() -> None:
    kwargs = {'episode_time': 0.6, 'initial_pieces': 5, 'weigher': True,
              'feed_amplitudes': True, 'feed': {'rate': 20.0}, 'observation': 'dict'}
    first, second = ConeFeederEnv(**kwargs), ConeFeederEnv(**kwargs)
    a = run(first, 7, 6, 0) + run(first, None, 6, 1)  # reset(seed) then reset()
    b = run(second, 7, 6, 0) + run(second, None, 6, 1)
    assert same(a, b)
    masses = a[6][0]['pieces'][:, 6]
    assert np.count_nonzero(masses) > 5 and len(set(masses[masses > 0])) > 5  # drawn masses
    other = run(ConeFeederEnv(**kwargs), 8, 6, 0)
    assert not same(a[:7], other)
    # the second episode differs from the first (the generator moved on)
    assert not same(a[0][0], a[7][0])


def test_observations_stay_in_their_space_with_contact_on() -> None:
    env = ConeFeederEnv(initial_pieces=12, episode_time=2.0, interactions={'enabled': True},
                        feed={'rate': 10.0}, observation='dict', max_pieces_observed=16)
    steps = run(env, 3, 20, 3)
    for obs, *_ in steps:
        assert env.observation_space.contains(obs)
    obs, _, terminated, truncated, info = steps[-1]
    assert truncated and not terminated and info['pieces'] > 16  # more pieces than rows
    assert obs['mask'].sum() == 16 and info['failures'] == 0
    assert [s[3] for s in steps[1:-1]] == [False] * 19  # truncated at episode_time only
    assert env.mass_grid().sum() == pytest.approx(env.engine.state.products[:, P_M].sum())


def test_observation_layout_by_hand() -> None:
    env = ConeFeederEnv(episode_time=1.0, feed={'rate': 0.0}, grid={'radial': 2, 'angular': 4})
    env.reset(seed=0)
    engine = env.engine
    # two pieces placed by hand in the cone's frame (the cone is at angle 0, still)
    engine.spawn([[0.05, 0.02, 0.1], [-0.15, -0.01, 0.08]])
    obs, *_ = env.step(np.array([0.0], dtype=np.float32))
    m = engine.model.product.m
    assert obs[0] == 0.0 and obs[1] == 0.0 and obs[2] == 1.0  # omega, sin, cos
    np.testing.assert_allclose(obs[3:17], 0.0446 * 0.1 / m, rtol=1e-6)  # nothing fell yet
    grid = obs[17:].reshape(2, 4)
    expected = np.zeros((2, 4))
    expected[0, 0] = 1.0  # rho 0.054 < r / 2, angle 22 deg
    expected[1, 2] = 1.0  # rho 0.150 > r / 2, angle 184 deg
    np.testing.assert_allclose(grid, expected, rtol=1e-6)


def test_rewards_match_a_hand_computation() -> None:
    # no pieces, the cone still: every deficit is target * t, nothing else happens
    weights = {'distribution': 2.0, 'packs': 3.0, 'giveaway': 5.0}
    env = ConeFeederEnv(episode_time=0.3, feed={'rate': 0.0}, reward=weights,
                        channel_targets=[0.01 * (i + 1) for i in range(14)])
    env.reset(seed=0)
    m = env.config.engine.model.product.m
    for k in (1, 2, 3):
        _, reward, _, truncated, info = env.step(np.array([0.0], dtype=np.float32))
        t = 0.1 * k
        hand = -2.0 * sum((0.01 * (i + 1) * t / m) ** 2 for i in range(14)) / 14 * 0.1
        assert reward == pytest.approx(hand, rel=1e-12)
        assert info['reward_distribution'] == reward and info['t'] == pytest.approx(t)
    assert truncated
    # with the feed and the weigher: the terms add up, packs and giveaway as the machine says
    env = ConeFeederEnv(episode_time=12.0, weigher={'target': 0.25}, reward=weights,
                        feed={'rate': 20.0}, initial_pieces=20)
    env.reset(seed=4)
    total_packs, total_giveaway, mass = 0, 0.0, 0.0
    done = False
    while not done:
        _, reward, _, done, info = env.step(np.array([-6.0], dtype=np.float32))
        deficit = np.array(env.config.channel_targets) * info['t'] - info['channel_mass']
        hand = (-2.0 * np.mean((deficit / m) ** 2) * 0.1 + 3.0 * info['packs']
                - 5.0 * info['giveaway'] / m)
        assert reward == pytest.approx(hand, rel=1e-12, abs=1e-15)
        total_packs += info['packs']
        total_giveaway += info['giveaway']
        mass = info['channel_mass'].sum()
    stats = env.engine.weigher.stats()
    assert total_packs == stats.packs > 0
    assert total_giveaway == pytest.approx(stats.giveaway_mean * stats.packs, rel=1e-9)
    exits = env.engine.channel_mass.sum()
    assert mass == pytest.approx(exits) and mass > 0.0


def test_discrete_and_amplitude_actions_reach_the_engine() -> None:
    env = ConeFeederEnv(episode_time=1.0, action='discrete', discrete_omega=4.0,
                        feed={'rate': 0.0})
    env.reset(seed=0)
    omegas = [env.step(a)[4]['omega'] for a in (2, 2, 1, 0, 0, 0)]
    assert omegas[:2] == [2.0, 4.0]  # 20 rad/s^2 over 0.1 s, then held at +4
    assert omegas[2] == pytest.approx(2.0) and omegas[5] == pytest.approx(-4.0)
    with pytest.raises(ValueError, match='a discrete action is 0'):
        env.step(3)
    env = ConeFeederEnv(episode_time=1.0, weigher=True, feed_amplitudes=True,
                        normalize_actions=True, feed={'rate': 0.0})
    env.reset(seed=0)
    action = np.full(15, -1.0, dtype=np.float32)
    action[0] = 0.5
    info = env.step(action)[4]
    assert info['omega'] == pytest.approx(2.0)  # ramping towards 0.5 * 10.47
    np.testing.assert_array_equal(env.engine.weigher.amplitude, 0.0)
    with pytest.raises(ValueError, match='15 finite numbers'):
        env.step(np.zeros(3, dtype=np.float32))


def test_step_before_reset_and_render_mode() -> None:
    env = ConeFeederEnv(episode_time=1.0)
    with pytest.raises(gymnasium.error.ResetNeeded):
        env.step(np.zeros(1, dtype=np.float32))
    with pytest.raises(EnvConfigError, match="render_mode 'ansi' is not available"):
        ConeFeederEnv(render_mode='ansi')
    assert math.isfinite(env.config.episode_time)


def test_rgb_array_frames_show_the_pieces() -> None:
    env = ConeFeederEnv(render_mode='rgb_array', initial_pieces=10, episode_time=1.0)
    assert env.metadata['render_fps'] == 10.0
    env.reset(seed=3)
    env.step(env.action_space.sample())
    frame = env.render()
    assert frame.shape == (FRAME_SIZE, FRAME_SIZE, 3) and frame.dtype == np.uint8
    red = np.all(frame == PALETTE[0], axis=2).sum()
    # ten discs of radius s0 = 25 mm, the rim at 0.9 of the half-width, some overlap
    disc = math.pi * (0.025 / env.config.engine.model.r * 0.45 * FRAME_SIZE) ** 2
    assert 4 * disc < red <= 10 * disc * 1.1
    assert ConeFeederEnv(initial_pieces=0).render() is None
