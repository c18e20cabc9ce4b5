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
:class:`ConeFeederVectorEnv`: K feeders stepped together on the machine's cores.

Each sub-environment is a :class:`~cone_feeder_sim.rl.env.ConeFeederEnv`. Without contact
between pieces, every tick of a step advances the pieces of all K feeders in one compiled
call (:func:`~cone_feeder_sim.feeder.engine.tick_many`), spread over the cores. With contact
on, the K environments go to a pool of threads (one per core), each feeder on one numba
thread: every kernel a tick runs releases the GIL, and the contact kernels run an island on
one thread, so feeders side by side use the cores better than one feeder's islands. Results
are the same either way and for any number of threads: each feeder's state depends on
nothing but its own inputs, so the vector environment equals K single environments step for
step (a test checks it against ``SyncVectorEnv``).

Autoreset is ``NEXT_STEP`` (Gymnasium's default): the step after an episode ended resets
that sub-environment and returns its first observation, with reward 0 and
``terminated = truncated = False``; the action given for it is ignored. ``reset(seed=s)``
seeds sub-environment i with ``s + i``, as ``SyncVectorEnv`` does.
"""

from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
import os
from pathlib import Path
from typing import Any

import gymnasium
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array, iterate
import numba
import numpy as np

from .config import EnvConfig, load_env_config
from .env import ConeFeederEnv
from ..errors import EnvConfigError
from ..feeder.engine import tick_many, TickResult
from ..physics.simulation import warm_up

__all__ = ['ConeFeederVectorEnv']


def _single_threaded() -> None:
    """Give a pool thread one numba thread (numba's thread count is per calling thread)."""
    numba.set_num_threads(1)


class ConeFeederVectorEnv(gymnasium.vector.VectorEnv):
    """
    K cone feeders as one Gymnasium vector environment (see the module documentation).

    The arguments:

    num_envs: K, the number of feeders (>= 1).
    config: as for :class:`~cone_feeder_sim.rl.env.ConeFeederEnv` (None: config/rl.yaml;
    a file; a mapping; an EnvConfig), the same for every feeder.
    threads: threads that step the feeders with contact on (0: one per core, at most K);
    without contact, the one compiled call runs on numba's threads.
    render_mode: None (no rendering yet).
    **overrides: keys of ``config/rl.yaml`` merged over ``config``.
    """

    metadata: dict[str, Any] = {'render_modes': [], 'autoreset_mode': AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1,
                 config: str | Path | Mapping[str, Any] | EnvConfig | None = None,
                 threads: int = 0, render_mode: str | None = None, **overrides: Any) -> None:
        """Build the K environments and the thread pool."""
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise EnvConfigError(f'num_envs must be a positive integer, got {num_envs!r}')
        if isinstance(threads, bool) or not isinstance(threads, int) or threads < 0:
            raise EnvConfigError(f'threads must be 0 (one per core) or more, got {threads!r}')
        if not isinstance(config, EnvConfig):
            config = load_env_config(config, overrides)
        elif overrides:
            raise EnvConfigError('overrides need a file or a mapping, not an EnvConfig')
        self.config = config
        warm_up(config.engine.model, batched=True)  # tick_many's kernel, before any step
        self.envs = [ConeFeederEnv(config, render_mode=render_mode) for _ in range(num_envs)]
        self.num_envs = num_envs
        self.render_mode = render_mode
        self.single_observation_space = self.envs[0].observation_space
        self.single_action_space = self.envs[0].action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        workers = min(num_envs, threads or os.cpu_count() or 1)
        self._pool = (ThreadPoolExecutor(workers, thread_name_prefix='cone_feeder_env',
                                         initializer=_single_threaded)
                      if workers > 1 else None)
        self._observations = create_empty_array(self.single_observation_space, num_envs)
        self._rewards = np.zeros(num_envs)
        self._terminations = np.zeros(num_envs, dtype=np.bool_)
        self._truncations = np.zeros(num_envs, dtype=np.bool_)
        self._autoreset = np.zeros(num_envs, dtype=np.bool_)

    def _map(self, function: Any, items: list[Any]) -> list[Any]:
        if self._pool is None:
            return [function(*item) for item in items]
        return list(self._pool.map(lambda item: function(*item), items))

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """
        Reset the feeders (seed s: feeder i gets s + i; a list: one seed each).

        ``options={'reset_mask': mask}`` (a bool array (K,)) resets only the feeders where
        mask is True (Gymnasium's partial reset); the others keep their state and their
        rows of the returned observation.
        """
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, int):
            seeds = [seed + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f'{len(seeds)} seeds given for {self.num_envs} environments')
        options = dict(options or {})
        mask = np.asarray(options.pop('reset_mask', np.ones(self.num_envs, dtype=np.bool_)))
        if mask.shape != (self.num_envs,) or mask.dtype != np.bool_ or not mask.any():
            raise ValueError(f"options['reset_mask'] must be a bool array of shape "
                             f'({self.num_envs},) with a True, got {mask!r}')
        chosen = [i for i in range(self.num_envs) if mask[i]]
        results = self._map(lambda i: self.envs[i].reset(seed=seeds[i], options=options or None),
                            [(i,) for i in chosen])
        self._terminations[mask] = False
        self._truncations[mask] = False
        self._autoreset[mask] = False
        self._rewards[mask] = 0.0
        infos: dict[str, Any] = {}
        observations = list(iterate(self.single_observation_space, self._observations))
        for i, (obs, info) in zip(chosen, results):
            observations[i] = obs
            infos = self._add_info(infos, info, i)
        self._observations = concatenate(self.single_observation_space, observations,
                                         self._observations)
        return self._copy(), infos

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        """Step every feeder by a control period (NEXT_STEP autoreset)."""
        actions = list(iterate(self.action_space, actions))
        if len(actions) != self.num_envs:
            raise ValueError(f'{len(actions)} actions given for {self.num_envs} environments')

        if self.config.engine.model.interactions.enabled:
            results = self._map(self._step_one, list(enumerate(actions)))
        else:
            results = self._step_batched(actions)
        infos: dict[str, Any] = {}
        for i, (_, reward, terminated, truncated, info) in enumerate(results):
            self._rewards[i] = reward
            self._terminations[i] = terminated
            self._truncations[i] = truncated
            infos = self._add_info(infos, info, i)
        self._autoreset = self._terminations | self._truncations
        self._observations = concatenate(self.single_observation_space,
                                         [r[0] for r in results], self._observations)
        return (self._copy(), self._rewards.copy(), self._terminations.copy(),
                self._truncations.copy(), infos)

    def _step_one(self, index: int, action: Any) -> tuple[Any, float, bool, bool,
                                                          dict[str, Any]]:
        """Step (or autoreset) one feeder."""
        env = self.envs[index]
        if self._autoreset[index]:
            obs, info = env.reset()
            return obs, 0.0, False, False, info
        return env.step(action)

    def _step_batched(
            self, actions: list[Any]) -> list[tuple[Any, float, bool, bool, dict[str, Any]]]:
        """Step the feeders with one compiled call per tick for all of them."""
        results: list[Any] = [None] * self.num_envs
        stepping = []
        for i, env in enumerate(self.envs):
            if self._autoreset[i]:
                obs, info = env.reset()
                results[i] = (obs, 0.0, False, False, info)
            else:
                env.act(actions[i])
                stepping.append(i)
        ticks: list[list[TickResult]] = [[] for _ in stepping]
        for _ in range(self.config.ticks):
            for done, result in zip(ticks, tick_many([self.envs[i].engine for i in stepping])):
                done.append(result)
        for i, done in zip(stepping, ticks):
            results[i] = self.envs[i].outcome(done)
        return results

    def _copy(self) -> Any:
        if isinstance(self._observations, dict):
            return {key: value.copy() for key, value in self._observations.items()}
        return self._observations.copy()

    def close_extras(self, **kwargs: Any) -> None:
        """Stop the thread pool and close the feeders."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        for env in self.envs:
            env.close()
