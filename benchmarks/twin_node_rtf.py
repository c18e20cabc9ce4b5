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
Benchmark: twin_node following sim_node live, on these cores, for ensemble sizes M.

The plant is sim_node (no recording, no feed; contact between pieces as --contact, in the
twin too) with N pieces placed at random on the annulus 0.05-0.17 m, a cone reversing
between -3 and 3 rad/s every 2 s (the pieces stay on it), its ``particle_states`` at 30 Hz
(``update_rate`` 30) as the twin's detections. For each M a fresh twin_node runs 25 s; from
its diagnostics of the last 15 s it prints the frames it took per second (30 keeps up), the
real-time factor (the stream time it took per wall second), its capacity (stream seconds
per second of computing), the p95 and the largest latency from a frame's arrival to the
publication of its estimates, the association rate and the pieces followed::

    .venv/bin/python benchmarks/twin_node_rtf.py [--pieces 30 60] [--members 4 8 16]
        [--twin-parameters 'smoother_pieces:=6' 'smoother_pieces:=2']
        [--forecast-period 0.1] [--forecast-thread true false] [--contact false true]
"""

import argparse
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from calibration import calibration_line
from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor

BIN = Path(sys.executable).parent


def start(command: list[str], domain: int) -> subprocess.Popen:
    """Start a node in the ROS domain given (its output to nowhere)."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    return subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)


def stop(proc: subprocess.Popen) -> None:
    """Stop a node with SIGTERM (a background shell ignores SIGINT)."""
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()


def case(pieces: int, members: int, period: float, domain: int, thread: bool,
         extra: str = '', contact: bool = False) -> None:
    """Run the plant and a twin of M members; print the figures of the last 15 s."""
    rng = np.random.default_rng(pieces)
    r = np.sqrt(rng.uniform(0.05 ** 2, 0.17 ** 2, pieces))
    a = rng.uniform(0.0, 2.0 * np.pi, pieces)
    positions = np.column_stack([r * np.cos(a), r * np.sin(a), np.full(pieces, 0.06)])
    plant = start([str(BIN / 'sim_node'), '--ros-args', '-p', "record_path:=''",
                   '-p', 'update_rate:=30.0', '-p', 'feed.rate:=0.0',
                   '-p', f'interactions.enabled:={str(contact).lower()}',
                   '-p', 'weigher.enabled:=false',
                   '-p', 'open_loop_pattern:=[2.0, -3.0, 2.0, 3.0]',
                   '-p', 'initial_pieces.positions:=['
                   + ', '.join(f'{v:.4f}' for v in positions.ravel()) + ']',
                   '-p', 'initial_pieces.d:=[' + ', '.join(['225.0'] * pieces) + ']'], domain)
    twin = start([str(BIN / 'twin_node'), '--ros-args', '-r', 'detections:=particle_states',
                  '-p', "record_path:=''", '-p', f'members:={members}',
                  '-p', f'forecast_period:={period}',
                  '-p', f'forecast_thread:={str(thread).lower()}',
                  '-p', f'interactions.enabled:={str(contact).lower()}',
                  *(part for item in extra.split() for part in ('-p', item))], domain)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('twin_bench', context=context)
    rows: list[dict[str, str]] = []
    started = time.monotonic()

    def take(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.endswith(': twin') and time.monotonic() > started + 10.0:
                rows.append({kv.key: kv.value for kv in status.values} | {
                    'state': status.message, 'wall': str(time.monotonic())})

    node.create_subscription(DiagnosticArray, '/diagnostics', take, 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        while time.monotonic() < started + 25.0:
            executor.spin_once(timeout_sec=0.1)
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
        stop(twin)
        stop(plant)
    if len(rows) < 2 or not any(int(row['frames']) for row in rows):
        print(f'N = {pieces}, M = {members}: no diagnostics from the twin', flush=True)
        return
    wall = float(rows[-1]['wall']) - float(rows[0]['wall'])
    frames = sum(int(row['frames']) for row in rows[1:])
    p95 = [float(row['latency p95 (ms)']) for row in rows[1:]]
    worst = [float(row['latency max (ms)']) for row in rows[1:]]
    capacity = [float(row['real-time factor (capacity)']) for row in rows[1:]]
    association = [float(row['association rate']) for row in rows[1:]]
    states = sorted({row['state'] for row in rows})
    print(f'N = {pieces}, M = {members}{", " + extra if extra else ""}, '
          f'contact {"on" if contact else "off"}, forecasts every '
          f'{period:g} s '
          f'({"on their own thread" if thread else "in turn"}): '
          f'{frames / wall:.1f} frames/s taken (of 30), RTF {frames / wall / 30:.3f}, '
          f'capacity {np.median(capacity):.2f} (median), latency p95 {np.nanmedian(p95):.1f} ms '
          f'(median over windows; max {np.nanmax(worst):.0f} ms), association '
          f'{np.median(association):.3f}, pieces {rows[-1].get("pieces")}, states {states}',
          flush=True)


def main() -> None:
    """Print the calibration and the cases."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--pieces', type=int, nargs='+', default=[30, 60])
    parser.add_argument('--members', type=int, nargs='+', default=[4, 8, 16])
    parser.add_argument('--forecast-period', type=float, default=0.1)
    parser.add_argument('--forecast-thread', nargs='+', default=['true'],
                        choices=['true', 'false'], help='twin_node forecast_thread values')
    parser.add_argument('--twin-parameters', nargs='+', default=[''],
                        help="twin_node parameters of each run in turn ('name:=value ...')")
    parser.add_argument('--contact', nargs='+', default=['false'], choices=['true', 'false'],
                        help='contact between pieces in the plant and the twin, in turn')
    args = parser.parse_args()
    print(calibration_line(), flush=True)
    domain = 40 + os.getpid() % 50
    for pieces in args.pieces:
        for members in args.members:
            for thread in args.forecast_thread:
                for extra in args.twin_parameters:
                    for contact in args.contact:
                        case(pieces, members, args.forecast_period, domain, thread == 'true',
                             extra, contact == 'true')
    print(calibration_line(), flush=True)


if __name__ == '__main__':
    main()
