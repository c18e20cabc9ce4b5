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

"""twin_node in process: a simulated plant's detections in, the twin's estimates out."""

import csv
from dataclasses import fields
from pathlib import Path
import time
from typing import Any

from cone_feeder_sim.formats.cdr import CdrCodec
from cone_feeder_sim.formats.mcap_reader import open_recording, parse_run_source
from cone_feeder_sim.formats.messages import cloud_message, cone_state_message, header
from cone_feeder_sim.formats.pointcloud import cloud_points, EXIT_DTYPE, NO_TRACK, STATE_DTYPE
from cone_feeder_sim.physics.params import INTERACTION_KEYS, ModelParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    add_particles, advance, resting_height, SimParams, SimState, world_from_cone)
from cone_feeder_sim.ros.twin_node import twin_parameter_specs, TwinNode
from cone_feeder_sim.twin.estimator import TUNING, TwinSettings
from cone_feeder_sim.twin.run import run_twin
from cone_feeder_sim.twin.spec import load_twin
from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState, PointCloud2
from std_msgs.msg import Float64MultiArray
import yaml

MODEL = ModelParams()
PARAMS = SimParams(model=MODEL)
PROFILE = RotationProfile.from_table([[0.0, 0.0], [0.5, 6.0]])
PLACES = [[0.10, 0.02], [-0.08, 0.09], [0.03, -0.13], [-0.12, -0.05]]
CODEC = CdrCodec()


class Plant:
    """The physics core as the feeder, and a client node that is its camera and encoder."""

    def __init__(self, context: Any, twin: TwinNode) -> None:
        q = np.array([[x, y, resting_height(MODEL, MODEL.product, x, y)] for x, y in PLACES])
        self.state, _ = add_particles(SimState(), PARAMS, q)
        self.rng = np.random.default_rng(0)
        self.node = Node('camera', context=context)
        self.detections = self.node.create_publisher(PointCloud2, 'detections', 10)
        self.cone = self.node.create_publisher(JointState, 'cone_state', 10)
        self.exits = self.node.create_publisher(PointCloud2, 'exit_events', 10)
        self.received: dict[str, list] = {'pieces': [], 'forecast': [], 'parameters': [],
                                          'diagnostics': []}
        for kind, topic, msg_type in (('pieces', 'twin/pieces', PointCloud2),
                                      ('forecast', 'twin/channel_forecast', Float64MultiArray),
                                      ('parameters', 'twin/parameters', Float64MultiArray),
                                      ('diagnostics', '/diagnostics', DiagnosticArray)):
            self.node.create_subscription(msg_type, topic, self.received[kind].append, 10)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.executor.add_node(twin)

    def spin_until(self, condition: Any, seconds: float = 30.0) -> bool:
        end = time.monotonic() + seconds
        while not condition():
            if time.monotonic() > end:
                return False
            self.executor.spin_once(timeout_sec=0.05)
        return True

    def truth(self) -> np.ndarray:
        seen, _, _ = world_from_cone(self.state.y, self.state.angle, PROFILE.omega(self.state.t))
        return seen

    def frame(self, t: float, **bad: Any) -> None:
        """Move the plant to t, publish the cone speed and (after it) the frame of t."""
        self.state = advance(self.state, PARAMS, PROFILE, t).state
        self.cone.publish(CODEC.encode('sensor_msgs/msg/JointState', cone_state_message(
            header(t, 'feeder'), self.state.angle, PROFILE.omega(t))))
        seen = self.truth()
        points = np.zeros(len(seen), dtype=STATE_DTYPE)
        points['x'] = seen[:, 0] + self.rng.normal(0.0, 0.001, len(seen))
        points['y'] = seen[:, 1] + self.rng.normal(0.0, 0.001, len(seen))
        points['z'] = seen[:, 2]
        points['id'] = self.state.ids
        points['mass'] = np.nan
        self.detections.publish(CODEC.encode('sensor_msgs/msg/PointCloud2',
                                             cloud_message(header(t, 'feeder'), points)))


