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
Fuzzing sim_node's inputs: random and malformed messages on every topic and service.

For a few hundred ticks, rotation_cmd and spawn get valid, extreme (NaN, inf, 1e300, huge,
empty, wrong frame) and malformed (random bytes, cut-off CDR) messages, and the services
are called at random. The node must stay up, its recording must stay readable, and the
mass on the cone, exited and failed must add up to the mass put on it.
"""

from collections.abc import Callable
from functools import partial
import math
from pathlib import Path
import random
import struct
from typing import Any

from cone_feeder_sim.formats.cdr import encode
from cone_feeder_sim.formats.mcap_reader import open_recording
from cone_feeder_sim.ros.sim_node import SimNode
from geometry_msgs.msg import PoseArray
import pytest
from rclpy.parameter import Parameter
import sim_process
from std_msgs.msg import Float64
from std_srvs.srv import SetBool, Trigger

TICKS = 300
ACTIONS = 500


def pose_array_bytes(rng: random.Random) -> bytes:
    """Return a PoseArray: valid, extreme or cut off."""
    count = rng.choice([0, 1, 3, 50, 5000])
    special = [math.nan, math.inf, -math.inf, 1e300, -1e300, 0.0]
    poses = []
    for _ in range(count):
        if rng.random() < 0.3:
            point = [rng.choice(special) for _ in range(3)]
        else:
            point = [rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(-0.1, 2.0)]
        poses.append({'position': dict(zip('xyz', point)),
                      'orientation': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}})
    frame = rng.choice(['', 'feeder', 'map', 'x' * 300])
    data = encode('geometry_msgs/msg/PoseArray', {
        'header': {'stamp': {'sec': 0, 'nanosec': 0}, 'frame_id': frame}, 'poses': poses})
    if rng.random() < 0.2:
        data = data[:rng.randrange(len(data))]  # cut off
    return data


def float_bytes(rng: random.Random) -> bytes:
    """Return a Float64: valid, extreme or malformed."""
    value = rng.choice([rng.uniform(-20, 20), math.nan, math.inf, -math.inf, 1e308, 0.0])
    data = b'\x00\x01\x00\x00' + struct.pack('<d', value)
    return data[:rng.randrange(len(data) + 1)] if rng.random() < 0.2 else data


def garbage(rng: random.Random) -> bytes:
    return bytes(rng.randrange(256) for _ in range(rng.randrange(0, 200)))


@pytest.mark.parametrize('seed', [1, 2])
@pytest.mark.slow
def test_the_node_survives_random_input(tmp_path: Path, seed: int) -> None:
    rng = random.Random(seed)
    path = tmp_path / 'fuzz.mcap'
    with sim_process.InProcess('fuzz_client', timeout=30.0, spin_step=0.005) as ros:
        overrides = [Parameter('record_path', value=str(path)),
                     Parameter('real_time_factor', value=0.0),
                     Parameter('feed.rate', value=20.0),
                     Parameter('feed.max_pieces', value=40)]
        sim = ros.add(SimNode(context=ros.context, parameter_overrides=overrides))
        node = ros.client
        cmd = node.create_publisher(Float64, 'rotation_cmd', 10)
        spawn = node.create_publisher(PoseArray, 'spawn', 10)
        clients = {name: node.create_client(kind, f'/sim_node/{name}')
                   for name, kind in (('reset', Trigger), ('pause', SetBool),
                                      ('step', Trigger))}
        assert ros.spin_until(lambda: cmd.get_subscription_count() > 0
                              and spawn.get_subscription_count() > 0
                              and all(c.service_is_ready() for c in clients.values()), 30.0)

        def send(publisher: Any, callback: Callable[[bytes], None], data: bytes) -> None:
            try:
                publisher.publish(data)
            except RuntimeError:  # the RMW refuses bytes it cannot send: hand them over
                callback(data)

        actions: list[Callable[[], Any]] = [
            lambda: send(cmd, partial(sim.inject, 'rotation_cmd'), float_bytes(rng)),
            lambda: send(cmd, partial(sim.inject, 'rotation_cmd'), garbage(rng)),
            lambda: send(spawn, partial(sim.inject, 'spawn'), pose_array_bytes(rng)),
            lambda: send(spawn, partial(sim.inject, 'spawn'), garbage(rng)),
            lambda: clients['step'].call_async(Trigger.Request()),
            lambda: clients['pause'].call_async(SetBool.Request(data=rng.random() < 0.3)),
            lambda: clients['reset'].call_async(Trigger.Request()) if rng.random() < 0.1
            else None,
        ]
        balance_checked = 0
        done = 0
        while sim.engine.tick_index < TICKS or done < ACTIONS:
            rng.choice(actions)()
            done += 1
            ros.spin_until(lambda: False, 0.01)
            if sim.paused and rng.random() < 0.3:
                sim.set_paused(False)
            res = sim.last_tick
            if res is not None:
                assert res.mass_in == pytest.approx(
                    float(res.masses.sum()) + float(res.channel_mass.sum()) + res.failed_mass,
                    rel=1e-9)
                balance_checked += 1
        assert sim.totals.refused > 0 and balance_checked > 0
        recording_path = sim.recording_path
    recording = open_recording(recording_path)
    assert recording.complete and recording.problem is None
    assert recording.topics['/particle_states'].message_count >= TICKS
