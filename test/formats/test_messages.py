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
Tests of the message building shared by sim_node and the headless runner.

Messages are encoded with the package's CDR encoder and decoded with rosbags' typestore
(independent of the encoder), so the point layouts are checked from the outside.
"""

import math

from cone_feeder_sim.formats.cdr import default_codec, encode
from cone_feeder_sim.formats.messages import (
    channel_mass_message, cone_state_message, exits_message, header, MarkerBuilder, MarkerSchedule,
    particles_message, stamp, stamp_ns, states_message)
from cone_feeder_sim.formats.pointcloud import EXIT_DTYPE, STATE_DTYPE
from cone_feeder_sim.formats.topics import TOPICS
from cone_feeder_sim.physics.params import ModelParams
from cone_feeder_sim.physics.simulation import ExitEvents
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

STORE = get_typestore(Stores.ROS2_JAZZY)


def decode(type_name: str, message: dict) -> object:
    return STORE.deserialize_cdr(encode(type_name, message), type_name)


def test_stamps_round_to_the_nanosecond() -> None:
    assert stamp(0.02) == {'sec': 0, 'nanosec': 20_000_000}
    assert stamp(3 * 0.1) == {'sec': 0, 'nanosec': 300_000_000}
    assert stamp_ns(12345.678901234) == 12_345_678_901_234
    assert header(1.5, 'feeder') == {'stamp': {'sec': 1, 'nanosec': 500_000_000},
                                     'frame_id': 'feeder'}


def test_state_cloud_layout() -> None:
    rng = np.random.default_rng(1)
    positions, velocities = rng.normal(size=(4, 3)), rng.normal(size=(4, 3))
    ids = np.array([0, 7, 2 ** 32 + 5, 3], dtype=np.int64)
    masses = np.array([0.1, 0.2, 0.3, 0.125])
    msg = decode('sensor_msgs/msg/PointCloud2',
                 states_message(header(0.02, 'feeder'), ids, positions, velocities, masses))
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (1, 4, 32, 128)
    assert [f.name for f in msg.fields] == list(STATE_DTYPE.names)
    points = np.frombuffer(msg.data.tobytes(), dtype=STATE_DTYPE)
    np.testing.assert_array_equal(points['x'], positions[:, 0].astype(np.float32))
    np.testing.assert_array_equal(points['vz'], velocities[:, 2].astype(np.float32))
    assert points['id'].tolist() == [0, 7, 5, 3]  # wraps at 2**32 on the wire
    np.testing.assert_array_equal(points['mass'], masses.astype(np.float32))


def test_exit_cloud_layout() -> None:
    exits = ExitEvents(ids=np.array([4]), t=np.array([1.234]), angle_deg=np.array([90.0]),
                       channel=np.array([3]), position=np.array([[0.0, 0.225, 0.0]]),
                       velocity=np.array([[0.5, 0.0, 0.0]]), mass=np.array([0.1234567]))
    msg = decode('sensor_msgs/msg/PointCloud2', exits_message(header(1.24, 'feeder'), exits))
    assert msg.point_step == 80 and [f.datatype for f in msg.fields] == [8] * 9 + [6, 6]
    row = np.frombuffer(msg.data.tobytes(), dtype=EXIT_DTYPE)[0]
    assert (row['id'], row['channel'], row['exit_time'], row['mass']) == (
        4, 3, 1.234, 0.1234567)
    assert row['angle'] == pytest.approx(math.pi / 2)


def test_small_messages() -> None:
    msg = decode('std_msgs/msg/Float64MultiArray', channel_mass_message(np.arange(14.0)))
    assert msg.layout.dim[0].label == 'channel' and msg.layout.dim[0].size == 14
    assert msg.data.tolist() == list(range(14))
    msg = decode('sensor_msgs/msg/JointState',
                 cone_state_message(header(0.5, 'feeder'), 2.5, -8.0))
    assert (list(msg.name), msg.position.tolist(), msg.velocity.tolist()) == (
        ['cone'], [2.5], [-8.0])
    msg = decode('geometry_msgs/msg/PoseArray',
                 particles_message(header(0.5, 'feeder'), np.array([[0.1, 0.2, 0.3]])))
    pose = msg.poses[0]
    assert (pose.position.x, pose.position.z, pose.orientation.w) == (0.1, 0.3, 1.0)


def test_markers_show_cone_channels_and_pieces() -> None:
    builder = MarkerBuilder(ModelParams(), 'feeder')
    msg = decode('visualization_msgs/msg/MarkerArray', builder.message(
        header(0.1, 'feeder'), 0.3, np.array([[0.1, 0.0, 0.02], [0.0, 0.1, 0.02]])))
    namespaces = [m.ns for m in msg.markers]
    assert namespaces.count('channel_labels') == 14
    assert {'cone', 'channels', 'cone_angle', 'pieces'} <= set(namespaces)
    pieces = next(m for m in msg.markers if m.ns == 'pieces')
    assert len(pieces.points) == 2
    empty = decode('visualization_msgs/msg/MarkerArray',
                   builder.message(header(0.1, 'feeder'), 0.0, np.zeros((0, 3))))
    assert next(m for m in empty.markers if m.ns == 'pieces').action == 2  # DELETE


def test_marker_schedule() -> None:
    schedule = MarkerSchedule(10.0)
    due = [k for k in range(1, 21) if schedule.due(k * 0.02)]
    assert due == [1, 6, 11, 16]  # every 0.1 s of simulated time
    assert schedule.due(21 * 0.02, reset=True)
    schedule.restart()
    assert schedule.due(22 * 0.02)  # the tick after a reset too
    assert not MarkerSchedule(0.0).due(1.0, reset=True)


def test_every_topic_type_has_a_full_definition() -> None:
    registry = default_codec().registry
    for spec in TOPICS.values():
        assert registry.full_text(spec.type_name)
        assert spec.direction in ('in', 'out')
    assert TOPICS['exit_events'].qos.depth == 1000
    assert TOPICS['markers'].qos.durability == 'transient_local'
