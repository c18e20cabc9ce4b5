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
sim_node as its own process, driven from a separate test node over ROS 2.

Each test starts `python -m cone_feeder_sim.ros.sim_node` from this source tree with its own
ROS_DOMAIN_ID and namespace, and stops it with SIGINT (killed if it hangs) at the end.
Messages are received with rclpy's own type support, so these tests also check that the
node's hand-encoded CDR bytes are what ROS 2 expects.
"""

from collections.abc import Iterator
import math
import os
from pathlib import Path
import random
import sys
import time
from typing import Any

from cone_feeder_sim.formats.pointcloud import EXIT_DTYPE, STATE_DTYPE
from cone_feeder_sim.physics.params import ChannelLayout
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray
import numpy as np
import pytest
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState, PointCloud2
from sim_process import (
    Client, FIRST_MESSAGE_TIMEOUT, pose_array, random_domain, SimProcess, wait_for_log)
from std_msgs.msg import Float64, Float64MultiArray
from std_srvs.srv import SetBool, Trigger

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / 'config' / 'sim_node.yaml'
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class Session:
    """A sim_node process and a client on a private domain."""

    def __init__(self, tmp_path: Path, params: dict[str, str]) -> None:
        domain = random_domain()
        # a namespace of its own as well, in case another run drew the same domain
        self.namespace = f'/proc{random.randrange(1_000_000)}'
        args = [sys.executable, '-m', 'cone_feeder_sim.ros.sim_node', '--ros-args',
                '--params-file', str(CONFIG), '-r', f'__ns:={self.namespace}']
        for name, value in params.items():
            args += ['-p', f'{name}:={value}']
        env = dict(os.environ)
        env['PYTHONPATH'] = os.pathsep.join([str(ROOT)] + (
            [env['PYTHONPATH']] if env.get('PYTHONPATH') else []))
        self.process = SimProcess(args, domain, tmp_path / 'sim_node.log', env=env,
                                  cwd=tmp_path)
        self.client = Client(domain, namespace=self.namespace)

    def subscribe(self, msg_type: Any, topic: str, qos: Any = 10) -> list:
        received: list = []
        self.client.node.create_subscription(msg_type, topic, received.append, qos)
        return received

    def first(self, received: list) -> None:
        assert self.client.spin_until(
            lambda: bool(received) or not self.process.alive(), FIRST_MESSAGE_TIMEOUT), \
            self.process.log()
        assert received, self.process.log()

    def service(self, srv_type: Any, name: str, request: Any) -> Any:
        return self.client.call(srv_type, f'{self.namespace}/sim_node/{name}', request)

    def close(self) -> int:
        self.client.close()
        return self.process.stop()


@pytest.fixture
def session(tmp_path: Path) -> Iterator[Any]:
    sessions: list[Session] = []

    def start(**params: Any) -> Session:
        text = {name: str(value).lower() if isinstance(value, bool) else str(value)
                for name, value in params.items()}
        sessions.append(Session(tmp_path, text))
        return sessions[-1]

    try:
        yield start
    finally:
        for item in sessions:
            item.close()


def stamp_ns(msg: Any) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def test_poses_arrive_at_the_configured_rate(session: Any) -> None:
    sim = session()
    # one subscription holds each message with its arrival time: two subscriptions to one
    # topic drop messages apart from each other (each has its own queue of 10), so the
    # arrivals of one do not count the messages of the other
    received: list = []
    arrivals: list[float] = []

    def take(msg: PoseArray) -> None:
        arrivals.append(time.monotonic())
        received.append(msg)

    sim.client.node.create_subscription(PoseArray, 'particles', take, 10)
    diagnostics: list = []
    ours = f'{sim.namespace}/sim_node: simulation'
    sim.client.node.create_subscription(
        DiagnosticArray, '/diagnostics',
        lambda m: diagnostics.append(m) if m.status[0].name == ours else None, 10)
    sim.first(received)
    start = len(received)
    assert sim.client.spin_until(lambda: len(received) >= start + 100, 30.0)
    msgs = received[start:]
    stamps = np.array([stamp_ns(m) for m in msgs])
    steps = np.diff(stamps)
    # simulated time: exactly dt = 1 / update_rate between ticks (a multiple if one was lost)
    assert np.all(steps % 20_000_000 == 0) and np.all(steps > 0)
    assert np.mean(steps == 20_000_000) >= 0.9
    assert all(m.header.frame_id == 'feeder' for m in msgs)
    for msg in msgs:
        assert all(math.hypot(p.position.x, p.position.y) < 0.225 for p in msg.poses)
    # wall clock: about 50 per second at real_time_factor 1 (loose: the machine is shared
    # and the arrival times of this client jitter)
    wall = arrivals[-1] - arrivals[start]
    assert (len(arrivals) - 1 - start) / wall == pytest.approx(50.0, rel=0.6)
    # the node's own measurement: never faster than asked (no burst of caught-up ticks); and
    # where it kept up (nothing given up, no tick over its period, the lag within the period)
    # not slower either: a pacer that ran at half speed would show 0.5 here
    assert sim.client.spin_until(lambda: len(diagnostics) >= 2, 30.0)
    for msg in diagnostics:
        status = msg.status[0]
        values = {kv.key: kv.value for kv in status.values}
        assert float(values['real-time factor (target)']) == 1.0
        achieved = float(values['real-time factor (achieved)'])
        assert 0.2 < achieved <= 1.05
        if (float(values['time given up (s)']) == 0.0
                and values['overruns (ticks longer than the period)'] == '0'
                and float(values['lag behind the wall clock max (ms)']) < 20.0):
            assert achieved >= 0.9, values


def test_rotation_commands_are_followed_within_the_acceleration_limit(session: Any) -> None:
    accel = 10.0
    sim = session(max_angular_acceleration=accel, cmd_timeout=0.5)
    states = sim.subscribe(JointState, 'cone_state')
    sim.first(states)
    assert all(s.name == ['cone'] for s in states)
    pub = sim.client.node.create_publisher(Float64, 'rotation_cmd', 10)
    timer = sim.client.node.create_timer(0.05, lambda: pub.publish(Float64(data=5.0)))
    assert sim.client.spin_until(lambda: abs(states[-1].velocity[0] - 5.0) < 1e-9, 30.0)
    reached = len(states)
    sim.client.spin_for(0.3)
    assert all(abs(s.velocity[0] - 5.0) < 1e-9 for s in states[reached:])
    # commands stop: the cone ramps to rest after cmd_timeout
    sim.client.node.destroy_timer(timer)
    assert sim.client.spin_until(lambda: states[-1].velocity[0] == 0.0, 30.0)
    t = np.array([stamp_ns(s) for s in states]) * 1e-9
    omega = np.array([s.velocity[0] for s in states])
    angle = np.array([s.position[0] for s in states])
    rates = np.abs(np.diff(omega)) / np.diff(t)
    assert np.max(rates) <= accel * (1 + 1e-9)
    assert np.max(rates) == pytest.approx(accel)
    # the angle is the integral of omega (trapezoid exact for the piecewise-linear ramp
    # between samples 20 ms apart, up to the kinks inside a tick)
    np.testing.assert_allclose(np.diff(angle), 0.5 * (omega[1:] + omega[:-1]) * np.diff(t),
                               atol=accel * 0.02 ** 2)


def test_exit_events_and_channel_mass_agree(session: Any) -> None:
    sim = session(start_paused=True, real_time_factor=0.0, **{'feed.rate': 40.0})
    events = sim.subscribe(PointCloud2, 'exit_events',
                           QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    totals = sim.subscribe(Float64MultiArray, 'channel_mass', LATCHED)
    subs = list(sim.client.node.subscriptions)
    assert sim.client.spin_until(lambda: all(s.get_publisher_count() for s in subs),
                                 FIRST_MESSAGE_TIMEOUT), sim.process.log()
    assert sim.service(SetBool, 'pause', SetBool.Request(data=False)).success

    def exits() -> np.ndarray:
        rows = [np.frombuffer(bytes(m.data), dtype=EXIT_DTYPE) for m in events]
        return np.concatenate(rows) if rows else np.zeros(0, dtype=EXIT_DTYPE)

    assert sim.client.spin_until(lambda: len(exits()) >= 30, FIRST_MESSAGE_TIMEOUT)
    assert sim.service(SetBool, 'pause', SetBool.Request(data=True)).success

    def agree() -> bool:
        if not totals:
            return False
        total = np.zeros(14)
        rows = exits()
        np.add.at(total, rows['channel'].astype(int) - 1, rows['mass'])
        return np.allclose(total, totals[-1].data, rtol=0, atol=1e-12)

    assert sim.client.spin_until(agree, 30.0)
    rows = exits()
    assert [f.name for f in events[0].fields] == list(EXIT_DTYPE.names)
    assert len(np.unique(rows['id'])) == len(rows)
    assert np.all(np.diff(rows['exit_time']) >= -0.02)
    for msg in events:
        part = np.frombuffer(bytes(msg.data), dtype=EXIT_DTYPE)
        assert msg.width == len(part) and msg.point_step == 80
        t = stamp_ns(msg) * 1e-9
        assert np.all((part['exit_time'] > t - 0.02 - 1e-9) & (part['exit_time'] <= t + 1e-9))
    np.testing.assert_allclose(np.hypot(rows['x'], rows['y']), 0.225, atol=1e-6)
    channels = ChannelLayout().channel_of(np.degrees(rows['angle']))
    np.testing.assert_array_equal(channels, rows['channel'])
    assert totals[-1].layout.dim[0].label == 'channel'
    assert sum(totals[-1].data) == pytest.approx(rows['mass'].sum(), abs=1e-12)


#: The spawn messages of these tests.
spawn_message = pose_array


def test_spawn_reset_pause_and_step(session: Any) -> None:
    sim = session(start_paused=True, **{'feed.rate': 0.0})
    particles = sim.subscribe(PoseArray, 'particles')
    states = sim.subscribe(PointCloud2, 'particle_states')
    totals = sim.subscribe(Float64MultiArray, 'channel_mass', LATCHED)
    step = sim.service(Trigger, 'step', Trigger.Request())
    assert step.success, step.message
    sim.first(particles)
    assert stamp_ns(particles[-1]) == 20_000_000 and len(particles[-1].poses) == 5
    pub = sim.client.node.create_publisher(PoseArray, 'spawn', 10)
    assert sim.client.spin_until(lambda: pub.get_subscription_count() > 0, 30.0)
    pub.publish(spawn_message((0.05, 0.02, 0.06), (0.3, 0.0, 0.05)))
    assert wait_for_log(sim.process, sim.client, 'refused 1 of 2 poses', 30.0)
    assert sim.service(Trigger, 'step', Trigger.Request()).success
    assert sim.client.spin_until(lambda: stamp_ns(particles[-1]) == 40_000_000, 30.0)
    assert len(particles[-1].poses) == 6
    assert sim.client.spin_until(lambda: states and states[-1].width == 6, 30.0)
    cloud = np.frombuffer(bytes(states[-1].data), dtype=STATE_DTYPE)
    assert list(cloud['id']) == [0, 1, 2, 3, 4, 5]
    np.testing.assert_allclose([cloud['x'][5], cloud['y'][5]], [0.05, 0.02], atol=1e-3)
    reset = sim.service(Trigger, 'reset', Trigger.Request())
    assert reset.success and 'next tick' in reset.message
    assert sim.service(Trigger, 'step', Trigger.Request()).success
    assert sim.client.spin_until(lambda: stamp_ns(particles[-1]) == 60_000_000, 30.0)
    assert len(particles[-1].poses) == 5
    assert sim.client.spin_until(lambda: states[-1].width == 5, 30.0)
    cloud = np.frombuffer(bytes(states[-1].data), dtype=STATE_DTYPE)
    assert list(cloud['id']) == [6, 7, 8, 9, 10]  # ids keep counting after a reset
    assert sim.client.spin_until(lambda: bool(totals), 30.0)
    assert sum(totals[-1].data) == 0.0
    # running again: time flows, and ~/step is refused
    assert sim.service(SetBool, 'pause', SetBool.Request(data=False)).success
    assert sim.client.spin_until(lambda: stamp_ns(particles[-1]) >= 200_000_000, 30.0)
    refused = sim.service(Trigger, 'step', Trigger.Request())
    assert not refused.success and 'not paused' in refused.message
    # SIGINT ends the node cleanly
    assert sim.close() == 0
    assert 'Traceback' not in sim.process.log()


def set_parameter(sim: Session, name: str, value: Any) -> Any:
    request = SetParameters.Request()
    request.parameters = [Parameter(name, value=value).to_parameter_msg()]
    return sim.service(SetParameters, 'set_parameters', request).results[0]


def test_bad_input_is_refused_while_the_node_keeps_running(session: Any) -> None:
    sim = session()
    particles = sim.subscribe(PoseArray, 'particles')
    sim.first(particles)
    cmd = sim.client.node.create_publisher(Float64, 'rotation_cmd', 10)
    spawn = sim.client.node.create_publisher(PoseArray, 'spawn', 10)
    assert sim.client.spin_until(
        lambda: cmd.get_subscription_count() and spawn.get_subscription_count(), 30.0)
    cmd.publish(Float64(data=math.nan))
    assert wait_for_log(sim.process, sim.client, 'rotation_cmd refused', 30.0)
    spawn.publish(spawn_message((0.05, 0.0, 0.06), frame='map'))
    assert wait_for_log(sim.process, sim.client, "frame 'map'", 30.0)
    spawn.publish(spawn_message((0.0, 0.0, -1.0), (1.0, 1.0, 0.1)))
    assert wait_for_log(sim.process, sim.client, 'refused 2 of 2 poses', 30.0)
    result = set_parameter(sim, 'feed.rho_max', 0.3)
    assert not result.successful and 'inside the cone' in result.reason
    result = set_parameter(sim, 'model.d', 10.0)
    assert not result.successful and 'read-only' in result.reason
    result = set_parameter(sim, 'max_angular_acceleration', -1.0)
    assert not result.successful
    result = set_parameter(sim, 'feed.rate', 0.5)
    assert result.successful
    # still running: new states keep coming
    count = len(particles)
    assert sim.client.spin_until(lambda: len(particles) >= count + 25, 30.0)
    assert sim.process.alive()
    assert stamp_ns(particles[-1]) > stamp_ns(particles[count - 1])
