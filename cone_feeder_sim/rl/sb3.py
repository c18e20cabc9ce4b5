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
The vector environment as a stable-baselines3 ``VecEnv`` (``pip install cone_feeder_sim[rl]``).

stable-baselines3 resets a finished environment within the step that ends it: the step
returns the next episode's first observation, with the last one of the finished episode in
``info['terminal_observation']`` and ``info['TimeLimit.truncated']`` True where the episode
was cut by its time limit (here always: the feeder has no terminal state). :class:`SB3VecEnv`
gives that over any Gymnasium vector environment with partial resets
(``reset(options={'reset_mask': mask})``), :class:`~cone_feeder_sim.rl.vector.ConeFeederVectorEnv`
in the first place.
"""

from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium
from gymnasium.vector.utils import iterate
import numpy as np
import stable_baselines3
from stable_baselines3.common.vec_env import VecEnv

from ..errors import EnvConfigError

__all__ = ['load_policy', 'SB3VecEnv']

#: The stable-baselines3 algorithms a saved policy may come from.
ALGORITHMS = ('A2C', 'DDPG', 'DQN', 'PPO', 'SAC', 'TD3')


def load_policy(path: str, algorithm: str = 'PPO') -> Any:
    """Load a saved stable-baselines3 model (``model.predict(obs)``) on the CPU."""
    if algorithm not in ALGORITHMS:
        raise EnvConfigError(f'algorithm must be one of {", ".join(ALGORITHMS)}, got '
                             f'{algorithm!r}')
    try:
        return getattr(stable_baselines3, algorithm).load(path, device='cpu')
    except (OSError, ValueError, KeyError) as exc:
        raise EnvConfigError(f'cannot load the {algorithm} policy {path}: {exc}') from exc


class SB3VecEnv(VecEnv):
    """
    A Gymnasium vector environment as a stable-baselines3 VecEnv.

    The arguments:

    venv: the vector environment (its sub-environments, ``venv.envs``, answer
    get_attr, set_attr and env_method).
    """

    def __init__(self, venv: gymnasium.vector.VectorEnv) -> None:
        """Wrap venv; its single spaces are the VecEnv's spaces."""
        self.venv = venv
        self._actions: np.ndarray | None = None
        super().__init__(venv.num_envs, venv.single_observation_space,
                         venv.single_action_space)

    def reset(self) -> Any:
        """Reset every environment with the seeds and options set before (then forget them)."""
        seeds = list(self._seeds)
        options = self._options[0] if self._options else {}
        obs, infos = self.venv.reset(seed=seeds if any(s is not None for s in seeds) else None,
                                     options=options or None)
        self.reset_infos = self._split(infos)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        """Remember the actions for step_wait."""
        self._actions = actions

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        """Step, then reset the finished environments at once (SB3's convention)."""
        obs, rewards, terminated, truncated, infos = self.venv.step(self._actions)
        dones = terminated | truncated
        info_list = self._split(infos)
        if dones.any():
            finals = list(iterate(self.venv.observation_space, obs))
            for i in np.flatnonzero(dones):
                info_list[i]['terminal_observation'] = finals[i]
                info_list[i]['TimeLimit.truncated'] = bool(truncated[i] and not terminated[i])
            obs, reset_infos = self.venv.reset(options={'reset_mask': dones})
            for i, info in enumerate(self._split(reset_infos)):
                if dones[i]:
                    self.reset_infos[i] = info
        return obs, rewards.astype(np.float32), dones, info_list

    def _split(self, infos: dict[str, Any]) -> list[dict[str, Any]]:
        """Return the vector env's info dict as one dict per environment."""
        out: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for key, values in infos.items():
            if key.startswith('_'):
                continue
            present = infos.get('_' + key, np.ones(self.num_envs, dtype=np.bool_))
            for i in range(self.num_envs):
                if present[i]:
                    out[i][key] = values[i]
        return out

    def close(self) -> None:
        """Close the vector environment."""
        self.venv.close()

    def _targets(self, indices: Any) -> list[Any]:
        return [self.venv.envs[i] for i in self._get_indices(indices)]

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        """Return an attribute of each environment."""
        return [getattr(env, attr_name) for env in self._targets(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        """Set an attribute of each environment."""
        for env in self._targets(indices):
            setattr(env, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None,
                   **method_kwargs: Any) -> list[Any]:
        """Call a method of each environment."""
        return [getattr(env, method_name)(*method_args, **method_kwargs)
                for env in self._targets(indices)]

    def env_is_wrapped(self, wrapper_class: type[gymnasium.Wrapper],
                       indices: Any = None) -> list[bool]:
        """Tell whether each environment is wrapped by wrapper_class (never: bare envs)."""
        return [isinstance(env, wrapper_class) for env in self._targets(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        """Return no images (no rendering yet)."""
        return [None] * self.num_envs

    def _get_indices(self, indices: Any) -> Iterable[int]:
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return indices
