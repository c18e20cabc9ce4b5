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
The weigher under three ways of turning the cone, same feed, same seeds, 10 simulated min.

* ``open loop``: sim_node's default reversing pattern (2 s at -8 rad/s, 2 s at +8 rad/s);
* ``channel_mass``: ``example_controller`` evening out the cumulative mass per channel;
* ``hoppers``: ``example_controller`` with ``objective: hoppers``, evening out the weigh
  hoppers' readings (what the weigher below the cone needs).

The controller is the node's own :class:`DirectionLearner`, fed from the engine as the
node feeds it from its topics (a decision every ``period`` simulated seconds, 8 rad/s).
Pieces alone (the engine's default model), the default weigher (config/weigher.yaml), feed
``--rate`` pieces/s with masses varying by ``--mass-std`` (relative). Prints packs per
minute, giveaway, under-target packs and starved heads per cycle; writes a figure::

    .venv/bin/python benchmarks/weigher_control.py --out doc/figures/weigher_control.png
"""

import argparse
from pathlib import Path

from cone_feeder_sim.feeder.engine import DriveParams, EngineConfig, FeederEngine, FeedParams
from cone_feeder_sim.ros.example_controller import DirectionLearner
from cone_feeder_sim.weigher.machine import WeigherParams
import numpy as np

PATTERN = ((2.0, -8.0), (2.0, 8.0))
POLICIES = ('open loop', 'channel_mass', 'hoppers')


def run(policy: str, minutes: float, rate: float, seed: int, mass_std: float,
        period: float = 2.0) -> tuple[FeederEngine, list]:
    """Run one policy; return the engine at the end and the packs."""
    drive = DriveParams(pattern=PATTERN) if policy == 'open loop' else DriveParams(
        cmd_timeout=0.0)
    feed = FeedParams(rate=rate, mass_rel_std=mass_std)
    engine = FeederEngine(EngineConfig(drive=drive, feed=feed, seed=seed,
                                       weigher=WeigherParams(seed=seed)))
    learner = DirectionLearner(learning_rate=0.3, explore_after=3)
    every = int(round(period / engine.dt))
    if policy != 'open loop':
        engine.command(learner.direction * 8.0)
    packs = []
    for k in range(1, int(round(60.0 * minutes / engine.dt)) + 1):
        result = engine.tick()
        packs += result.packs
        learner.add_exits(result.exits.channel, result.exits.mass)
        if policy != 'open loop' and k % every == 0:
            masses = result.hoppers if policy == 'hoppers' else result.channel_mass
            engine.command(learner.decide(masses) * 8.0)
    return engine, packs


def main() -> None:
    """Run the three policies, print their figures and draw them."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=10.0)
    parser.add_argument('--rate', type=float, default=8.0, help='feed, pieces/s')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--mass-std', type=float, default=0.3,
                        help='relative standard deviation of the piece masses')
    parser.add_argument('--out', type=Path, default=None, help='PNG of the comparison')
    args = parser.parse_args()
    print(f'# {args.minutes:g} simulated min, feed {args.rate:g} pieces/s (masses 0.125 kg '
          f'+- {100 * args.mass_std:g} %), seed {args.seed}, default weigher (1 kg packs, '
          '60 cycles/min)')
    print(f'{"policy":>13} {"packs/min":>10} {"giveaway g":>11} {"std g":>7} '
          f'{"under %":>8} {"< TNE %":>8} {"starved":>8} {"kg packed":>10}')
    results = {}
    for policy in POLICIES:
        engine, packs = run(policy, args.minutes, args.rate, args.seed, args.mass_std)
        stats = engine.weigher.stats()
        results[policy] = packs
        print(f'{policy:>13} {stats.packs_per_minute:>10.2f} '
              f'{1e3 * stats.giveaway_mean:>11.1f} {1e3 * stats.giveaway_std:>7.1f} '
              f'{100 * stats.under_target:>8.2f} {100 * stats.below_tne:>8.2f} '
              f'{stats.starved_per_cycle:>8.2f} '
              f'{engine.weigher.packed:>10.2f}', flush=True)
    if args.out is not None:
        draw(results, args)


def draw(results: dict[str, list], args: argparse.Namespace) -> None:
    """Write the figure: packs over time and the giveaway histograms."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(11.0, 4.2), dpi=100)
    FigureCanvasAgg(figure)
    left, right = figure.subplots(1, 2)
    bins = np.linspace(-10.0, 150.0, 33)  # 5-g bins; packs under the target on the left
    for policy, packs in results.items():
        t = np.array([p.t for p in packs])
        left.step(t / 60.0, np.arange(1, len(t) + 1), where='post', label=policy)
        right.hist([1e3 * p.giveaway for p in packs], bins=bins, histtype='step',
                   linewidth=1.5, label=policy)
    left.set_xlabel('simulated time (min)')
    left.set_ylabel('packs')
    left.set_title(f'Packs made (feed {args.rate:g} pieces/s, seed {args.seed})')
    right.set_xlabel('giveaway (g)')
    right.set_ylabel('packs')
    right.set_title('Giveaway per pack (1-kg target)')
    for ax in (left, right):
        ax.grid(True, linewidth=0.3, alpha=0.5)
        ax.legend(fontsize=9)
    figure.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(args.out)
    print(f'figure written to {args.out}')


if __name__ == '__main__':
    main()
