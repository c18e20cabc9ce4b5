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
Benchmark: the engine's cost in each state of the model, at several piece counts.

A headless :class:`FeederEngine` (the node's engine, no ROS), 50 Hz ticks, every core; for
each state and piece count N it prints particle-seconds per CPU-second, integration steps
per particle-second, the real-time capacity (simulated seconds per wall second with N
pieces) and the median and longest tick. The states:

* ``resting``: pieces resting on a stationary cone (the cheapest state);
* ``turning``: pieces resting on a cone turning at 2 rad/s (the self-excited friction
  oscillation of sticking pieces, see doc/model.md);
* ``dropped``: pieces released at rest 2 cm above a stationary cone (fall, landing,
  settling: the first 0.5 s);
* ``reversing``: the default reversing pattern (+-8 rad/s, 2 s each way) with the feed
  keeping N pieces on the cone (exits replaced as they happen), one pattern period.

Pieces start at seeded random places with rho in [0.03, 0.15] m. With ``--interactions``
every row is measured twice, side by side: pieces alone (the paper's model) and pieces that
touch (the soft-sphere law, :mod:`cone_feeder_sim.physics.contact`), both from places where
no two pieces overlap (a lattice, in layers when one is not enough), with the cost ratio,
the largest contact island and the contacts; ``--coupling`` picks how touching pieces are
integrated (``island``, the default, which adds its common steps per simulated second and
the pieces it refined alone; ``multirate``, which adds its coupling intervals; or
``exact``). The calibration workload is printed first. Example::

    .venv/bin/python benchmarks/bench_states.py --pieces 20 150 2000 5000
    .venv/bin/python benchmarks/bench_states.py --pieces 150 1000 --interactions
    .venv/bin/python benchmarks/bench_states.py --pieces 54 --interactions --coupling exact
"""

import argparse
import statistics
import time

from calibration import calibration_line
from cone_feeder_sim.feeder.engine import (
    DriveParams, EngineConfig, FeederEngine, FeedParams)
from cone_feeder_sim.physics.params import InteractionParams, ModelParams
from cone_feeder_sim.physics.simulation import resting_height
import numba
import numpy as np

STATES = ('resting', 'turning', 'dropped', 'reversing')
#: Default reversing pattern of sim_node (s, rad/s).
PATTERN = ((2.0, -8.0), (2.0, 8.0))


def places(count: int, lift: float, packed: bool = False) -> np.ndarray:
    """
    Return (count, 3) world positions (m): resting on the cone, raised by ``lift`` m.

    Scattered: seeded random places with rho in [0.03, 0.15] m, overlapping freely (pieces
    alone). Packed (for pieces that touch): a hexagonal lattice of spacing 51 mm (the
    pieces' diameter plus 2 %) over rho in [0.03, 0.2] m, in layers 51 mm apart when one
    layer is not enough, so that no two pieces start pressed into each other.
    """
    model = ModelParams()
    if packed:
        step = 1.02 * 2.0 * model.product.s0
        grid = np.arange(-0.2, 0.2 + step, step)
        xy = np.array([(a + (0.5 * step if k % 2 else 0.0), b) for k, b in
                       enumerate(np.arange(-0.2, 0.2, step * np.sqrt(0.75))) for a in grid])
        rho = np.hypot(xy[:, 0], xy[:, 1])
        xy = xy[(rho >= 0.03) & (rho <= 0.2)]
        xy = xy[np.argsort(np.hypot(xy[:, 0], xy[:, 1]), kind='stable')]
        layer = np.arange(count) // len(xy)
        xy = xy[np.arange(count) % len(xy)]
        x, y = xy[:, 0], xy[:, 1]
        lift = lift + step * layer
    else:
        rng = np.random.default_rng(7)
        rho = np.sqrt(rng.uniform(0.03 ** 2, 0.15 ** 2, count))
        theta = rng.uniform(0.0, 2.0 * np.pi, count)
        x, y = rho * np.cos(theta), rho * np.sin(theta)
    z = np.array([resting_height(model, model.product, a, b) for a, b in zip(x, y)]) + lift
    return np.column_stack([x, y, z])


def engine_for(state: str, count: int, contacts: bool, packed: bool,
               coupling: str = InteractionParams().coupling,
               tolerance: float = 1e-6) -> tuple[FeederEngine, int, int]:
    """Return the engine in ``state`` with ``count`` pieces, warm-up and measured ticks."""
    model = ModelParams(interactions=InteractionParams(enabled=contacts, coupling=coupling,
                                                       coupling_tolerance=tolerance))
    if state == 'reversing':
        feed = FeedParams(rate=max(500.0, count), max_pieces=count)
        engine = FeederEngine(EngineConfig(model=model, drive=DriveParams(pattern=PATTERN),
                                           feed=feed))
        fill = int(np.ceil(count / feed.rate / engine.dt)) + 100  # fill, then 2 s in
        return engine, fill, int(round(4.0 / engine.dt))
    engine = FeederEngine(EngineConfig(model=model, drive=DriveParams(cmd_timeout=0.0),
                                       feed=FeedParams(max_pieces=max(count, 1))))
    if state == 'dropped':
        engine.spawn(places(count, 0.02, packed), velocities=np.zeros((count, 3)))
        return engine, 0, 25
    engine.spawn(places(count, 0.0, packed))  # carried: at rest on the (resting) cone
    engine.command(2.0 if state == 'turning' else 0.0)
    return engine, 50, 50  # 1 s to settle (and spin up), 1 s measured


def measure(state: str, count: int, contacts: bool = False, packed: bool = False,
            coupling: str = InteractionParams().coupling,
            tolerance: float = 1e-6) -> dict[str, float]:
    """Run one state with ``count`` pieces; return the figures."""
    return run_state(state, count, contacts, packed, coupling, tolerance)[0]


def run_state(state: str, count: int, contacts: bool = False, packed: bool = False,
              coupling: str = InteractionParams().coupling,
              tolerance: float = 1e-6) -> tuple[dict[str, float], FeederEngine]:
    """Run one state with ``count`` pieces; return the figures and the engine at the end."""
    engine, warm, ticks = engine_for(state, count, contacts, packed, coupling, tolerance)
    for _ in range(warm):
        engine.tick()
    durations, piece_seconds, steps, island, cut, intervals, refined = [], 0.0, 0, 0, 0, 0, 0
    cpu0 = time.process_time()
    wall0 = time.perf_counter()
    for _ in range(ticks):
        start = time.perf_counter()
        result = engine.tick()
        durations.append(time.perf_counter() - start)
        piece_seconds += engine.dt * (len(result.ids) + len(result.exits)
                                      + len(result.failures))
        steps += result.stats.accepted + result.stats.rejected
        island = max(island, result.stats.largest_island)
        cut = max(cut, result.stats.contacts)
        intervals += result.stats.coupling_intervals + result.stats.coupling_rejected
        refined += result.stats.refined
    wall = time.perf_counter() - wall0
    cpu = time.process_time() - cpu0
    return {'pieces': engine.piece_count, 'per_cpu': piece_seconds / cpu,
            'steps': steps / max(piece_seconds, 1e-12), 'capacity': ticks * engine.dt / wall,
            'median_ms': 1e3 * statistics.median(durations), 'max_ms': 1e3 * max(durations),
            'island': island, 'cut': cut, 'intervals': intervals / (ticks * engine.dt),
            'refined': refined / (ticks * engine.dt)}, engine


def main() -> None:
    """Print the calibration and one row per state and piece count."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--pieces', type=int, nargs='+', default=[20, 150, 2000, 5000])
    parser.add_argument('--states', nargs='+', choices=STATES, default=list(STATES))
    parser.add_argument('--interactions', action='store_true',
                        help='measure each row without and with contact between pieces')
    parser.add_argument('--coupling', choices=('island', 'exact', 'multirate'),
                        default=InteractionParams().coupling,
                        help='with --interactions: how touching pieces are integrated')
    parser.add_argument('--coupling-tolerance', type=float,
                        default=InteractionParams().coupling_tolerance,
                        help='with --coupling multirate: interactions.coupling_tolerance (m); '
                             "default: the product's")
    args = parser.parse_args()
    print(calibration_line())
    if args.interactions:
        compare(args)
        return
    print(f'# 50 Hz ticks, {numba.get_num_threads()} threads; capacity = simulated s per '
          'wall s; pc-s/CPU-s = particle-seconds per CPU-second (all threads)')
    print(f'{"state":>10} {"N":>6} {"pc-s/CPU-s":>11} {"steps/pc-s":>11} {"capacity":>9} '
          f'{"median ms":>10} {"max ms":>8}')
    for state in args.states:
        for count in args.pieces:
            r = measure(state, count)
            print(f'{state:>10} {int(r["pieces"]):>6} {r["per_cpu"]:>11.0f} '
                  f'{r["steps"]:>11.0f} {r["capacity"]:>9.2f} {r["median_ms"]:>10.2f} '
                  f'{r["max_ms"]:>8.1f}', flush=True)


def compare(args: argparse.Namespace) -> None:
    """Print each state and count without and with contacts, side by side."""
    print('# pc-s/CPU-s without and with contact between pieces; cost ratio = with / '
          'without per particle-second; island = most pieces in one contact island; '
          'contacts = most touching pairs at a tick end; coupling '
          f'{args.coupling} (tolerance {args.coupling_tolerance:g} m): '
          'steps = per particle-second alone / with contact, intervals = common steps '
          '(island) or coupling intervals (multirate) per simulated s, refined = pieces '
          'refined alone per simulated s (island)')
    print(f'{"state":>10} {"N":>6} {"without":>9} {"with":>9} {"ratio":>6} {"capacity":>9} '
          f'{"max ms":>8} {"island":>9} {"contacts":>8} {"steps":>13} {"intervals":>9} '
          f'{"refined":>8}')
    for state in args.states:
        for count in args.pieces:
            alone = measure(state, count, False, packed=True)
            touch = measure(state, count, True, packed=True, coupling=args.coupling,
                            tolerance=args.coupling_tolerance)
            print(f'{state:>10} {int(touch["pieces"]):>6} {alone["per_cpu"]:>9.0f} '
                  f'{touch["per_cpu"]:>9.0f} {alone["per_cpu"] / touch["per_cpu"]:>6.2f} '
                  f'{touch["capacity"]:>9.2f} {touch["max_ms"]:>8.1f} '
                  f'{int(touch["island"]):>9} {int(touch["cut"]):>8} '
                  f'{alone["steps"]:>6.0f}/{touch["steps"]:<6.0f} {touch["intervals"]:>9.0f} '
                  f'{touch["refined"]:>8.0f}',
                  flush=True)


if __name__ == '__main__':
    main()
