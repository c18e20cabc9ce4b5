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
Benchmark: the live node as a user runs it, measured from another process.

Starts ``sim_node`` (its own process, default config, recording on, 50 Hz, real time) with
the feed keeping N pieces on the cone (``feed.rate`` high, ``feed.max_pieces`` N, the
default reversing pattern), and measures from this process:

* start: wall time from launching the process to the first ``particles`` message;
* real-time factor from ``/clock`` over ``--seconds`` of wall time after the cone holds N
  pieces: the whole window and the worst ``--window``-second window;
* the longest wall-clock gap between two ``/clock`` messages (how long subscribers wait);
* the node's own step and publish times, its longest tick and its longest executor
  callback (how long its executor was blocked; absent before the worker thread), from
  ``/diagnostics``.

Prints the calibration workload first. Example::

    .venv/bin/python benchmarks/bench_live.py --pieces 150 2000 --seconds 60
"""

import argparse
import os
from pathlib import Path
import random
import subprocess
import sys
import tempfile
import time

from calibration import calibration_line
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

ROOT = Path(__file__).resolve().parent.parent


def measure(pieces: int, seconds: float, window: float, rate: float,
            extra: list[str], tree: Path) -> dict[str, float]:
    """Run one node with ``pieces`` on the cone; return the measured figures."""
    domain = random.randrange(1, 200)
    context = Context()
    rclpy.init(args=[], context=context, domain_id=domain)
    node = Node('bench_live', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    clock: list[tuple[float, float]] = []
    diags: list[dict[str, str]] = []
    first: list[float] = []
    node.create_subscription(
        Clock, '/clock', lambda m: clock.append(
            (time.monotonic(), m.clock.sec + 1e-9 * m.clock.nanosec)),
        QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    node.create_subscription(
        PoseArray, 'particles', lambda m: first or first.append(time.monotonic()), 10)
    node.create_subscription(
        DiagnosticArray, '/diagnostics', lambda m: diags.extend(
            {kv.key: kv.value for kv in s.values} for s in m.status
            if s.name.endswith('simulation')), 10)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONPATH=str(tree))
    module = ('cone_feeder_sim.ros.sim_node' if (tree / 'cone_feeder_sim' / 'ros').is_dir()
              else 'cone_feeder_sim.sim_node')  # the layout before 0.2
    with tempfile.TemporaryDirectory() as tmp:
        start = time.monotonic()
        proc = subprocess.Popen(
            [sys.executable, '-m', module, '--ros-args',
             '--params-file', str(tree / 'config' / 'sim_node.yaml'),
             '-p', 'publish_clock:=true', '-p', f'feed.rate:={rate}',
             '-p', f'feed.max_pieces:={pieces}', '-p', f'record_path:={tmp}/run.mcap',
             *[arg for item in extra for arg in ('-p', item)]],
            env=env, cwd=tmp, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            while not first and time.monotonic() - start < 300:
                executor.spin_once(timeout_sec=0.05)
            started = first[0] - start if first else float('nan')
            while time.monotonic() - start < 600:  # until the cone holds N pieces
                executor.spin_once(timeout_sec=0.05)
                if diags and int(diags[-1].get('pieces', 0)) >= 0.98 * pieces:
                    break
            clock.clear()
            diags.clear()
            begin = time.monotonic()
            while time.monotonic() - begin < seconds:
                executor.spin_once(timeout_sec=0.05)
        finally:
            proc.send_signal(2)
            proc.wait(timeout=60)
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown(context=context)
    wall = clock[-1][0] - clock[0][0]
    rtf = (clock[-1][1] - clock[0][1]) / wall
    worst = min(
        (clock[j][1] - clock[i][1]) / (clock[j][0] - clock[i][0])
        for i in range(len(clock)) for j in [next(
            (j for j in range(i, len(clock)) if clock[j][0] - clock[i][0] >= window), -1)]
        if j > i)
    steps = [float(d['step time mean (ms)']) for d in diags if 'step time mean (ms)' in d]
    pubs = [float(d['publish time mean (ms)']) for d in diags if 'publish time mean (ms)' in d]
    peak = [float(d['step time max (ms)']) for d in diags if 'step time max (ms)' in d]
    key = 'executor callback max (ms)'
    blocked = [float(d[key]) for d in diags if key in d]
    gap = max(clock[i + 1][0] - clock[i][0] for i in range(len(clock) - 1))
    return {'start_s': started, 'rtf': rtf, 'worst_rtf': worst, 'gap_ms': 1e3 * gap,
            'blocked_ms': max(blocked) if blocked else float('nan'),
            'step_ms': sum(steps) / max(len(steps), 1),
            'publish_ms': sum(pubs) / max(len(pubs), 1), 'step_max_ms': max(peak or [0.0]),
            'pieces': float(diags[-1]['pieces']) if diags else float('nan')}


def main() -> None:
    """Print the calibration and one row per piece count."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--pieces', type=int, nargs='+', default=[150, 2000])
    parser.add_argument('--seconds', type=float, default=60.0)
    parser.add_argument('--window', type=float, default=10.0)
    parser.add_argument('--rate', type=float, default=500.0, help='feed.rate (pieces/s)')
    parser.add_argument('--tree', type=Path, default=ROOT,
                        help='source tree of the node to measure (e.g. an old main checked out '
                             'in a temporary directory); default: this one')
    parser.add_argument('-p', dest='extra', action='append', default=[],
                        help='another parameter of the node, NAME:=VALUE (repeatable)')
    args = parser.parse_args()
    print(calibration_line())
    print(f'# tree {args.tree}')
    print(f'# {args.seconds:g} s of wall time per count, 50 Hz, recording on, '
          f'{" ".join(args.extra) or "default parameters"}, '
          f'load average {" ".join(f"{v:.2f}" for v in os.getloadavg())}')
    print(f'{"pieces":>7} {"start s":>8} {"RTF":>6} {"worst":>6} {"step ms":>8} '
          f'{"pub ms":>7} {"max ms":>7} {"gap ms":>7} {"exec ms":>7}')
    for count in args.pieces:
        r = measure(count, args.seconds, args.window, args.rate, args.extra, args.tree)
        print(f'{int(r["pieces"]):>7} {r["start_s"]:>8.2f} {r["rtf"]:>6.3f} '
              f'{r["worst_rtf"]:>6.3f} {r["step_ms"]:>8.2f} {r["publish_ms"]:>7.2f} '
              f'{r["step_max_ms"]:>7.1f} {r["gap_ms"]:>7.1f} {r["blocked_ms"]:>7.1f}',
              flush=True)


if __name__ == '__main__':
    main()
