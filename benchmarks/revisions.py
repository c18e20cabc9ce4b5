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
Side by side: bench_states' workloads on several git revisions of the package, A B A B.

Each revision is checked out into a temporary git worktree with its own numba cache
(compiled in a warm-up run); every run is a fresh process with that worktree first on the
path, on one thread, and the rounds alternate the revisions so that the machine's drift
hits each alike. Printed: the calibration, then per state and revision the median
particle-seconds per CPU-second, its ratio to the first revision's (pair by pair, the
median), the integration steps per particle-second, and whether the pieces' final states
are bit for bit the first revision's (else the largest difference of a position, m)::

    .venv/bin/python benchmarks/revisions.py 6a0ed04 1a09b09 HEAD --rounds 5
    .venv/bin/python benchmarks/revisions.py HEAD~1 HEAD --states dropped --interactions
"""

import argparse
import json
import os
from pathlib import Path
import statistics
import subprocess
import sys
import tempfile

from bench_states import run_state, STATES
from calibration import calibration_line
import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


def worker(state: str, count: int, contacts: bool) -> None:
    """Run one workload with the package on the path; print its figures as JSON."""
    figures, engine = run_state(state, count, contacts, packed=contacts)
    order = np.argsort(engine.state.ids)
    figures['y'] = engine.state.y[order].tolist()
    print(json.dumps(figures))


def run(tree: Path, state: str, count: int, contacts: bool) -> dict:
    """Run one workload in a fresh process on the revision checked out at ``tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree), NUMBA_NUM_THREADS='1')
    out = subprocess.run(
        [sys.executable, str(Path(__file__)), '--worker', state, str(count)]
        + (['--interactions'] if contacts else []),
        env=env, cwd=tree, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    """Check out the revisions, warm each, then print the side-by-side figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('revisions', nargs='*', default=['HEAD~1', 'HEAD'])
    parser.add_argument('--states', nargs='+', choices=STATES, default=['reversing'])
    parser.add_argument('--pieces', type=int, default=200)
    parser.add_argument('--interactions', action='store_true',
                        help='pieces that touch (packed places, the default coupling)')
    parser.add_argument('--rounds', type=int, default=3)
    parser.add_argument('--worker', nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.worker[0], int(args.worker[1]), args.interactions)
        return
    print(calibration_line())
    print(f'# {args.pieces} pieces, {"with" if args.interactions else "without"} contact, '
          f'one thread, {args.rounds} rounds A B A B; pc-s/CPU-s = particle-seconds per '
          'CPU-second (median), ratio = to the first revision (median of the rounds)')
    with tempfile.TemporaryDirectory() as tmp:
        trees = []
        for k, revision in enumerate(args.revisions):
            tree = Path(tmp) / f'rev{k}'
            subprocess.run(['git', '-C', str(ROOT), 'worktree', 'add', '--detach', str(tree),
                            revision], check=True, capture_output=True)
            trees.append(tree)
        try:
            for state in args.states:
                for tree in trees:  # compile and warm the caches
                    run(tree, state, args.pieces, args.interactions)
                rows = [[run(tree, state, args.pieces, args.interactions) for tree in trees]
                        for _ in range(args.rounds)]
                print(f'{"state":>10} {"revision":>12} {"pc-s/CPU-s":>11} {"ratio":>6} '
                      f'{"steps/pc-s":>11} {"final state":>16}')
                first = np.array(rows[0][0]['y'])
                for k, revision in enumerate(args.revisions):
                    speed = statistics.median(r[k]['per_cpu'] for r in rows)
                    ratio = statistics.median(r[k]['per_cpu'] / r[0]['per_cpu'] for r in rows)
                    y = np.array(rows[0][k]['y'])
                    same = 'bit for bit' if (y.shape == first.shape and (y == first).all()) \
                        else (f'{np.abs(y[:, :3] - first[:, :3]).max():.2e} m'
                              if y.shape == first.shape else 'other pieces')
                    print(f'{state:>10} {revision:>12} {speed:>11.0f} {ratio:>6.3f} '
                          f'{rows[0][k]["steps"]:>11.0f} {same:>16}', flush=True)
        finally:
            for tree in trees:
                subprocess.run(['git', '-C', str(ROOT), 'worktree', 'remove', '--force',
                                str(tree)], check=False, capture_output=True)


if __name__ == '__main__':
    main()
