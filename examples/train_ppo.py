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
Train PPO on the batched cone feeder; compare it with the open-loop pattern and a rule.

stable-baselines3's PPO (on the CPU) learns to turn the cone from the native vector
environment (``ConeFeederVectorEnv`` through ``SB3VecEnv``) with the weigher below the cone
and contact off. Then three policies run the same 20 seeded episodes of ``--eval-time``
simulated seconds:

* ``open loop``: ``sim_node``'s default pattern, 2 s at -8 rad/s then 2 s at +8 rad/s;
* ``rule``: ``example_controller``'s rule (its ``DirectionLearner``, a direction chosen every
  2 s from the channel deficits, 8 rad/s), fed from the environment's channel masses;
* ``ppo``: the learned policy, deterministic.

Printed and written to ``OUT/comparison.csv``: the episode reward, the channel distribution
error (the root mean square of the channels' deficits against their targets at the end,
relative to the mean target mass), packs per minute and the mean giveaway (g). Also written:
``OUT/policy.zip`` (the policy, for ``policy_controller``), ``OUT/env_config.yaml`` (the
environment it was trained on), ``OUT/learning_curve.csv`` and ``.png`` (with the
baselines' mean reward on episodes of the training length). Example::

    .venv/bin/python examples/train_ppo.py --timesteps 200000 --out results/ppo
"""

import argparse
import csv
from pathlib import Path
import time

from cone_feeder_sim.rl import ConeFeederEnv, ConeFeederVectorEnv
from cone_feeder_sim.rl.sb3 import SB3VecEnv
from cone_feeder_sim.ros.example_controller import DirectionLearner
import matplotlib
import numpy as np
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecMonitor
import torch
import yaml

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402, I100 - after choosing the backend

#: The environment PPO trains on (keys of config/rl.yaml over its defaults).
ENV_CONFIG = {'weigher': True, 'normalize_actions': True, 'episode_time': 30.0,
              'initial_pieces': 20}
#: sim_node's default open-loop pattern: (duration s, omega rad/s).
PATTERN = ((2.0, -8.0), (2.0, 8.0))
#: example_controller's defaults: speed (rad/s), period (s), learning rate, explore_after.
RULE = (8.0, 2.0, 0.3, 3)


class Curve(BaseCallback):
    """Keep (timesteps, mean episode reward of the last episodes) after every rollout."""

    def __init__(self) -> None:
        """Start with no points."""
        super().__init__()
        self.points: list[tuple[int, float, int]] = []

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        episodes = self.model.ep_info_buffer
        if episodes:
            self.points.append((self.num_timesteps,
                                float(np.mean([e['r'] for e in episodes])), len(episodes)))
            print(f'{self.num_timesteps:8d} steps: mean episode reward '
                  f'{self.points[-1][1]:9.2f} (last {len(episodes)} episodes)', flush=True)


def pattern_policy(env: ConeFeederEnv):
    """Return the open-loop pattern as a policy (normalized omega action)."""
    limit = env.config.engine.drive.max_angular_velocity
    period = sum(d for d, _ in PATTERN)

    def act(obs, info) -> np.ndarray:
        phase = (info['t'] + 1e-9) % period
        omega = PATTERN[0][1] if phase < PATTERN[0][0] else PATTERN[1][1]
        return np.array([omega / limit], dtype=np.float32)
    return act


def rule_policy(env: ConeFeederEnv):
    """Return example_controller's rule as a policy (fed from the channel masses)."""
    speed, period, rate, explore = RULE
    limit = env.config.engine.drive.max_angular_velocity
    learner = DirectionLearner(rate, explore)
    state = {'next': period, 'mass': np.zeros(env.config.engine.model.channels.count)}
    channels = np.arange(1, state['mass'].size + 1)

    def act(obs, info) -> np.ndarray:
        masses = np.asarray(info['channel_mass'])
        learner.add_exits(channels, masses - state['mass'])
        state['mass'] = masses
        if info['t'] >= state['next'] - 1e-9:
            learner.decide(masses)
            state['next'] += period
        return np.array([learner.direction * speed / limit], dtype=np.float32)
    return act


def ppo_policy(model: PPO):
    """Return the learned policy, deterministic."""
    return lambda obs, info: model.predict(obs, deterministic=True)[0]


def evaluate(make_policy, seeds: list[int], eval_time: float) -> dict[str, float]:
    """Run one policy on the seeded episodes; return the means of the figures."""
    rows = []
    for seed in seeds:
        env = ConeFeederEnv(ENV_CONFIG, episode_time=eval_time)
        obs, info = env.reset(seed=seed)
        act = make_policy(env)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, info = env.step(act(obs, info))
            total += reward
            done = terminated or truncated
        targets = np.array(env.config.channel_targets) * info['t']
        error = float(np.sqrt(np.mean(info['deficit'] ** 2)) / targets.mean())
        stats = env.engine.weigher.stats()
        rows.append((total, error, stats.packs_per_minute, 1e3 * stats.giveaway_mean))
    return dict(zip(('reward', 'distribution error', 'packs/min', 'giveaway g'),
                    np.mean(rows, axis=0)))


def plot(out: Path, eval_seeds: int) -> None:
    """
    Draw OUT/learning_curve.png from OUT/learning_curve.csv, with the baselines' lines.

    The baselines run the same seeded episodes of the training length, so that their
    mean episode rewards compare with the curve's.
    """
    with (out / 'learning_curve.csv').open() as stream:
        points = [(int(r['timesteps']), float(r['mean_episode_reward']))
                  for r in csv.DictReader(stream)]
    if not points:
        return
    seeds = list(range(1000, 1000 + eval_seeds))
    steps, rewards = zip(*points)
    fig, ax = plt.subplots(figsize=(6, 3.5), dpi=100)
    ax.plot(steps, rewards, marker='.', label='PPO (training episodes)')
    for (name, make), style in zip((('open loop', pattern_policy), ('rule', rule_policy)),
                                   ('--', ':')):
        reward = evaluate(make, seeds, ENV_CONFIG['episode_time'])['reward']
        ax.axhline(reward, linestyle=style, color='grey', label=f'{name} ({eval_seeds} seeds)')
    ax.set_xlabel('environment steps')
    ax.set_ylabel(f'mean episode reward ({ENV_CONFIG["episode_time"]:g}-s episodes)')
    ax.set_title('PPO on ConeFeederVectorEnv (contact off, weigher on)')
    ax.legend(fontsize=8, loc='lower right')
    fig.tight_layout()
    fig.savefig(out / 'learning_curve.png')


def main() -> None:
    """Train, evaluate, write the files."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--timesteps', type=int, default=100_000)
    parser.add_argument('--envs', type=int, default=8, help='feeders in the vector env')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--eval-seeds', type=int, default=20)
    parser.add_argument('--eval-time', type=float, default=60.0, help='s per evaluation')
    parser.add_argument('--out', type=Path, default=Path('results/ppo'))
    parser.add_argument('--plot-only', action='store_true',
                        help='only redraw OUT/learning_curve.png from OUT/learning_curve.csv')
    args = parser.parse_args()
    if args.plot_only:
        plot(args.out, args.eval_seeds)
        return
    args.out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)  # the feeders take the cores
    venv = VecMonitor(SB3VecEnv(ConeFeederVectorEnv(args.envs, ENV_CONFIG)))
    venv.seed(args.seed)
    model = PPO('MlpPolicy', venv, n_steps=256, batch_size=256, learning_rate=3e-4,
                gamma=0.99, seed=args.seed, device='cpu', verbose=0)
    curve = Curve()
    start = time.perf_counter()
    model.learn(total_timesteps=args.timesteps, callback=curve)
    print(f'trained {args.timesteps} steps in {time.perf_counter() - start:.0f} s')
    model.save(args.out / 'policy.zip')
    (args.out / 'env_config.yaml').write_text(yaml.safe_dump(ENV_CONFIG))
    with (args.out / 'learning_curve.csv').open('w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(['timesteps', 'mean_episode_reward', 'episodes'])
        writer.writerows(curve.points)
    seeds = list(range(1000, 1000 + args.eval_seeds))
    results = {name: evaluate(make, seeds, args.eval_time) for name, make in (
        ('open loop', pattern_policy), ('rule', rule_policy),
        ('ppo', lambda env: ppo_policy(model)))}
    columns = list(next(iter(results.values())))
    with (args.out / 'comparison.csv').open('w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(['policy', *columns])
        for name, figures in results.items():
            writer.writerow([name, *(f'{figures[c]:.6g}' for c in columns)])
    print(f'\n{args.eval_seeds} seeds, {args.eval_time:g} s each:')
    print('| policy | ' + ' | '.join(columns) + ' |')
    print('|---' * (len(columns) + 1) + '|')
    for name, figures in results.items():
        print(f'| {name} | ' + ' | '.join(f'{figures[c]:.3g}' for c in columns) + ' |')
    plot(args.out, args.eval_seeds)
    venv.close()


if __name__ == '__main__':
    main()
