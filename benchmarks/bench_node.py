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
The largest number of pieces that sim_node simulates and publishes at 50 Hz in real time.

The benchmark runs the real node (SimNode: engine tick, message building, CDR encoding and
rclpy publishing of every topic, markers at their default rate) in this process with
``real_time_factor`` 0 (as fast as possible) on one CPU core, and measures the achieved
real-time factor RTF = simulated time / wall time over ``--ticks`` ticks after
``--warmup`` ticks. The piece count N is doubled until RTF < 1, then bisected; the answer
is the largest N measured with RTF >= 1.

Scenarios (the piece count stays at N during a measurement):

* ``carried``: N pieces resting on the cone, spread over the annulus 0.03..0.20 m, the
  cone turning steadily at ``--omega`` rad/s (2 by default: the pieces stick and are
  carried; the integrator takes a few steps per piece and tick).
* ``sliding``: the same pieces with the cone reversing at +-``--omega`` rad/s every
  ``--reverse`` s (default +-8 rad/s every 2 s, the default open-loop pattern), so pieces
  slip and leave; every piece that leaves is replaced by a spawn at a random resting
  position in the next tick. This is far more work per piece than ``carried``.

With ``--subscriber`` a second process subscribes to particles, particle_states and markers
(raw bytes, on another core), so the publishing path includes delivery to a reader.
Examples::

    python benchmarks/bench_node.py                       # carried, no subscriber
    python benchmarks/bench_node.py --scenario sliding --subscriber
    python benchmarks/bench_node.py --counts 500 1000 2000  # fixed counts, no search

Timing figures depend on the machine and its load: the load average is printed with them.
"""

import argparse
import math
import os
from pathlib import Path
import subprocess
import sys
import time
from typing import Any

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

SUBSCRIBER = """
import sys, rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, DurabilityPolicy
from geometry_msgs.msg import PoseArray
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import MarkerArray
rclpy.init()
node = Node('bench_subscriber')
count = [0]
def cb(_):
    count[0] += 1
node.create_subscription(PoseArray, 'particles', cb, 10, raw=True)
node.create_subscription(PointCloud2, 'particle_states', cb, 10, raw=True)
node.create_subscription(MarkerArray, 'markers', cb,
                         QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL),
                         raw=True)
print('ready', flush=True)
try:
    rclpy.spin(node)
except BaseException:
    pass
