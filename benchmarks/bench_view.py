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
Benchmark: what the live view costs a run, and how steady its frames come (issue 22).

A headless run (the runner's 10-ms intervals, what ``run --view`` serves) of 150 pieces,
contact off (the cheapest interval: the view's share is largest there) and on, the cone
steady (3 rad/s) or reversing every 0.25 s. A client of the tests' own
(``test/foxglove_client.py``) is connected and subscribed to every topic of the view, so
that every frame is encoded and sent.

* cost: intervals as fast as possible without and with the view, alternated ``--repeat``
  times (the machine's speed drifts), the best of each; the view's share of an interval =
  (with - without) / without. Also: the snapshot (the simulation's own share, in the
  progress callback) and the frame (the view's thread: scene, series, events) per call.
* the same for the engine's 20-ms ticks (what ``sim_node`` and the RL environment tick),
  the view watching the engine (it observes every tick).
* frame rate: ``--seconds`` of the run paced to real time (speed 1); the frame times as
  the client receives them: frames per second, mean and worst gap.

Prints the calibration workload first. Example::

    .venv/bin/python benchmarks/bench_view.py                 # both, ~1 minute
    .venv/bin/python benchmarks/bench_view.py --contact off --repeat 5
"""

import argparse
from pathlib import Path
import sys
import time
from typing import Any

from calibration import calibration_line
from cone_feeder_sim.feeder.realtime import RealTime
from cone_feeder_sim.feeder.runner import run_scenario
from cone_feeder_sim.feeder.scenario import Scenario
from cone_feeder_sim.formats.scenario_file import scenario_from_mapping
from cone_feeder_sim.view import LiveView
import numpy as np

PIECES = 150
TOPICS = ('/scene', '/cone_state', '/channel_mass', '/hopper_weights', '/events')


def connect(port: int) -> Any:
    """Return a client of the tests' own (test/foxglove_client.py) connected to port."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))
    from foxglove_client import FoxgloveClient
    return FoxgloveClient(port)


def scenario(contact: bool, motion: str, duration: float) -> Scenario:
    """Return 150 pieces at rest on the cone (seeded), the cone steady or reversing."""
    rng = np.random.default_rng(1)
    radius = rng.uniform(0.04, 0.19, PIECES)
    bearing = rng.uniform(0.0, 2.0 * np.pi, PIECES)
    particles = [{'position': [float(r * np.cos(b)), float(r * np.sin(b)), 0.0],
                  'on_surface': True} for r, b in zip(radius, bearing)]
    if motion == 'steady':
        rotation = [[0.0, 3.0]]
    else:
        rotation = [[0.25 * k, 3.0 * (-1) ** k] for k in range(int(duration / 0.25) + 2)]
    return scenario_from_mapping({
        'duration': duration, 'rotation': rotation, 'particles': particles,
        'weigher': {}, 'interactions': {'enabled': contact},
        'parameters': str(Path(__file__).resolve().parents[1] / 'config' / 'table2.yaml')})


class Timed:
    """A progress callback that times another (s, summed over calls)."""

    def __init__(self, callback) -> None:
        """Time ``callback``."""
        self.callback = callback
        self.seconds = 0.0
        self.calls = 0
        self.pieces = 0

    def __call__(self, t, sim, step) -> None:
        start = time.perf_counter()
        self.callback(t, sim, step)
        self.seconds += time.perf_counter() - start
        self.calls += 1
        self.pieces += sim.state.count


def run(case: Scenario, view: LiveView | None) -> tuple[float, int, float]:
    """Time a run with the view or without: wall seconds, intervals, mean piece count."""
    timed = Timed(view if view is not None else (lambda *_: None))
    start = time.perf_counter()
    run_scenario(case, timed)
    return time.perf_counter() - start, timed.calls, timed.pieces / max(timed.calls, 1)


def cost(contact: bool, motion: str, intervals: int, repeat: int) -> None:
    """Print the view's share of an interval, without and with the view, side by side."""
    case = scenario(contact, motion, 0.01 * intervals)
    with LiveView(case.model, port=0) as view:
        client = connect(view.port)
        client.subscribe(*TOPICS)
        plain, served = [], []
        for _ in range(repeat):
            plain.append(run(case, None))
            frames0, publish0 = view.frames, view.publish_seconds
            wall, calls, pieces = run(case, view)
            served.append((wall, calls, pieces, view.frames - frames0,
                           view.publish_seconds - publish0))
        snapshot = Timed(view)
        run_scenario(case, snapshot)
        client.close()
    best_plain = min(plain)
    best = min(served)
    per_plain = best_plain[0] / best_plain[1]
    per_view = best[0] / best[1]
    print(f'{"on" if contact else "off":>7} {motion:>9} {best_plain[2]:6.0f} '
          f'{1e3 * per_plain:9.2f} {1e3 * per_view:9.2f} {100 * (per_view / per_plain - 1):6.1f}'
          f' % {1e3 * snapshot.seconds / snapshot.calls:9.3f} '
          f'{1e3 * best[4] / max(best[3], 1):8.2f} {best[3] / best[0]:7.1f}')


def engine_cost(ticks: int, repeat: int) -> None:
    """Print the view's share of a sim_node tick (the engine, 20 ms) at 150 pieces."""
    from cone_feeder_sim.feeder.engine import EngineConfig, FeederEngine, FeedParams, PieceSpec
    case = scenario(False, 'steady', 1.0)
    config = EngineConfig(model=case.model, feed=FeedParams(rate=0.0, max_pieces=PIECES),
                          initial_pieces=tuple(PieceSpec(tuple(p.position))
                                               for p in case.particles))

    def run_engine(view: LiveView | None) -> float:
        engine = FeederEngine(config)
        engine.command(3.0)
        for _ in range(10):  # past the start
            engine.tick()
        if view is not None:
            view.watch(engine)  # the view observes every tick
        start = time.perf_counter()
        for _ in range(ticks):
            engine.tick()
        return (time.perf_counter() - start) / ticks

    with LiveView(case.model, port=0) as view:
        client = connect(view.port)
        client.subscribe(*TOPICS)
        plain, served = [], []
        for _ in range(repeat):
            plain.append(run_engine(None))
            served.append(run_engine(view))
        client.close()
    print(f'engine ticks (20 ms, contact off, steady, {PIECES} pieces): '
          f'{1e3 * min(plain):.2f} ms without the view, {1e3 * min(served):.2f} ms with it: '
          f'{100 * (min(served) / min(plain) - 1):.1f} %')


def steadiness(seconds: float) -> None:
    """Print the frame rate a client sees over a run paced to real time."""
    case = scenario(False, 'steady', seconds)
    with LiveView(case.model, port=0) as view:
        client = connect(view.port)
        client.subscribe('/scene')
        pace = RealTime(1.0)

        def on_interval(t, sim, step) -> None:
            view(t, sim, step)
            pace(t)

        start = time.monotonic()
        run_scenario(case, on_interval)
        wall = time.monotonic() - start
        time.sleep(0.2)
        client.close()
    arrivals = np.array(client.arrivals['/scene'])
    arrivals = arrivals[arrivals <= start + wall]
    gaps = np.diff(arrivals)
    print(f'paced run (speed 1, contact off, steady), {seconds:g} s simulated in {wall:.2f} s '
          f'wall: {len(arrivals)} frames at the client, '
          f'{len(gaps) / (arrivals[-1] - arrivals[0]):.1f} frames/s, gap mean '
          f'{1e3 * gaps.mean():.1f} ms, std {1e3 * gaps.std():.1f} ms, 95th percentile '
          f'{1e3 * np.percentile(gaps, 95):.1f} ms, worst {1e3 * gaps.max():.1f} ms (target 30 '
          'frames/s: 33.3 ms)')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--contact', choices=('off', 'on', 'both'), default='both')
    parser.add_argument('--repeat', type=int, default=3)
    parser.add_argument('--intervals', type=int, default=100)
    parser.add_argument('--seconds', type=float, default=10.0)
    args = parser.parse_args()
    print(calibration_line())
    print('contact    motion pieces  ms/intvl  +view ms  share  snap ms  frame ms  fps(run)')
    for contact in {'off': (False,), 'on': (True,), 'both': (False, True)}[args.contact]:
        for motion in ('steady', 'reversing'):
            cost(contact, motion, args.intervals if not contact else args.intervals // 4,
                 args.repeat)
    engine_cost(args.intervals, args.repeat)
    steadiness(args.seconds)
    print(calibration_line())


if __name__ == '__main__':
    main()
