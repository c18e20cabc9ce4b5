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

"""camera_node in process: a plant's true pieces in, the camera's detections out, late."""

import time
from typing import Any

from cone_feeder_sim.errors import ParameterError
from cone_feeder_sim.formats.cdr import CdrCodec
from cone_feeder_sim.formats.messages import cloud_message, header
from cone_feeder_sim.formats.pointcloud import cloud_points, STATE_DTYPE
from cone_feeder_sim.ros.camera_node import CameraNode
from cone_feeder_sim.twin.camera import CameraSettings, observe
import numpy as np
import pytest
from rclpy.exceptions import InvalidParameterValueException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2

CODEC = CdrCodec()
#: The camera's publisher is best effort; a deep queue keeps every frame of a stalled test.
SEEN_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
TRUTH = np.array([[0.1, 0.02, 0.01], [-0.08, 0.09, 0.012], [0.03, -0.13, 0.011]])


class Plant:
    """A client node that publishes true pieces and takes the camera's detections."""

    def __init__(self, context: Any, camera: CameraNode) -> None:
        self.node = Node('plant', context=context)
        self.states = self.node.create_publisher(PointCloud2, 'particle_states', 10)
        self.received: list[tuple[float, dict[str, Any]]] = []  # arrival (monotonic s)
        self.node.create_subscription(
            PointCloud2, 'detections', lambda data: self.received.append(
                (time.monotonic(), CODEC.decode('sensor_msgs/msg/PointCloud2', data))),
            SEEN_QOS, raw=True)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.executor.add_node(camera)

    def publish(self, t: float, truth: np.ndarray = TRUTH) -> float:
        """Publish the true pieces of t (s); return the wall time (monotonic s) it was sent."""
        points = np.zeros(len(truth), dtype=STATE_DTYPE)
        points['x'], points['y'], points['z'] = truth.T
        points['id'] = np.arange(len(truth)) + 7
        self.states.publish(CODEC.encode('sensor_msgs/msg/PointCloud2',
                                         cloud_message(header(t, 'feeder'), points)))
        return time.monotonic()

    def spin_until(self, condition: Any, seconds: float = 30.0) -> bool:
        end = time.monotonic() + seconds
        while not condition():
            if time.monotonic() > end:
                return False
            self.executor.spin_once(timeout_sec=0.01)
        return True


def camera_node(context: Any, **values: Any) -> CameraNode:
    return CameraNode(context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in values.items()])


def test_each_frame_is_the_camera_s_view_of_it_passed_on_late(context: Any) -> None:
    settings = {'sigma': 0.002, 'miss': 0.2, 'false_rate': 0.5, 'swap': 0.3, 'delay': 0.05,
                'jitter': 0.0, 'seed': 4}
    camera = camera_node(context, **settings)
    plant = Plant(context, camera)
    # what the camera must give: observe() with the node's seed, frame by frame (the
    # jitter's draw follows each frame's, and is zero here)
    rng = np.random.default_rng(4)
    expected = []
    for _ in range(10):
        expected.append(observe(CameraSettings(**settings), rng,
                                TRUTH.astype(np.float32).astype(float), np.arange(3) + 7))
        rng.random()
    try:
        for k in range(10):
            sent = plant.publish(0.1 * (k + 1))
            assert plant.spin_until(lambda k=k: len(plant.received) > k), k
            arrived, msg = plant.received[k]
            assert arrived - sent >= 0.05  # held back by the delay
            assert msg['header'] == header(0.1 * (k + 1), 'feeder')  # the time it was taken
            found = cloud_points(msg)
            seen, track = expected[k]
            assert np.array_equal(found['track_id'], track)
            assert np.array_equal(found['x'], seen[:, 0].astype(np.float32))
            assert np.array_equal(found['z'], seen[:, 2].astype(np.float32))
    finally:
        plant.executor.shutdown()
        camera.destroy_node()
        plant.node.destroy_node()


def test_frames_fall_due_out_of_order_with_jitter(context: Any) -> None:
    camera = camera_node(context, delay=0.0, jitter=1.0, miss=0.0, false_rate=0.0, seed=1)
    plant = Plant(context, camera)
    try:
        for k in range(20):  # taken one by one (the subscription keeps the last 10)
            plant.publish(0.01 * (k + 1))
            assert plant.spin_until(lambda k=k: camera.taken > k)
        assert plant.spin_until(lambda: len(plant.received) == 20)
        stamps = [msg['header']['stamp']['nanosec'] for _, msg in plant.received]
        assert sorted(stamps) == [round(0.01 * (k + 1) * 1e9) for k in range(20)]
        assert stamps != sorted(stamps)  # 20 frames taken at once, each up to 1 s late
    finally:
        plant.executor.shutdown()
        camera.destroy_node()
        plant.node.destroy_node()


def test_a_frame_without_coordinates_is_refused_and_the_camera_goes_on(context: Any) -> None:
    camera = camera_node(context, delay=0.0, jitter=0.0)
    plant = Plant(context, camera)
    try:
        points = np.zeros(2, dtype=np.dtype([('a', '<f4'), ('b', '<f4')]))
        plant.states.publish(CODEC.encode('sensor_msgs/msg/PointCloud2',
                                          cloud_message(header(0.1, 'feeder'), points)))
        plant.publish(0.2)
        assert plant.spin_until(lambda: len(plant.received) == 1)
        assert plant.received[0][1]['header'] == header(0.2, 'feeder')
        assert camera.frames == 1
    finally:
        plant.executor.shutdown()
        camera.destroy_node()
        plant.node.destroy_node()


def test_a_setting_out_of_its_range_refuses_the_start(context: Any) -> None:
    with pytest.raises(InvalidParameterValueException, match='miss'):  # the ROS range
        camera_node(context, miss=2.0)
    with pytest.raises(ParameterError, match="'radius'"):  # an open bound: the settings'
        camera_node(context, radius=0.0)