print('received', count[0], flush=True)
"""


def resting_positions(model: Any, count: int, rng: np.random.Generator) -> np.ndarray:
    """Return count resting positions spread uniformly (per area) over 0.03..0.20 m."""
    from cone_feeder_sim.physics.simulation import resting_height
    rho = np.sqrt(rng.uniform(0.03 ** 2, 0.20 ** 2, count))
    theta = rng.uniform(0.0, 2.0 * math.pi, count)
    x, y = rho * np.cos(theta), rho * np.sin(theta)
    z = np.array([resting_height(model, model.product, a, b) for a, b in zip(x, y)])
    return np.column_stack([x, y, z])


def measure(context: Context, count: int, args: argparse.Namespace) -> dict[str, Any]:
    """Run the node with count pieces; return the achieved RTF and the time split."""
    from cone_feeder_sim.physics.params import ModelParams
    from cone_feeder_sim.ros.sim_node import SimNode
    model = ModelParams()
    rng = np.random.default_rng(count)
    positions = resting_positions(model, count, rng)
    if args.scenario == 'carried':
        pattern = [1.0e5, args.omega]
    else:
        pattern = [args.reverse, -args.omega, args.reverse, args.omega]
    params = [
        Parameter('update_rate', value=args.rate),
        Parameter('real_time_factor', value=0.0),
        Parameter('feed.rate', value=0.0),
        Parameter('feed.max_pieces', value=max(count, 1)),
        Parameter('open_loop_pattern', value=pattern),
        Parameter('initial_pieces.positions', value=positions.reshape(-1).tolist()),
        Parameter('initial_pieces.d'),  # NOT_SET: the default product for every piece
        Parameter('diagnostics.period', value=3600.0),
        Parameter('start_paused', value=True),
        Parameter('record_path', value=str(Path(args.record) / f'bench_{count}.mcap')
                  if args.record else ''),
    ]
    node = SimNode(context=context, parameter_overrides=params, namespace='/bench')
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        engine = node.engine
        steps = [0, 0]
        tick = engine.tick

        def counted_tick() -> Any:
            result = tick()
            steps[0] += result.stats.accepted
            steps[1] += result.stats.rejected
            return result

        engine.tick = counted_tick  # count the integrator's steps of the measured ticks

        def run(ticks: int) -> None:
            target = engine.tick_index + ticks
            node.set_paused(False)
            while engine.tick_index < target:
                if args.scenario == 'sliding' and engine.piece_count < count:
                    missing = count - engine.piece_count - sum(
                        len(p.positions) for p in engine.pending if hasattr(p, 'positions'))
                    if missing > 0:
                        engine.spawn(resting_positions(model, missing, rng))
                executor.spin_once(timeout_sec=0.1)
            node.set_paused(True)

        run(args.warmup)
        start_ticks = engine.tick_index
        _, step0, publish0 = node.timing
        steps[0] = steps[1] = 0
        wall0 = time.perf_counter()
        cpu0 = time.process_time()
        run(args.ticks)
        wall = time.perf_counter() - wall0
        cpu = time.process_time() - cpu0
        ticks = engine.tick_index - start_ticks
        _, step1, publish1 = node.timing
        return {
            'count': count, 'ticks': ticks, 'rtf': ticks * engine.dt / wall,
            'tick_ms': 1e3 * wall / ticks, 'cpu_ms': 1e3 * cpu / ticks,
            'step_ms': 1e3 * (step1 - step0) / ticks,
            'publish_ms': 1e3 * (publish1 - publish0) / ticks,
            'pieces_end': engine.piece_count,
            'steps': (steps[0] + steps[1]) / ticks / max(count, 1),
            'rejected': steps[1] / max(steps[0] + steps[1], 1),
        }
    finally:
        executor.shutdown()
        node.destroy_node()


def report(row: dict[str, Any]) -> None:
    """Print one measurement."""
    print(f"{row['count']:7d} {row['ticks']:6d} {row['tick_ms']:9.2f} {row['cpu_ms']:8.2f} "
          f"{row['step_ms']:9.2f} {row['publish_ms']:10.2f} {row['rtf']:7.2f} "
          f"{row['pieces_end']:8d} {row['steps']:10.2f} {row['rejected']:9.1%}", flush=True)


def main() -> int:
    """Parse the arguments, run the search and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenario', choices=('carried', 'sliding'), default='carried')
    parser.add_argument('--omega', type=float, default=None,
                        help='rad/s (default 2 carried, 8 sliding)')
    parser.add_argument('--reverse', type=float, default=2.0,
                        help='s between reversals (sliding)')
    parser.add_argument('--rate', type=float, default=50.0, help='update rate (Hz)')
    parser.add_argument('--warmup', type=int, default=25, help='ticks before measuring')
    parser.add_argument('--ticks', type=int, default=100, help='ticks measured')
    parser.add_argument('--start', type=int, default=250, help='first piece count')
    parser.add_argument('--max', type=int, default=32000, help='largest piece count tried')
    parser.add_argument('--resolution', type=float, default=0.05,
                        help='relative resolution of the bisection')
    parser.add_argument('--counts', type=int, nargs='*', help='measure these counts only')
    parser.add_argument('--cpu', type=int, default=0, help='core to pin to (-1: no pinning)')
    parser.add_argument('--record', metavar='DIR', default=None,
                        help='record every run to DIR/bench_COUNT.mcap (default: no recording)')
    parser.add_argument('--subscriber', action='store_true',
                        help='run a subscriber process on another core')
    parser.add_argument('--domain', type=int, default=None, help='ROS_DOMAIN_ID')
    args = parser.parse_args()
    if args.omega is None:
        args.omega = 2.0 if args.scenario == 'carried' else 8.0
    domain = args.domain if args.domain is not None else 210 + os.getpid() % 20
    if args.cpu >= 0 and hasattr(os, 'sched_setaffinity'):
        os.sched_setaffinity(0, {args.cpu})
    subscriber = None
    if args.subscriber:
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
        command = [sys.executable, '-c', SUBSCRIBER, '--ros-args', '-r', '__ns:=/bench']
        if args.cpu >= 0 and (os.cpu_count() or 1) > 1:
            other = (args.cpu + 1) % (os.cpu_count() or 1)
            command = ['taskset', '-c', str(other)] + command
        subscriber = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, text=True)
        assert subscriber.stdout is not None
        subscriber.stdout.readline()
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    rclpy.logging.set_logger_level('bench.sim_node', rclpy.logging.LoggingSeverity.WARN)
    print(f'# sim_node benchmark: scenario {args.scenario}, omega {args.omega:g} rad/s, '
          f'{args.rate:g} Hz, {args.ticks} ticks after {args.warmup}, core {args.cpu}, '
          f'subscriber {"yes" if args.subscriber else "no"}, load average '
          f'{" ".join(f"{v:.2f}" for v in os.getloadavg())}')
    print('# pieces  ticks  wall/tick  cpu/tick  step(ms)  publish(ms)     RTF  pieces@end '
          'steps/piece rejected')
    print('#                     (ms)      (ms)   (engine)    (encode+publish)            '
          '  per tick')
    try:
        measure(context, 5, argparse.Namespace(**{**vars(args), 'ticks': 5, 'warmup': 1}))
        if args.counts:
            for count in args.counts:
                report(measure(context, count, args))
            return 0
        good, bad = 0, None
        count = args.start
        while count <= args.max:
            row = measure(context, count, args)
            report(row)
            if row['rtf'] >= 1.0:
                good = count
                count *= 2
            else:
                bad = count
                break
        while bad is not None and bad - good > max(1, args.resolution * good):
            count = (good + bad) // 2
            row = measure(context, count, args)
            report(row)
            if row['rtf'] >= 1.0:
                good = count
            else:
                bad = count
        print(f'# largest piece count with real-time factor >= 1 at {args.rate:g} Hz: {good}'
              + (f' (fails at {bad})' if bad is not None else f' (limit --max {args.max})'))
    finally:
        context.try_shutdown()
        if subscriber is not None:
            subscriber.terminate()
            out, _ = subscriber.communicate(timeout=20)
            print(f'# subscriber: {out.strip()} messages (particles, particle_states, markers)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
