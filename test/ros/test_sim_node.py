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

"""In-process tests of sim_node: an isolated rclpy Context and executor per test."""

from collections.abc import Callable, Iterator
from dataclasses import fields
import math
from pathlib import Path
import threading
import time
from typing import Any

from cone_feeder_sim.errors import ParameterError, ScenarioError, Stopped
from cone_feeder_sim.formats.cdr import decode
from cone_feeder_sim.formats.pointcloud import EXIT_DTYPE, PACK_DTYPE, STATE_DTYPE
from cone_feeder_sim.formats.topics import MessageRecord
from cone_feeder_sim.physics.params import SolverParams
from cone_feeder_sim.ros.parameters import parameter_specs
from cone_feeder_sim.ros.sim_node import SimNode
from crowds import crowd_in_layers
from geometry_msgs.msg import PoseArray
import numpy as np
import pytest
from rclpy.exceptions import InvalidParameterValueException
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
import sim_process
from std_msgs.msg import Float64
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray
import yaml

CONFIG = Path(__file__).resolve().parents[2] / 'config' / 'sim_node.yaml'


class Ros(sim_process.InProcess):
    """A private context, executor and helper node for one test."""

    def __init__(self) -> None:
        super().__init__('test_client', timeout=20.0, spin_step=0.02)

    def sim(self, namespace: str = '', clock: Callable[[], float] = time.perf_counter,
            **params: Any) -> SimNode:
        params.setdefault('record_path', '')  # no runs/ directory in the working directory
        # an empty list cannot be typed in rclpy; NOT_SET is what `[]` in a YAML file gives
        overrides = [Parameter(k) if v == [] else Parameter(k, value=v)
                     for k, v in params.items()]
        return self.add(SimNode(context=self.context, parameter_overrides=overrides,
                                namespace=namespace, clock=clock))

    def call(self, srv_type: Any, name: str, request: Any) -> Any:
        return super().call(srv_type, name, request, timeout=20.0, ready_timeout=10.0)


@pytest.fixture
def ros() -> Iterator[Ros]:
    with Ros() as harness:
        yield harness


def pause(ros: Ros, sim: SimNode) -> None:
    response = ros.call(SetBool, f'{sim.get_fully_qualified_name()}/pause',
                        SetBool.Request(data=True))
    assert response.success and sim.paused


def step(ros: Ros, sim: SimNode) -> Trigger.Response:
    return ros.call(Trigger, f'{sim.get_fully_qualified_name()}/step', Trigger.Request())


def flatten(tree: dict, prefix: str = '') -> dict[str, Any]:
    flat = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            flat.update(flatten(value, f'{prefix}{key}.'))
        else:
            flat[f'{prefix}{key}'] = value
    return flat


def test_defaults_are_the_default_config_file(ros: Ros) -> None:
    sim = ros.sim()
    content = yaml.safe_load(CONFIG.read_text())
    params = flatten(content['/**/sim_node']['ros__parameters'])
    assert len(params) > 20
    # the harness turns recording off; the file has the built-in default
    defaults = {spec.name: spec.default for spec in parameter_specs()}
    assert params.pop('record_path') == defaults['record_path']
    for name, value in params.items():
        actual = sim.get_parameter(name).value
        if isinstance(value, list):
            assert list(actual) == value, name
        else:
            assert actual == value, name
    # every setting of the integrator is a parameter, with its default in the file
    solver = {n for n in params if n.startswith('solver.')}
    assert solver == {f'solver.{f.name}' for f in fields(SolverParams)}
    assert sim.engine.piece_count == 5
    np.testing.assert_allclose(sim.engine.state.products[:, 1], [225, 135, 750, 750, 30])


def test_parameters_have_descriptions_ranges_and_read_only_flags(ros: Ros) -> None:
    sim = ros.sim()
    specs = {s.name: s for s in parameter_specs()}
    names = set(specs)
    assert {'model.d', 'model.cone_diameter', 'model.channel_count', 'solver.rtol',
            'feed.rate', 'real_time_factor', 'open_loop_pattern'} <= names
    for name in names:
        descriptor = sim.describe_parameter(name)
        assert descriptor.description, name
        assert descriptor.read_only == (not specs[name].dynamic), name
    assert sim.describe_parameter('model.d').read_only
    assert not sim.describe_parameter('feed.rate').read_only
    rng = sim.describe_parameter('max_angular_acceleration').floating_point_range[0]
    assert (rng.from_value, rng.to_value) == (0.0, 1.0e4)
    assert sim.describe_parameter('model.channel_count').integer_range[0].to_value == 360


