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
Benchmark of the CDR encoder and decoder against rosbags' serialize_cdr and deserialize_cdr.

Usage: python benchmarks/bench_cdr.py [--count 150] [--repeat 7]

The messages are the node's: a geometry_msgs/msg/PoseArray of `count` poses (given to the
encoder as the (n, 7) numpy array the node passes, and as a list of dicts) and the
particle_states sensor_msgs/msg/PointCloud2 of `count` points (a structured numpy array).
rosbags serialises its own message objects (made by deserialising the same bytes, so both
sides write identical bytes, which is checked). Each figure is the best of `repeat` timeit
runs, each long enough to take about 0.2 s, as time per message. A fixed pure-Python
workload (a loop of 3 million additions) is timed first, to compare machines.
"""

import argparse
from collections.abc import Callable
from functools import partial
from pathlib import Path
import sys
import timeit
from typing import Any

from calibration import calibration_line, calibration_loop
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def best_seconds(function: Callable[[], Any], repeat: int) -> float:
    """Return the best time of one call of ``function`` over ``repeat`` timeit runs."""
    timer = timeit.Timer(function)
    number, _ = timer.autorange()
    number = max(1, number)
    return min(timer.repeat(repeat=repeat, number=number)) / number


def cases(count: int) -> list[tuple[str, str, Any]]:
    """Return (label, type name, message as the node encodes it) of each message."""
    from cone_feeder_sim.formats.messages import header, particles_message, states_message
    rng = np.random.default_rng(1)
    head = header(12.34, 'cone')
    positions = rng.uniform(-0.2, 0.2, (count, 3))
    velocities = rng.uniform(-1.0, 1.0, (count, 3))
    ids = np.arange(count, dtype=np.int64)
    masses = np.full(count, 0.004)
    poses = particles_message(head, positions)
    pose_dicts = {'header': head, 'poses': [
        {'position': dict(zip('xyz', row[:3].tolist())),
         'orientation': dict(zip('xyzw', row[3:].tolist()))} for row in poses['poses']]}
    return [
        (f'PoseArray, {count} poses (numpy)', 'geometry_msgs/msg/PoseArray', poses),
        (f'PoseArray, {count} poses (dicts)', 'geometry_msgs/msg/PoseArray', pose_dicts),
        (f'PointCloud2, {count} points', 'sensor_msgs/msg/PointCloud2',
         states_message(head, ids, positions, velocities, masses)),
    ]


def main() -> int:
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--count', type=int, default=150, help='poses and points per message')
    parser.add_argument('--repeat', type=int, default=7, help='timeit runs; the best counts')
    args = parser.parse_args()
    from cone_feeder_sim.formats.cdr import CdrCodec
    from rosbags.typesys import get_typestore, Stores
    calibration = best_seconds(calibration_loop, args.repeat)
    print(f'{calibration_line(calibration)} (best of {args.repeat})')
    codec = CdrCodec()
    typestore = get_typestore(Stores.ROS2_JAZZY)
    print(f'{"message":<32} {"operation":<9} {"cone_feeder_sim µs":>18} {"rosbags µs":>11} '
          f'{"rosbags / ours":>15}')
    decoded: set = set()
    for label, type_name, message in cases(args.count):
        data = codec.encode(type_name, message)
        theirs = typestore.deserialize_cdr(data, type_name)
        if bytes(typestore.serialize_cdr(theirs, type_name)) != data:
            raise SystemExit(f'{label}: rosbags writes different bytes')
        rows = [('encode', partial(codec.encode, type_name, message),
                 partial(typestore.serialize_cdr, theirs, type_name))]
        if type_name not in decoded:  # the bytes are the same whatever the encoder's input
            decoded.add(type_name)
            rows.append(('decode', partial(codec.decode, type_name, data),
                         partial(typestore.deserialize_cdr, data, type_name)))
        for operation, ours, rosbags in rows:
            mine = best_seconds(ours, args.repeat)
            other = best_seconds(rosbags, args.repeat)
            print(f'{label:<32} {operation:<9} {mine * 1e6:>18.1f} {other * 1e6:>11.1f} '
                  f'{other / mine:>14.1f}x')
    return 0


if __name__ == '__main__':
    sys.exit(main())
