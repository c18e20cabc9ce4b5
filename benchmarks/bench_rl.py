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
Benchmark: environment steps per second of the RL environment (issue 20's targets).

Each feeder holds 50 pieces (50 dropped at reset, the feed refilling up to 50 at 50
pieces/s), a control period of 0.1 s (5 ticks of 20 ms), contact off and on. Actions:
``random`` (uniform over the Box: the cone reverses at random, the expensive state, every
piece slipping) or ``steady`` (+3 rad/s held: most pieces carried, the cheap state). Rows:
one ``ConeFeederEnv``; ``SyncVectorEnv`` of K envs (Gymnasium's, one feeder after the other,
each on numba's threads); the native ``ConeFeederVectorEnv`` at K = 2, 8, 32 (contact off:
the pieces of the K feeders in one compiled call a tick; on: the feeders on a thread pool).
Feeder i is reset with seed i in every row. The calibration workload is printed first::

    .venv/bin/python benchmarks/bench_rl.py                        # everything (minutes)
    .venv/bin/python benchmarks/bench_rl.py --contact off --actions random --ks 8
"""

import argparse
import time

from calibration import calibration_line
from cone_feeder_sim.rl import ConeFeederEnv, ConeFeederVectorEnv
import gymnasium
import numpy as np

PIECES = 50
#: Measured rounds (one step of every env each) per row, by contact; after WARM rounds.
ROUNDS = {False: 20, True: 4}
WARM = 3


def settings(contact: bool) -> dict:
    """Return the environment's keys for 50 pieces a feeder."""
    return {'initial_pieces': PIECES, 'episode_time': 1.0e5, 'interactions': {'enabled': contact},
            'feed': {'rate': 50.0, 'max_pieces': PIECES}}


def action_source(kind: str, k: int):
    """
    Return a function giving the actions (K, 1) of the next round.

    Feeder i gets the same actions in every row (its own generator, seeded with i), so that
    the rows run the same episodes and differ only in how they are stepped.
    """
    if kind == 'steady':
        return lambda: np.full((k, 1), 3.0, dtype=np.float32)
    rngs = [np.random.default_rng(i) for i in range(k)]
    return lambda: np.array([[rng.uniform(-10.47, 10.47)] for rng in rngs], dtype=np.float32)


def measure(env, k: int, kind: str, rounds: int) -> tuple[float, float]:
    """Return env steps per second and the mean pieces per feeder over the measured rounds."""
    env.reset(seed=0)  # feeder i: seed i (vector envs), as the single env's feeder 0
    next_actions = action_source(kind, k)
    for _ in range(WARM):
        env.step(next_actions() if k > 1 else next_actions()[0])
    pieces = 0.0
    start = time.perf_counter()
    for _ in range(rounds):
        info = env.step(next_actions() if k > 1 else next_actions()[0])[4]
        pieces += float(np.mean(info['pieces']))
    return k * rounds / (time.perf_counter() - start), pieces / rounds


def main() -> None:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--contact', choices=('off', 'on', 'both'), default='both')
    parser.add_argument('--actions', choices=('random', 'steady', 'both'), default='both')
    parser.add_argument('--ks', type=int, nargs='+', default=[2, 8, 32])
    parser.add_argument('--sync-k', type=int, default=8, help='K of the SyncVectorEnv row')
    args = parser.parse_args()
    print(calibration_line())
    print(f'{PIECES} pieces per feeder, control period 0.1 s (5 ticks of 20 ms)')
    print(f'{"contact":8} {"actions":8} {"environment":28} {"K":>3} {"steps/s":>9} '
          f'{"pieces":>7} {"sim s/s":>8}')
    contacts = {'off': [False], 'on': [True], 'both': [False, True]}[args.contact]
    kinds = ['random', 'steady'] if args.actions == 'both' else [args.actions]
    for contact in contacts:
        for kind in kinds:
            rounds = ROUNDS[contact]
            rows = [('ConeFeederEnv', 1, ConeFeederEnv(**settings(contact)))]
            rows.append(('SyncVectorEnv', args.sync_k, gymnasium.vector.SyncVectorEnv(
                [lambda c=contact: ConeFeederEnv(**settings(c))] * args.sync_k)))
            rows += [('ConeFeederVectorEnv', k, ConeFeederVectorEnv(k, **settings(contact)))
                     for k in args.ks]
            for name, k, env in rows:
                rate, pieces = measure(env, k, kind, max(1, rounds // max(1, k // 8)))
                env.close()
                print(f'{"on" if contact else "off":8} {kind:8} {name:28} {k:3d} '
                      f'{rate:9.1f} {pieces:7.1f} {rate * 0.1:8.1f}', flush=True)
    print(calibration_line())


if __name__ == '__main__':
    main()