def twin_node(context: Any, tmp_path: Path, **overrides: Any) -> TwinNode:
    values = {'members': 8, 'sigma': 0.001, 'd_spread': 0.05, 'mu_C_spread': 0.01,
              'diagnostics.period': 0.2, 'record_path': str(tmp_path / 'twin.mcap'),
              **overrides}
    return TwinNode(context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in values.items()])


def test_the_twin_follows_the_plant_and_forecasts(context: Any, tmp_path: Path) -> None:
    twin = twin_node(context, tmp_path)
    plant = Plant(context, twin)
    try:
        for k in range(1, 31):
            t = k / 30.0
            plant.frame(t)
            assert plant.spin_until(lambda k=k: len(plant.received['pieces']) >= k), k
        last = cloud_points(plant.received['pieces'][-1])
        truth = plant.truth()
        assert len(last) == len(truth)
        error = np.hypot(last['x'][:, None] - truth[None, :, 0],
                         last['y'][:, None] - truth[None, :, 1]).min(axis=1)
        assert error.max() < 0.005
        assert (last['sigma_x'] > 0).all() and (last['sigma_x'] < 0.005).all()
        assert (last['track_id'] == NO_TRACK).all()  # particle_states: id, not track_id
        assert plant.received['forecast'] and plant.received['parameters']
        forecast = plant.received['forecast'][-1]
        assert [d.size for d in forecast.layout.dim] == [3, MODEL.channels.count, 2]
        assert np.all(np.array(forecast.data) >= 0.0)
        assert plant.spin_until(lambda: any(
            m.status[0].message == 'following' for m in plant.received['diagnostics']))
        values = {v.key: v.value for v in plant.received['diagnostics'][-1].status[0].values}
        assert float(values['piece mass (kg)']) == MODEL.product.m  # no exit weighed
    finally:
        plant.executor.shutdown()
        twin.destroy_node()
        plant.node.destroy_node()
    recording = open_recording(parse_run_source(str(tmp_path / 'twin.mcap')))
    topics = recording.topics
    assert topics['/detections'].message_count == 30
    assert topics['/cone_state'].message_count == 30
    assert topics['/twin/pieces'].message_count == 30
    # the recording run again headless, with the node's settings: the node's estimates
    (tmp_path / 'scenario.yaml').write_text(yaml.safe_dump(
        {'duration': 1.0, 'rotation': [[0.0, 0.0]],
         'particles': [{'position': [0.1, 0.0, 0.0], 'on_surface': True}]}))
    (tmp_path / 'replay.yaml').write_text(yaml.safe_dump(
        {'scenario': 'scenario.yaml', 'detections': 'twin.mcap', 'cone': 'twin.mcap',
         'members': 8, 'sigma': 0.001, 'd_spread': 0.05, 'mu_C_spread': 0.01,
         'loosen': 100.0, 'every': 1.0 / 30.0}))  # the node's loosen: not the file's
    run_twin(load_twin(tmp_path / 'replay.yaml'), tmp_path / 'replay')
    node_twin = twin._follower.twin
    with (tmp_path / 'replay' / 'parameters.csv').open(newline='') as stream:
        rows = list(csv.DictReader(stream))[-2:]
    assert all(float(r['t']) == pytest.approx(node_twin.t, abs=1e-6) for r in rows)
    for row in rows:
        estimate, spread = node_twin.parameters()[row['key']]
        assert float(row['estimate']) == pytest.approx(estimate, rel=1e-5)
        assert float(row['spread']) == pytest.approx(spread, rel=1e-3)
    ids, mean, _ = node_twin.pieces()
    with (tmp_path / 'replay' / 'pieces.csv').open(newline='') as stream:
        last = [r for r in csv.DictReader(stream) if float(r['t']) == float(rows[0]['t'])]
    assert [int(r['piece']) for r in last] == ids.tolist()
    np.testing.assert_allclose([[float(r['x']), float(r['y'])] for r in last], mean,
                               atol=1e-6)


def test_the_estimator_settings_are_node_parameters() -> None:
    names = {spec.name for spec in twin_parameter_specs()}
    assert set(TUNING) | {'members', 'sigma', 'seed'} <= names
    assert set(TUNING) | {'members', 'sigma', 'seed', 'd', 'mu_C'} == {
        f.name for f in fields(TwinSettings)}


