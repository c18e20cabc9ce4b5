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

"""The node's input handling without a node: serialized bytes in, engine input out."""

from typing import Any

from cone_feeder_sim.feeder.engine import (
    DriveParams, EngineConfig, FeederEngine, FeedParams, RotationCommand, SpawnRequest)
from cone_feeder_sim.formats.cdr import default_codec, encode
from cone_feeder_sim.ros.inputs import Inputs, RefusalThrottle
import pytest


def pose_array(frame: str, *points: tuple[float, float, float]) -> bytes:
    poses = [{'position': {'x': x, 'y': y, 'z': z},
              'orientation': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}} for x, y, z in points]
    return encode('geometry_msgs/msg/PoseArray',
                  {'header': {'stamp': {'sec': 0, 'nanosec': 0}, 'frame_id': frame},
                   'poses': poses})


@pytest.fixture
def handled() -> tuple[Inputs, FeederEngine]:
    engine = FeederEngine(EngineConfig(
        drive=DriveParams(max_angular_velocity=10.0), feed=FeedParams(rate=0.0, max_pieces=2)))
    return Inputs(engine, default_codec(), 'feeder'), engine


def test_a_command_is_queued_and_a_clamped_one_warned_of(handled: Any) -> None:
    inputs, engine = handled
    assert inputs.handle('rotation_cmd', encode('std_msgs/msg/Float64', {'data': 3.0})) \
        .refusals == ()
    outcome = inputs.handle('rotation_cmd', encode('std_msgs/msg/Float64', {'data': 12.5}))
    assert outcome.refusals == () and outcome.warning == (
        'rotation_cmd 12.5 rad/s clamped to the limit 10 rad/s')
    assert engine.pending == (RotationCommand(3.0), RotationCommand(12.5))
    outcome = inputs.handle('rotation_cmd', b'\x00\x01')
    (refusal, text), = outcome.lines()
    assert refusal.kind == 'rotation_cmd' and text.startswith('rotation_cmd refused: ')


def test_spawn_poses_are_screened_by_frame_then_by_the_engine(handled: Any) -> None:
    inputs, engine = handled
    outcome = inputs.handle('spawn', pose_array('map', (0.05, 0.0, 0.06)))
    (refusal, _), = outcome.lines()
    assert refusal.count == 1 and "frame 'map'" in refusal.reason and engine.pending == ()
    outcome = inputs.handle('spawn', pose_array('', (0.05, 0.0, 0.06), (0.3, 0.0, 0.06),
                                                (0.0, 0.05, 0.06), (-0.05, 0.0, 0.06)))
    (invalid, text), (excess, _) = outcome.lines()
    assert invalid.count == 1 and 'pose [1]' in invalid.reason
    assert text.startswith('spawn: refused 1 of 4 poses: pose [1]')
    assert excess.count == 1 and 'feed.max_pieces' in excess.reason
    request, = engine.pending
    assert isinstance(request, SpawnRequest) and request.positions.shape == (2, 3)
    assert not request.velocities.any()  # dropped: at rest in the world frame


def test_a_channel_feed_without_a_weigher_is_refused(handled: Any) -> None:
    inputs, _ = handled
    outcome = inputs.handle('channel_feed', encode(
        'std_msgs/msg/Float64MultiArray',
        {'layout': {'dim': [], 'data_offset': 0}, 'data': [1.0] * 14}))
    (refusal, _), = outcome.lines()
    assert refusal.kind == 'channel_feed' and 'no weigher' in refusal.reason


def test_the_throttle_logs_each_kind_once_a_second() -> None:
    now = [0.0]
    throttle = RefusalThrottle(clock=lambda: now[0])
    assert throttle.due('spawn', 'cannot decode the message: too short')
    assert not throttle.due('spawn', 'cannot decode the message: bad length')  # same kind
    assert throttle.due('spawn', 'pose [0] is not finite')
    assert throttle.due('rotation_cmd', 'cannot decode the message: too short')
    now[0] = 0.9
    assert not throttle.due('spawn', 'cannot decode the message: too short')
    now[0] = 1.0
    assert throttle.due('spawn', 'cannot decode the message: too short')
