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

"""Tests of the example controller: its decision rule, cloud parsing, and a closed loop."""

import time

from cone_feeder_sim.errors import ParameterError
from cone_feeder_sim.formats.cdr import encode
from cone_feeder_sim.formats.pointcloud import cloud_points, EXIT_DTYPE, point_fields
from cone_feeder_sim.ros.example_controller import (
    choose_direction, DirectionLearner, ExampleController)
from cone_feeder_sim.ros.sim_node import SimNode
import numpy as np
import pytest
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import PointCloud2

CW, CCW = -1, 1


def test_cloud_points_reads_an_rclpy_exit_event_message() -> None:
    rows = np.zeros(3, dtype=EXIT_DTYPE)
    rows['channel'] = [2, 14, 7]
    rows['mass'] = [0.1, 0.2, 0.3]
    rows['exit_time'] = [1.0, 1.01, 1.02]
    data = encode('sensor_msgs/msg/PointCloud2', {
        'header': {'stamp': {'sec': 1, 'nanosec': 0}, 'frame_id': 'feeder'}, 'height': 1,
        'width': 3, 'fields': list(point_fields(EXIT_DTYPE)),
        'is_bigendian': False, 'point_step': 80, 'row_step': 240, 'data': rows,
        'is_dense': True})
    parsed = cloud_points(deserialize_message(data, PointCloud2))
    np.testing.assert_array_equal(parsed['channel'], [2, 14, 7])
    np.testing.assert_array_equal(parsed['mass'], [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(parsed['exit_time'], rows['exit_time'])


def test_choose_direction_explores_then_fills_the_deficit() -> None:
    empty = {CCW: np.zeros(4), CW: np.zeros(4)}
    unused = {CCW: 0, CW: 0}
    masses = np.array([1.0, 0.0, 1.0, 0.0])
    # no data for the other direction: try it
    assert choose_direction(empty, masses, unused, 3, CW) == CCW
    learned = {CCW: np.array([1.0, 0.0, 1.0, 0.0]), CW: np.array([0.0, 1.0, 0.0, 1.0])}
    # channels 2 and 4 lack product and clockwise rotation feeds them
    assert choose_direction(learned, masses, unused, 3, CCW) == CW
    assert choose_direction(learned, masses, unused, 3, CW) == CW
    assert choose_direction(learned, np.array([0.0, 1.0, 0.0, 1.0]), unused, 3, CW) == CCW
    # a direction unused for explore_after periods is tried again
    assert choose_direction(learned, masses, {CCW: 3, CW: 0}, 3, CW) == CCW
    # balanced: alternate
    assert choose_direction(learned, np.ones(4), unused, 3, CW) == CCW


def test_the_learner_learns_where_each_direction_sends_product() -> None:
    # clockwise rotation sends product to channels 1-2, counter-clockwise to 3-4
    learner = DirectionLearner(learning_rate=0.5, explore_after=3, direction=CW)
    hoppers = np.array([0.5, 0.5, 0.0, 0.0])  # heads 3 and 4 are empty
    for _ in range(2):  # one period each way (the other direction has no data yet)
        feeds = [1, 2] if learner.direction == CW else [3, 4]
        learner.add_exits(np.array(feeds), np.array([0.1, 0.1]))
        learner.decide(hoppers)
    assert learner.histograms[CW].tolist() == [0.05, 0.05, 0.0, 0.0]
    assert learner.histograms[CCW].tolist() == [0.0, 0.0, 0.05, 0.05]
    assert learner.direction == CCW  # it feeds the empty heads
    learner.add_exits(np.array([3, 4]), np.array([0.1, 0.1]))
    assert learner.decide(np.array([0.0, 0.0, 0.5, 0.5])) == CW


def test_an_unknown_objective_is_refused(context: Context) -> None:
    with pytest.raises(ParameterError, match="'objective' must be one of channel_mass, hop"):
        ExampleController(context=context, parameter_overrides=[
            Parameter('objective', value='speed')])


def test_controller_drives_the_simulator(context: Context) -> None:
    # as fast as possible, the controller on the simulator's /clock: it decides every 2 s
    # of simulated time however fast this machine is; cmd_timeout 0 holds its last command.
    # Contact off: the loop is the point, and a crowd of 80 touching pieces costs minutes
    sim = SimNode(context=context, namespace='/loop', parameter_overrides=[
        Parameter('real_time_factor', value=0.0), Parameter('feed.rate', value=20.0),
        Parameter('record_path', value=''), Parameter('cmd_timeout', value=0.0),
        Parameter('publish_clock', value=True), Parameter('interactions.enabled', value=False)])
    ctl = ExampleController(context=context, namespace='/loop', parameter_overrides=[
        Parameter('speed', value=6.0), Parameter('period', value=2.0),
        Parameter('use_sim_time', value=True)])
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(sim)
    executor.add_node(ctl)
    try:
        end = time.monotonic() + 120.0  # a cap only: the loop waits on simulated progress
        while time.monotonic() < end and not (ctl.exits >= 10 and ctl.masses.size):
            executor.spin_once(timeout_sec=0.05)
        assert ctl.exits >= 10
        res = sim.last_tick
        assert res.mode == 'command' and abs(res.target_omega) == 6.0
        # the controller's view of the totals lags the simulator's at most
        assert 0.0 < ctl.masses.sum() <= res.channel_mass.sum() + 1e-12
    finally:
        executor.shutdown()
        ctl.destroy_node()
        sim.destroy_node()