@pytest.mark.parametrize('name, value, fragment', [
    ('max_angular_acceleration', 0.0, 'max_angular_acceleration'),
    ('feed.rho_max', 0.3, 'inside the cone'),
    ('feed.rho_min', 0.2, 'must not exceed'),
    ('open_loop_pattern', [1.0, 2.0, 3.0], 'pairs'),
    ('open_loop_pattern', [0.0, 2.0], 'duration'),
    ('real_time_factor', 500.0, 'range'),
    ('model.d', 100.0, 'read-only'),
    ('update_rate', 100.0, 'read-only'),
    ('feed.rate', 'fast', 'type'),
])
def test_invalid_runtime_parameters_are_refused_with_a_reason(
        ros: Ros, name: str, value: Any, fragment: str) -> None:
    sim = ros.sim()
    before = sim.get_parameter(name).value
    result = sim.set_parameters([Parameter(name, value=value)])[0]
    assert not result.successful
    assert fragment in result.reason
    assert sim.get_parameter(name).value == before
    assert sim.engine.pending == ()


def test_runtime_parameters_take_effect(ros: Ros) -> None:
    sim = ros.sim(real_time_factor=1.0)
    assert sim.tick_timer_period_ns == 20_000_000
    results = sim.set_parameters([
        Parameter('real_time_factor', value=2.0), Parameter('feed.rate', value=7.0),
        Parameter('max_angular_velocity', value=3.0),
        Parameter('open_loop_pattern', value=[1.0, 2.0])])
    assert all(r.successful for r in results)
    assert sim.tick_timer_period_ns == 10_000_000
    pause(ros, sim)
    step(ros, sim)
    assert sim.engine.feed.rate == 7.0
    assert sim.engine.drive.max_angular_velocity == 3.0
    assert sim.engine.drive.pattern == ((1.0, 2.0),)
    assert sim.last_tick.target_omega == 2.0
    # 0: as fast as possible
    assert sim.set_parameters([Parameter('real_time_factor', value=0.0)])[0].successful
    assert sim.ticker.pacer.period == 0.0  # the worker chains its hand-overs
    sim.set_paused(False)
    index = sim.engine.tick_index
    assert ros.spin_until(lambda: sim.engine.tick_index >= index + 20)


@pytest.mark.parametrize('params, error, fragment', [
    ({'feed.rho_max': 0.3}, ParameterError, 'inside the cone'),
    ({'initial_pieces.positions': [0.3, 0.0, 0.0], 'initial_pieces.d': []}, ScenarioError,
     'outside the cone'),
    ({'initial_pieces.positions': [0.1, 0.0]}, ParameterError, 'triples'),
    ({'initial_pieces.d': [1.0]}, ParameterError, 'one per piece'),
    ({'model.m': 0.0}, ParameterError, "'m'"),
    ({'model.normal_force': 'magic'}, ParameterError, 'normal_force'),
    ({'update_rate': 0.0}, InvalidParameterValueException, 'update_rate'),
])
def test_invalid_start_configuration_is_refused(ros: Ros, params: dict, error: type,
                                                fragment: str) -> None:
    with pytest.raises(error, match=fragment):
        ros.sim(**params)


def test_model_parameters_override_the_parameter_file(ros: Ros, tmp_path: Path) -> None:
    table = tmp_path / 'model.yaml'
    table.write_text('cone_diameter: 0.5\nm: 0.2\nchannel_count: 10\n')
    sim = ros.sim(**{'parameter_file': str(table), 'model.m': 0.3,
                     'initial_pieces.positions': [0.1, 0.0, 0.05], 'initial_pieces.d': [],
                     'feed.rate': 0.0})
    assert sim.get_parameter('model.cone_diameter').value == 0.5
    assert sim.engine.model.r == 0.25
    assert sim.engine.model.product.m == 0.3
    assert sim.engine.model.channels.count == 10
    assert sim.engine.state.products[0, 0] == 0.3


