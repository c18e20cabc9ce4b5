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

"""Tests of rl.vector and rl.sb3: K feeders step for step as K single ones, autoreset."""

from pathlib import Path
import sys

from cone_feeder_sim.rl import ConeFeederEnv, ConeFeederVectorEnv, ENV_ID
from cone_feeder_sim.rl.config import load_env_config
from cone_feeder_sim.rl.sb3 import load_policy, SB3VecEnv
import gymnasium
from gymnasium.vector import AutoresetMode
import numpy as np
import pytest

KWARGS = {'episode_time': 0.3, 'initial_pieces': 4, 'feed': {'rate': 20.0}, 'weigher': True}


def actions(k: int, steps: int) -> list[np.ndarray]:
    rng = np.random.default_rng(5)
    return [rng.uniform(-10.0, 10.0, (k, 1)).astype(np.float32) for _ in range(steps)]


def assert_same(a, b) -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            assert_same(a[key], b[key])
    elif isinstance(a, tuple):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            assert_same(x, y)
    else:
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize('threads, contact', [(1, False), (2, False), (2, True)])
def test_native_equals_sync_step_for_step_autoreset_included(
        threads: int, contact: bool) -> None:
    # contact off: one compiled call a tick for every feeder; on: a thread per feeder
    k = 3
    kwargs = {**KWARGS, 'observation': 'dict', 'max_pieces_observed': 8,
              'interactions': {'enabled': contact}}
    native = ConeFeederVectorEnv(k, threads=threads, **kwargs)
    assert native.metadata['autoreset_mode'] == AutoresetMode.NEXT_STEP
    sync = gymnasium.vector.SyncVectorEnv([lambda: ConeFeederEnv(**kwargs)] * k,
                                          autoreset_mode=AutoresetMode.NEXT_STEP)
    assert native.observation_space == sync.observation_space
    assert native.action_space == sync.action_space
    assert_same(native.reset(seed=11), sync.reset(seed=11))
    ended = 0
    for step_actions in actions(k, 8):  # episodes of 3 steps: two autoresets each
        mine, theirs = native.step(step_actions), sync.step(step_actions)
        assert_same(mine, theirs)
        ended += int(mine[3].sum())
    assert ended == 2 * k
    native.close()
    sync.close()


def test_make_vec_returns_the_native_env_and_async_works() -> None:
    env = gymnasium.make_vec(ENV_ID, num_envs=2, **KWARGS)
    assert isinstance(env, ConeFeederVectorEnv) and env.num_envs == 2
    obs, _ = env.reset(seed=0)
    assert obs.shape == (2,) + env.single_observation_space.shape
    env.close()
    # numba's OpenMP threads cannot be forked: processes are spawned (doc/rl.md)
    asynchronous = gymnasium.make_vec(ENV_ID, num_envs=2, vectorization_mode='async',
                                      vector_kwargs={'context': 'spawn'}, **KWARGS)
    native = ConeFeederVectorEnv(2, **KWARGS)
    assert_same(asynchronous.reset(seed=3), native.reset(seed=3))
    for step_actions in actions(2, 4):
        assert_same(asynchronous.step(step_actions), native.step(step_actions))
    asynchronous.close()
    native.close()


def test_partial_reset_keeps_the_other_feeders() -> None:
    env = ConeFeederVectorEnv(2, **KWARGS)
    env.reset(seed=0)
    obs, *_ = env.step(actions(2, 1)[0])
    again, infos = env.reset(options={'reset_mask': np.array([False, True])})
    np.testing.assert_array_equal(again[0], obs[0])
    assert infos['_t'].tolist() == [False, True] and again[1][3] == 0.0  # no deficit yet
    with pytest.raises(ValueError, match='reset_mask'):
        env.reset(options={'reset_mask': np.array([False, False])})
    env.close()


def test_sb3_adapter_resets_in_the_step_with_the_terminal_observation() -> None:
    k = 2
    venv = SB3VecEnv(ConeFeederVectorEnv(k, **KWARGS))
    reference = ConeFeederVectorEnv(k, **KWARGS)
    venv.seed(21)
    obs = venv.reset()
    ref_obs, _ = reference.reset(seed=21)
    np.testing.assert_array_equal(obs, ref_obs)
    for n, step_actions in enumerate(actions(k, 6), start=1):
        obs, rewards, dones, infos = venv.step(step_actions)
        ref = reference.step(step_actions)
        assert rewards.dtype == np.float32
        np.testing.assert_array_equal(rewards, ref[1].astype(np.float32))
        if n % 3:
            assert not dones.any() and 'terminal_observation' not in infos[0]
            np.testing.assert_array_equal(obs, ref[0])
            continue
        assert dones.all()  # the episodes of 3 steps end together
        for i in range(k):
            np.testing.assert_array_equal(infos[i]['terminal_observation'], ref[0][i])
            assert infos[i]['TimeLimit.truncated'] is True
        # the next episode's first observation, as the reference's autoreset step gives it
        ref_next = reference.step(step_actions)
        np.testing.assert_array_equal(obs, ref_next[0])
        assert (ref_next[1] == 0.0).all()
    assert venv.get_attr('config')[0].episode_time == 0.3
    venv.close()
    reference.close()


def test_the_shipped_policy_loads_and_acts_in_its_environment() -> None:
    directory = Path(__file__).resolve().parents[2] / 'examples' / 'ppo_policy'
    model = load_policy(str(directory / 'policy.zip'))
    env = ConeFeederEnv(load_env_config(directory / 'env_config.yaml'))
    assert model.observation_space == env.observation_space
    obs, _ = env.reset(seed=0)
    for _ in range(3):
        action, _ = model.predict(obs, deterministic=True)
        assert env.action_space.contains(action)
        obs = env.step(action)[0]


def test_the_shipped_policy_beats_the_rule_on_a_seed() -> None:
    # what the README's comparison says, on one of its seeds and its training length: the
    # learned policy earns more reward than example_controller's rule (seed 0: about -156
    # against -434)
    directory = Path(__file__).resolve().parents[2] / 'examples'
    sys.path.insert(0, str(directory))
    try:
        import train_ppo
    finally:
        sys.path.remove(str(directory))
    model = load_policy(str(directory / 'ppo_policy' / 'policy.zip'))
    episode = train_ppo.ENV_CONFIG['episode_time']
    learned = train_ppo.evaluate(lambda env: train_ppo.ppo_policy(model), [0], episode)
    rule = train_ppo.evaluate(train_ppo.rule_policy, [0], episode)
    assert learned['reward'] > rule['reward'] + 100.0, (learned, rule)
    assert learned['distribution error'] < rule['distribution error']
