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

"""Tests of policy_controller: the observation from the topics, and a policy driving sim_node."""

from pathlib import Path
import time

from cone_feeder_sim.errors import ConeFeederError
from cone_feeder_sim.formats.messages import header, states_message
from cone_feeder_sim.formats.pointcloud import cloud_points
from cone_feeder_sim.physics.params import P_M
from cone_feeder_sim.physics.simulation import world_from_cone
from cone_feeder_sim.rl import ConeFeederEnv
from cone_feeder_sim.ros.policy_controller import observe, PolicyController
from cone_feeder_sim.ros.sim_node import SimNode
import numpy as np
import pytest
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from stable_baselines3 import PPO
import yaml


@pytest.mark.parametrize('variant', [{}, {'observation': 'dict', 'weigher': True}])
def test_the_topics_give_the_environments_observation(variant: dict) -> None:
    env = ConeFeederEnv(episode_time=2.0, initial_pieces=8, feed={'rate': 10.0}, **variant)
    env.reset(seed=2)
    for omega in (3.0, 3.0, -2.0):
        obs, *_ = env.step(np.array([omega], dtype=np.float32))
    engine = env.engine
    state = engine.state
    q, qdot, _ = world_from_cone(state.y, engine.angle, engine.omega)
    order = np.random.default_rng(0).permutation(state.count)  # any order on the wire
    message = states_message(header(engine.t, 'feeder'), state.ids[order], q[order],
                             qdot[order], state.products[order, P_M])
    hoppers = engine.weigher.hopper_readings() if engine.weigher is not None else None
    mine = observe(env.config, engine.angle, engine.omega, env.deficit(), hoppers,
                   cloud_points(message))
    if isinstance(obs, dict):
        for key in obs:
            np.testing.assert_allclose(mine[key], obs[key], rtol=1e-6, atol=1e-6)
    else:
        np.testing.assert_allclose(mine, obs, rtol=1e-6, atol=1e-6)


@pytest.fixture(scope='module')
def policy_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Return a directory with an (untrained, seeded) PPO policy and its environment."""
    directory = tmp_path_factory.mktemp('policy')
    config = {'episode_time': 1.0, 'normalize_actions': True}
    model = PPO('MlpPolicy', ConeFeederEnv(config), n_steps=64, seed=3, device='cpu')
    model.save(directory / 'policy.zip')
    (directory / 'env_config.yaml').write_text(yaml.safe_dump(config))
    return directory


def test_a_missing_policy_is_refused(context: Context, tmp_path: Path) -> None:
    with pytest.raises(ConeFeederError, match="parameter 'policy' is needed"):
        PolicyController(context=context)
    with pytest.raises(ConeFeederError, match='cannot load the PPO policy'):
        PolicyController(context=context, parameter_overrides=[
            Parameter('policy', value=str(tmp_path / 'none.zip')),
            Parameter('config', value='')])


def test_the_policy_drives_the_simulator(context: Context, policy_dir: Path) -> None:
    sim = SimNode(context=context, namespace='/rl', parameter_overrides=[
        Parameter('real_time_factor', value=0.0), Parameter('feed.rate', value=10.0),
        Parameter('record_path', value=''), Parameter('cmd_timeout', value=0.0)])
    ctl = PolicyController(context=context, namespace='/rl', parameter_overrides=[
        Parameter('policy', value=str(policy_dir / 'policy.zip'))])
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(sim)
    executor.add_node(ctl)
    try:
        end = time.monotonic() + 60.0
        while time.monotonic() < end and not (
                ctl.commands >= 3 and sim.last_tick is not None
                and sim.last_tick.mode == 'command'
                and sim.last_tick.target_omega == pytest.approx(ctl.last_omega)):
            executor.spin_once(timeout_sec=0.05)
        assert ctl.commands >= 3
        assert sim.last_tick.mode == 'command'
        assert sim.last_tick.target_omega == pytest.approx(ctl.last_omega)
        assert abs(ctl.last_omega) <= ctl.config.engine.drive.max_angular_velocity
    finally:
        executor.shutdown()
        ctl.destroy_node()
        sim.destroy_node()