def collect(sim: SimNode) -> list[MessageRecord]:
    records: list[MessageRecord] = []
    sim.add_message_hook(records.append)
    return records


def latest(records: list[MessageRecord], topic: str) -> dict[str, Any]:
    for record in reversed(records):
        if record.topic == topic:
            return decode(record.type_name, record.data)
    raise AssertionError(f'nothing published on {topic}')


def test_the_weigher_publishes_hoppers_packs_and_statistics(ros: Ros) -> None:
    sim = ros.sim(real_time_factor=0.0, **{'feed.rate': 20.0, 'weigher.target': 0.2,
                                           'weigher.transport_time': 0.5})
    records = collect(sim)

    def weigher_status() -> bool:
        return any(status['name'] == '/sim_node: weigher'
                   for r in records if r.topic == '/diagnostics'
                   for status in decode(r.type_name, r.data)['status'])

    assert ros.spin_until(lambda: sum(r.topic == '/pack_events' for r in records) >= 3
                          and weigher_status(), 120.0)
    pause(ros, sim)
    packs = []
    for record in records:
        if record.topic == '/pack_events':
            msg = decode(record.type_name, record.data)
            assert [f['name'] for f in msg['fields']] == list(PACK_DTYPE.names)
            packs += list(np.frombuffer(msg['data'], dtype=PACK_DTYPE))
    assert [int(p['pack']) for p in packs] == list(range(1, len(packs) + 1))
    for p in packs:
        assert p['mass'] >= 0.2 - 0.005 and p['giveaway'] == pytest.approx(p['mass'] - 0.2)
        assert 0 < int(p['heads']) < 1 << 14
    hoppers = latest(records, '/hopper_weights')
    assert hoppers['layout']['dim'] == [{'label': 'head', 'size': 14, 'stride': 14}]
    weigher = sim.engine.weigher
    np.testing.assert_array_equal(hoppers['data'], weigher.hopper_readings())
    balance = weigher.balance()
    assert sum(p['mass'] for p in packs) == pytest.approx(balance['packed'], rel=1e-12)
    assert balance['in'] == pytest.approx(float(sim.last_tick.channel_mass.sum()), rel=1e-12)


def test_channel_feed_sets_the_troughs(ros: Ros) -> None:
    from std_msgs.msg import Float64MultiArray
    sim = ros.sim(start_paused=True)
    pub = ros.client.create_publisher(Float64MultiArray, 'channel_feed', 10)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0, 20.0)
    pub.publish(Float64MultiArray(data=[0.5] * 7 + [0.0] * 7))
    assert ros.spin_until(lambda: len(sim.engine.pending) == 1, 20.0)
    sim.step()
    assert sim.engine.weigher.amplitude.tolist() == [0.5] * 7 + [0.0] * 7
    refused = sim.totals.refused
    pub.publish(Float64MultiArray(data=[1.0] * 3))  # not one per channel
    assert ros.spin_until(lambda: sim.totals.refused > refused, 20.0)