def test_the_pair_law_is_sim_node_s_and_off_unless_set(context: Any, tmp_path: Path) -> None:
    specs = {spec.name: spec for spec in twin_parameter_specs()}
    assert specs['interactions.enabled'].default is False
    assert {f'interactions.{key}' for key in INTERACTION_KEYS} <= set(specs)
    for overrides, enabled in (({}, False), ({'interactions.enabled': True,
                                              'interactions.friction': 0.3}, True)):
        twin = twin_node(context, tmp_path, record_path='', **overrides)
        try:
            law = twin._follower.params.model.interactions
            assert law.enabled is enabled
            assert law.friction == overrides.get('interactions.friction', 0.5)
        finally:
            twin.destroy_node()


def test_bad_inputs_are_refused_and_the_twin_goes_on(context: Any, tmp_path: Path) -> None:
    twin = twin_node(context, tmp_path, record_path='')
    plant = Plant(context, twin)
    logged: list[str] = []
    original = twin._refuse  # every refusal is logged through it: count them here

    def refuse(text: str) -> None:
        logged.append(text)
        original(text)

    twin._refuse = refuse  # type: ignore[method-assign]
    try:
        for k in range(1, 6):
            plant.frame(k / 30.0)
            assert plant.spin_until(lambda k=k: len(plant.received['pieces']) >= k)
        publish = plant.detections.publish

        def cloud(t: float, points: np.ndarray, frame_id: str = 'feeder') -> None:
            publish(CODEC.encode('sensor_msgs/msg/PointCloud2',
                                 cloud_message(header(t, frame_id), points)))

        good = np.zeros(2, dtype=STATE_DTYPE)
        good['x'], good['y'] = [0.1, -0.08], [0.02, 0.09]
        nan = good.copy()
        nan['x'][0] = np.nan
        cloud(0.2, nan)
        cloud(0.2, good, frame_id='camera')
        cloud(50.0, good)
        cloud(0.2, np.zeros(10_001, dtype=STATE_DTYPE))
        plant.cone.publish(CODEC.encode('sensor_msgs/msg/JointState', {
            'header': header(0.2, 'feeder'), 'name': ['belt'], 'position': np.zeros(1),
            'velocity': np.zeros(1), 'effort': np.zeros(0)}))
        plant.cone.publish(b'\x00\x01\x00\x00\x05')  # does not decode: refused, not fatal
        exits = np.zeros(2, dtype=EXIT_DTYPE)
        exits['exit_time'], exits['channel'] = [0.15, 0.16], [3, 15]
        plant.exits.publish(CODEC.encode('sensor_msgs/msg/PointCloud2',
                                         cloud_message(header(0.17, 'feeder'), exits)))
        assert plant.spin_until(lambda: len(logged) >= 7)
        assert any('a channel not in 1..14' in line for line in logged)
        # good ones (the twin waits to take them), and one older than its history: refused
        # alone
        exits = np.zeros(3, dtype=EXIT_DTYPE)
        exits['exit_time'], exits['channel'] = [0.15, 0.16, -0.1], [3, 4, 5]
        exits['mass'] = [0.05, 0.06, 0.07]
        plant.exits.publish(CODEC.encode('sensor_msgs/msg/PointCloud2',
                                         cloud_message(header(0.17, 'feeder'), exits)))
        assert plant.spin_until(lambda: len(twin._follower.twin.pending_exits) == 2)
        assert twin._follower.twin.pending_exits == [(0.15, 3, 0.05), (0.16, 4, 0.06)]
        assert plant.spin_until(lambda: any('older than the twin can go back' in line
                                            for line in logged))
        assert any('not finite' in line for line in logged)
        assert any("frame_id 'camera'" in line for line in logged)
        assert any('from the future' in line for line in logged)
        assert any('10001 detections' in line for line in logged)
        assert any("no joint 'cone'" in line for line in logged)
        assert any(line.startswith('cannot decode sensor_msgs/msg/JointState') for line in logged)
        count = len(plant.received['pieces'])
        plant.frame(6 / 30.0)
        assert plant.spin_until(lambda: len(plant.received['pieces']) > count)
    finally:
        plant.executor.shutdown()
        twin.destroy_node()
        plant.node.destroy_node()
