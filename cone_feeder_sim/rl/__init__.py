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
Reinforcement learning on the cone feeder: a Gymnasium environment, no ROS.

``config`` (``config/rl.yaml``, validated), ``env`` (:class:`ConeFeederEnv`, one feeder) and
``vector`` (:class:`ConeFeederVectorEnv`, K feeders stepped together). Importing this package
registers ``cone_feeder_sim/ConeFeeder-v0`` with Gymnasium, so
``gymnasium.make('cone_feeder_sim.rl:ConeFeeder-v0')`` imports it and makes the environment,
and ``gymnasium.make_vec(..., num_envs=K)`` returns the native vector environment. Gymnasium
is the optional extra ``pip install cone_feeder_sim[rl]``.
"""

import gymnasium

from .config import EnvConfig, load_env_config
from .env import ConeFeederEnv
from .vector import ConeFeederVectorEnv

__all__ = ['ConeFeederEnv', 'ConeFeederVectorEnv', 'EnvConfig', 'ENV_ID', 'load_env_config']

#: The registered id; ``cone_feeder_sim.rl:ConeFeeder-v0`` imports this package first.
ENV_ID = 'cone_feeder_sim/ConeFeeder-v0'

for _id in (ENV_ID, 'ConeFeeder-v0'):
    # 'module:ConeFeeder-v0' looks 'ConeFeeder-v0' up after importing the module
    if _id not in gymnasium.registry:
        gymnasium.register(id=_id, entry_point='cone_feeder_sim.rl.env:ConeFeederEnv',
                           vector_entry_point='cone_feeder_sim.rl.vector:ConeFeederVectorEnv')