def test_published_messages_carry_the_engine_state(ros: Ros) -> None:
    sim = ros.sim(namespace='/feeder1', real_time_factor=0.0, publish_clock=True)
    records = collect(sim)
    assert ros.spin_until(lambda: sim.engine.tick_index >= 120 and sum(
        r.topic == '/feeder1/exit_events' for r in records) >= 2, 60.0)
    pause(ros, sim)
    res = sim.last_tick
    sec, nanosec = divmod(round(res.t * 1e9), 1_000_000_000)
    stamp = {'sec': sec, 'nanosec': nanosec}
    particles = latest(records, '/feeder1/particles')
    assert particles['header'] == {'stamp': stamp, 'frame_id': 'feeder'}
    poses = np.array([[p['position'][k] for k in 'xyz'] for p in particles['poses']])
    np.testing.assert_array_equal(poses, res.positions)
    assert all(p['orientation']['w'] == 1.0 for p in particles['poses'])
    states = latest(records, '/feeder1/particle_states')
    assert [f['name'] for f in states['fields']] == list(STATE_DTYPE.names)
    cloud = np.frombuffer(states['data'], dtype=STATE_DTYPE)
    assert states['width'] == res.count == len(cloud)
    np.testing.assert_array_equal(cloud['id'], res.ids)
    np.testing.assert_allclose(cloud['vx'], res.velocities[:, 0], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(cloud['mass'], res.masses, rtol=1e-6)
    cone = latest(records, '/feeder1/cone_state')
    assert cone['name'] == ['cone']
    assert cone['position'][0] == res.angle and cone['velocity'][0] == res.omega
    clock = latest(records, '/clock')
    assert clock['clock'] == stamp
    first_clock = next(decode(r.type_name, r.data) for r in records if r.topic == '/clock')
    assert first_clock['clock'] == {'sec': 0, 'nanosec': 20_000_000}
    # exit events agree with the channel masses
    total = np.zeros(14)
    exits = 0
    for record in records:
        if record.topic == '/feeder1/exit_events':
            msg = decode(record.type_name, record.data)
            rows = np.frombuffer(msg['data'], dtype=EXIT_DTYPE)
            assert msg['width'] == len(rows) > 0
            np.add.at(total, rows['channel'].astype(int) - 1, rows['mass'])
            exits += len(rows)
            np.testing.assert_allclose(np.hypot(rows['x'], rows['y']), 0.225, atol=1e-6)
            np.testing.assert_allclose(rows['angle'], np.arctan2(rows['y'], rows['x']))
    channel = latest(records, '/feeder1/channel_mass')
    assert channel['layout']['dim'] == [{'label': 'channel', 'size': 14, 'stride': 14}]
    np.testing.assert_allclose(channel['data'], total, rtol=0, atol=1e-12)
    assert exits == sim.totals.exits


def test_pause_step_and_reset_services(ros: Ros) -> None:
    sim = ros.sim(real_time_factor=0.0)
    name = sim.get_fully_qualified_name()
    refused = step(ros, sim)
    assert not refused.success and 'not paused' in refused.message
    pause(ros, sim)
    index = sim.engine.tick_index
    # while paused, nothing ticks
    ros.spin_until(lambda: False, 0.2)
    assert sim.engine.tick_index == index
    for k in range(3):
        response = step(ros, sim)
        assert response.success
        assert sim.engine.tick_index == index + k + 1
    reset = ros.call(Trigger, f'{name}/reset', Trigger.Request())
    assert reset.success and 'next tick' in reset.message
    assert sim.engine.pending
    step(ros, sim)
    assert sim.last_tick.reset and sim.last_tick.count == 5
    assert sim.last_tick.channel_mass.sum() == 0.0
    resume = ros.call(SetBool, f'{name}/pause', SetBool.Request(data=False))
    assert resume.success and not sim.paused
    assert ros.spin_until(lambda: sim.engine.tick_index > index + 10)


def publish_until(ros: Ros, topic: str, msg: Any, condition: Callable[[], bool]) -> bool:
    pub = ros.client.create_publisher(type(msg), topic, 10)
    end = time.monotonic() + 20.0
    while time.monotonic() < end:
        pub.publish(msg)
        if ros.spin_until(condition, 0.3):
            return True
    return False


#: The spawn messages of these tests.
poses = sim_process.pose_array


def test_spawn_accepts_valid_poses_and_refuses_others(ros: Ros) -> None:
    sim = ros.sim(**{'feed.rate': 0.0, 'initial_pieces.positions': [0.1, 0.0, 0.05],
                     'initial_pieces.d': []})
    records = collect(sim)
    pause(ros, sim)
    bad_frame = poses((0.05, 0.0, 0.05), frame='map')
    assert publish_until(ros, 'spawn', bad_frame, lambda: sim.totals.refused >= 1)
    mixed = poses((0.05, 0.0, 0.05), (0.5, 0.0, 0.05), (0.0, 0.05, -0.01),
                  (float('nan'), 0.0, 0.1), (-0.05, 0.02, 0.06), frame='')
    assert publish_until(ros, 'spawn', mixed, lambda: len(sim.engine.pending) >= 1)
    assert sim.totals.refused >= 4
    step(ros, sim)
    res = sim.last_tick
    np.testing.assert_allclose(res.positions[0, 0], 0.1, atol=1e-3)
    spawned = res.ids[1:]
    assert len(spawned) % 2 == 0 and len(spawned) >= 2  # one valid pair per delivery
    # dropped at rest: they have fallen for at most one tick (g dt^2 / 2 = 2 mm)
    np.testing.assert_allclose(res.positions[1], [0.05, 0.0, 0.05], atol=2.5e-3)
    np.testing.assert_allclose(res.positions[2], [-0.05, 0.02, 0.06], atol=2.5e-3)
    received = [r for r in records if r.direction == 'in']
    assert received and received[0].topic == '/spawn'
    assert decode(received[0].type_name, received[0].data)['header']['frame_id'] == 'map'


def test_rotation_commands_are_followed_and_non_finite_refused(ros: Ros) -> None:
    sim = ros.sim(real_time_factor=0.0, max_angular_acceleration=50.0)
    records = collect(sim)
    assert publish_until(ros, 'rotation_cmd', Float64(data=math.nan),
                         lambda: sim.totals.refused >= 1)
    assert publish_until(ros, 'rotation_cmd', Float64(data=math.inf),
                         lambda: sim.totals.refused >= 2)
    assert publish_until(ros, 'rotation_cmd', Float64(data=4.0),
                         lambda: sim.last_tick is not None and sim.last_tick.mode == 'command'
                         and sim.last_tick.omega == pytest.approx(4.0))
    omegas = [decode(r.type_name, r.data)['velocity'][0] for r in records
              if r.topic == '/cone_state']
    assert max(np.abs(np.diff(omegas))) <= 50.0 * 0.02 + 1e-9
    commands = [decode(r.type_name, r.data)['data'] for r in records if r.direction == 'in']
    assert math.isnan(commands[0]) and 4.0 in commands


def test_late_joiners_get_the_static_scene_and_channel_mass(ros: Ros) -> None:
    sim = ros.sim(real_time_factor=0.0)
    counts: dict[tuple[int, int], int] = {}  # pieces per stamp, from particles
    ros.client.create_subscription(PoseArray, 'particles', lambda m: counts.update(
        {(m.header.stamp.sec, m.header.stamp.nanosec): len(m.poses)}), 100)
    assert ros.spin_until(lambda: sim.engine.tick_index >= 30)
    pause(ros, sim)
    got: list[MarkerArray] = []
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    ros.client.create_subscription(MarkerArray, 'markers', got.append, latched)
    assert ros.spin_until(lambda: bool(got))
    namespaces = {m.ns for m in got[-1].markers}
    assert {'cone', 'channels', 'channel_labels', 'pieces', 'cone_angle'} <= namespaces
    labels = sorted(int(m.text) for m in got[-1].markers if m.ns == 'channel_labels')
    assert labels == list(range(1, 15))
    pieces = next(m for m in got[-1].markers if m.ns == 'pieces')
    # markers are rate-limited: the latched message is of some tick, with that tick's pieces
    assert ros.spin_until(lambda: (pieces.header.stamp.sec,
                                   pieces.header.stamp.nanosec) in counts)
    assert len(pieces.points) == counts[pieces.header.stamp.sec, pieces.header.stamp.nanosec]


def test_start_paused_waits_for_resume(ros: Ros) -> None:
    sim = ros.sim(start_paused=True, real_time_factor=0.0)
    assert sim.paused
    ros.spin_until(lambda: False, 0.2)
    assert sim.engine.tick_index == 0
    response = ros.call(SetBool, f'{sim.get_fully_qualified_name()}/pause',
                        SetBool.Request(data=False))
    assert response.success and 'resumed' in response.message
    assert ros.spin_until(lambda: sim.engine.tick_index >= 3)


def test_clock_is_never_zero(ros: Ros) -> None:
    sim = ros.sim(publish_clock=True, real_time_factor=0.0)
    ticks: list[Clock] = []
    ros.client.create_subscription(Clock, '/clock', ticks.append, 10)
    assert ros.spin_until(lambda: len(ticks) >= 5)
    assert all(c.clock.sec > 0 or c.clock.nanosec > 0 for c in ticks)
    assert sim.get_parameter('publish_clock').value


def test_diagnostics_warn_when_the_cpu_cannot_keep_up(ros: Ros) -> None:
    sim = ros.sim(**{'update_rate': 1000.0, 'real_time_factor': 100.0,
                     'diagnostics.period': 0.2, 'catch_up': 0.0})
    records = collect(sim)

    def warned() -> bool:
        for r in records:
            if r.topic == '/diagnostics':
                status = decode(r.type_name, r.data)['status'][0]
                if status['level'] == 1:  # WARN
                    return True
        return False

    assert ros.spin_until(warned, 30.0)
    status = next(decode(r.type_name, r.data)['status'][0] for r in records
                  if r.topic == '/diagnostics'
                  and decode(r.type_name, r.data)['status'][0]['level'] == 1)
    assert 'cannot keep up' in status['message']
    keys = {kv['key'] for kv in status['values']}
    assert {'real-time factor (achieved)', 'step time mean (ms)', 'pieces',
            'accepted steps', 'time given up (s)'} <= keys
    # the lag beyond catch_up is given up, not caught up
    assert any(float(kv['value']) > 0 for kv in status['values']
               if kv['key'] == 'time given up (s)')


class MadeUpClock:
    """A steady clock (s) that moves only when a test moves it."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def test_a_short_stall_is_caught_up(ros: Ros) -> None:
    clock = MadeUpClock()
    sim = ros.sim(clock=clock, **{'feed.rate': 0.0, 'markers.rate': 0.0,
                                  'diagnostics.period': 3600.0, 'catch_up': 5.0})
    assert ros.spin_until(lambda: sim.engine.tick_index >= 1)
    clock.now += 4 * 0.02
    assert ros.spin_until(lambda: sim.engine.tick_index >= 5)
    ros.spin_for(0.05)
    assert sim.engine.tick_index == 5  # the made-up clock stands: no tick is due
    sim0 = sim.engine.t
    clock.now += 0.5  # the stall under test: 25 periods pass without a tick
    # the node makes the 0.5 s up: simulated time gets back to the clock, and no further
    assert ros.spin_until(lambda: sim.engine.t >= sim0 + 0.5 - 1e-9, 60.0)
    ros.spin_for(0.05)
    assert sim.engine.t == pytest.approx(sim0 + 0.5, abs=1e-9)
    assert sim.ticker.window.given_up == 0.0


def test_a_long_stall_is_given_up_not_bunched(ros: Ros) -> None:
    clock = MadeUpClock()
    sim = ros.sim(clock=clock, **{'feed.rate': 0.0, 'markers.rate': 0.0,
                                  'diagnostics.period': 3600.0, 'catch_up': 0.1})
    assert ros.spin_until(lambda: sim.engine.tick_index >= 1)
    index = sim.engine.tick_index
    clock.now += 0.5  # 0.4 s beyond catch_up
    # catch_up worth of ticks (5), the rest given up
    assert ros.spin_until(lambda: sim.engine.tick_index >= index + 5, 60.0)
    ros.spin_for(0.05)
    assert sim.engine.tick_index == index + 5
    assert sim.ticker.window.given_up == pytest.approx(0.4, abs=0.02 + 1e-9)


def test_the_executor_runs_while_a_tick_does(ros: Ros) -> None:
    sim = ros.sim(**{'feed.rate': 0.0, 'markers.rate': 0.0, 'cmd_timeout': 0.0})
    assert ros.spin_until(lambda: sim.engine.tick_index >= 2)
    release = threading.Event()
    entered = threading.Event()
    tick = sim.engine.tick

    def slow_tick() -> Any:
        entered.set()
        assert release.wait(60.0)
        return tick()

    sim.engine.tick = slow_tick  # type: ignore[method-assign]
    assert ros.spin_until(entered.is_set)
    # while the worker is inside a tick, the executor serves commands and services
    pub = ros.client.create_publisher(Float64, 'rotation_cmd', 10)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0)
    pub.publish(Float64(data=3.0))
    assert ros.spin_until(lambda: len(sim.engine.pending) == 1)
    assert not release.is_set()
    release.set()
    sim.engine.tick = tick  # type: ignore[method-assign]
    assert ros.spin_until(lambda: sim.last_tick is not None and sim.last_tick.mode == 'command')
    assert sim.last_tick.target_omega == 3.0


def test_the_executor_answers_while_a_real_contact_tick_runs(ros: Ros) -> None:
    # a crowd in three layers, every pair coupled, whose first tick would compute for
    # minutes (no step longer than 2e-8 s); while the worker is inside it, the executor
    # answers services and publishes diagnostics; then the tick is stopped. A kernel that
    # held the GIL would keep the executor from answering until the tick had ended by
    # itself (its pieces out of steps), and the tick would not have been stopped.
    from diagnostic_msgs.msg import DiagnosticArray
    positions = crowd_in_layers().reshape(-1).tolist()
    sim = ros.sim(**{'feed.rate': 0.0, 'markers.rate': 0.0, 'open_loop_pattern': [],
                     'start_paused': True, 'initial_pieces.positions': positions,
                     'initial_pieces.d': [], 'diagnostics.period': 0.05,
                     'solver.h_max': 2.0e-8})
    assert sim.engine.piece_count == len(positions) // 3 > 100
    tick = sim.engine.tick
    entered = threading.Event()
    outcome: list[str] = []

    def watched_tick() -> Any:
        entered.set()
        try:
            result = tick()
        except Stopped:
            outcome.append('stopped')
            raise
        outcome.append('ended by itself')
        return result

    sim.engine.tick = watched_tick  # type: ignore[method-assign]
    heard: list[float] = []
    ros.client.create_subscription(DiagnosticArray, '/diagnostics',
                                   lambda _: heard.append(time.monotonic()), 10)
    name = sim.get_fully_qualified_name()
    assert ros.call(SetBool, f'{name}/pause', SetBool.Request(data=False)).success
    assert ros.spin_until(entered.is_set)
    cpu = time.process_time()
    answered = 0
    while answered < 10 or time.process_time() < cpu + 0.2:  # the worker computes meanwhile
        assert not ros.call(Trigger, f'{name}/step', Trigger.Request()).success  # not paused
        answered += 1
    heard_before = len(heard)
    sim.engine.request_stop()
    assert ros.spin_until(lambda: bool(outcome), 60.0)
    assert outcome == ['stopped'] and answered >= 10 and heard_before >= 1


def test_topics_are_relative_and_described_for_recording(ros: Ros) -> None:
    sim = ros.sim(namespace='/line2')
    topics = {t.topic: t for t in sim.topics()}
    assert {'/line2/particles', '/line2/particle_states', '/line2/exit_events',
            '/line2/channel_mass', '/line2/cone_state', '/line2/markers', '/diagnostics',
            '/line2/rotation_cmd', '/line2/spawn', '/line2/sim_node/events',
            '/line2/hopper_weights', '/line2/pack_events', '/line2/channel_feed'} == set(topics)
    assert topics['/line2/channel_feed'].direction == 'in'
    assert topics['/line2/hopper_weights'].qos.durability == 'transient_local'
    assert topics['/line2/pack_events'].qos.depth == 1000
    assert topics['/line2/exit_events'].qos.depth == 1000
    assert topics['/line2/exit_events'].qos.reliability == 'reliable'
    assert topics['/line2/markers'].qos.durability == 'transient_local'
    assert topics['/line2/particle_states'].type_name == 'sensor_msgs/msg/PointCloud2'
    assert topics['/line2/rotation_cmd'].direction == 'in'


@pytest.mark.parametrize('enabled', [True, False])
def test_pieces_dropped_on_each_other_touch_by_default(ros: Ros, enabled: bool) -> None:
    # a piece released 6 cm above another on the resting cone
    params = {'feed.rate': 0.0, 'open_loop_pattern': [], 'start_paused': True,
              'initial_pieces.positions': [0.1, 0.0, 0.035, 0.1, 0.0, 0.095],
              'initial_pieces.d': []}
    if not enabled:
        params['interactions.enabled'] = False
    sim = ros.sim(**params)
    assert sim.engine.model.interactions.enabled is enabled
    for _ in range(40):
        sim.step()
    q = sim.last_tick.positions
    gap = float(np.linalg.norm(q[1] - q[0]))
    if enabled:  # it rests on the other (the restriction balances its weight near 47 mm)
        assert 0.04 < gap < 0.05 and q[1, 2] > q[0, 2]
    else:  # the paper's model: it falls through, to within a landing's slide (10 mm)
        assert gap < 0.02
