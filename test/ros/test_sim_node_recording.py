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
Recording and re-simulation of sim_node, in process (a private rclpy Context per test).

Files are read back with rosbags (an independent ROS 2 bag reader: it parses the ros2msg
schemas and decodes the CDR) and with the mcap package (metadata, summary).
"""

from collections.abc import Callable, Iterator
import dataclasses
import errno
import json
import os
from pathlib import Path
from typing import Any

from cone_feeder_sim.errors import RecordingError
from cone_feeder_sim.formats import mcap_writer, run_recorder
from cone_feeder_sim.formats.mcap_reader import open_recording
from cone_feeder_sim.formats.runlog import END_METADATA_NAME, INPUT_EVENTS, METADATA_NAME
from cone_feeder_sim.ros.parameters import parameter_specs
from cone_feeder_sim.ros.sim_node import SimNode
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseArray
import mcap.reader
from mcap.records import Chunk, Footer
from mcap.stream_reader import StreamReader
import numpy as np
import pytest
from rclpy.parameter import Parameter
from rosbags.highlevel import AnyReader
import sim_process
from std_msgs.msg import Float64
from std_srvs.srv import Trigger


class Ros(sim_process.InProcess):
    """A private context and executor with a client node."""

    def __init__(self) -> None:
        super().__init__('recording_test_client', timeout=30.0, spin_step=0.01)

    def sim(self, namespace: str = '', **params: Any) -> SimNode:
        overrides = [Parameter(k, value=v) for k, v in params.items()]
        return self.add(SimNode(context=self.context, parameter_overrides=overrides,
                                namespace=namespace))


@pytest.fixture
def ros() -> Iterator[Ros]:
    with Ros() as harness:
        yield harness


def plain(value: Any) -> Any:
    """Return a decoded rosbags message as nested dicts and lists (comparable with ==)."""
    if dataclasses.is_dataclass(value):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                if f.name != '__msgtype__'}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, list):
        return [plain(v) for v in value]
    return value


def read_bag(path: Path) -> dict[str, list[tuple[int, Any]]]:
    """Return every message of a file decoded by rosbags: topic -> [(log time, message)]."""
    out: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([path]) as reader:
        for connection in reader.connections:
            out.setdefault(connection.topic, [])
        for connection, log_time, raw in reader.messages():
            out[connection.topic].append((log_time, reader.deserialize(raw, connection.msgtype)))
    return out


def read_metadata(path: Path) -> dict[str, dict[str, str]]:
    with path.open('rb') as stream:
        reader = mcap.reader.make_reader(stream)
        return {m.name: dict(m.metadata) for m in reader.iter_metadata()}


def events(bag: dict[str, list[tuple[int, Any]]], topic: str) -> list[dict[str, Any]]:
    return [json.loads(message.data) for _, message in bag[topic]]


def pose_array(points: list[tuple[float, float, float]]) -> PoseArray:
    return sim_process.pose_array(*points)


def drive(ros: Ros, sim: SimNode, last_tick: int) -> None:
    """Send commands, a spawn, a reset and parameter changes while the node runs fast."""
    ns = sim.get_namespace().rstrip('/')
    cmd = ros.client.create_publisher(Float64, f'{ns}/rotation_cmd', 10)
    spawn = ros.client.create_publisher(PoseArray, f'{ns}/spawn', 10)
    reset = ros.client.create_client(Trigger, f'{sim.get_fully_qualified_name()}/reset')
    assert ros.spin_until(lambda: cmd.get_subscription_count() > 0
                          and spawn.get_subscription_count() > 0 and reset.service_is_ready())
    engine = sim.engine
    steps: list[tuple[int, Callable[[], Any]]] = [
        (10, lambda: cmd.publish(Float64(data=8.0))),
        (30, lambda: spawn.publish(pose_array([(0.05, 0.02, 0.05), (-0.08, 0.03, 0.04)]))),
        (45, lambda: sim.set_parameters([Parameter('feed.rate', value=40.0),
                                         Parameter('markers.rate', value=25.0)])),
        (60, lambda: reset.call_async(Trigger.Request())),
        (75, lambda: cmd.publish(Float64(data=-9.0))),
        (90, lambda: sim.set_parameters([Parameter('open_loop_pattern', value=[0.5, 3.0])])),
    ]
    sim.set_paused(False)
    for tick, action in steps:
        assert ros.spin_until(lambda at=tick: engine.tick_index >= at)
        action()
    # a pause with single steps in between, then on to the end
    assert ros.spin_until(lambda: engine.tick_index >= 100)
    sim.set_paused(True)
    for _ in range(3):
        sim.step()
    sim.set_paused(False)
    assert ros.spin_until(lambda: engine.tick_index >= last_tick)
    sim.set_paused(True)


def test_recording_holds_every_topic_the_inputs_and_the_parameters(
        ros: Ros, tmp_path: Path) -> None:
    path = tmp_path / 'run.mcap'
    sim = ros.sim(namespace='/line', record_path=str(path), real_time_factor=0.0,
                  start_paused=True, publish_clock=True, cmd_timeout=0.0)
    assert sim.recording_path == path
    drive(ros, sim, 140)
    ticks = sim.engine.tick_index
    topics = {t.topic: t for t in sim.topics()}
    ros.executor.remove_node(sim)
    ros.nodes.remove(sim)
    sim.destroy_node()  # finishes the file

    bag = read_bag(path)
    # every topic of the node is a channel with its type; every message decoded
    with AnyReader([path]) as reader:
        channels = {c.topic: c for c in reader.connections}
    assert set(channels) == set(topics)
    for topic, info in topics.items():
        assert channels[topic].msgtype == info.type_name
        qos = channels[topic].ext.offered_qos_profiles[0]
        assert qos.depth == info.qos.depth
        assert qos.durability.name.lower() == info.qos.durability
    for topic in ('/line/particles', '/line/particle_states', '/line/channel_mass',
                  '/line/cone_state', '/clock'):
        assert len(bag[topic]) == ticks, topic
    # log time = simulation time = header stamp of the message
    for log_time, message in bag['/line/particle_states']:
        assert log_time == message.header.stamp.sec * 10 ** 9 + message.header.stamp.nanosec
    assert [t for t, _ in bag['/clock']] == [
        m.clock.sec * 10 ** 9 + m.clock.nanosec for _, m in bag['/clock']]
    assert bag['/line/exit_events'], 'pieces left the cone'
    # the received commands, as received
    assert [m.data for _, m in bag['/line/rotation_cmd']] == [8.0, -9.0]
    assert len(bag['/line/spawn']) == 1 and len(bag['/line/spawn'][0][1].poses) == 2
    # applied inputs with their ticks, and what happened at the node
    recorded = events(bag, '/line/sim_node/events')
    kinds = [e['event'] for e in recorded]
    for kind in ('rotation', 'spawn', 'reset', 'reconfigure', 'parameters', 'pause',
                 'resume', 'step'):
        assert kind in kinds, kind
    rotation = [e for e in recorded if e['event'] == 'rotation']
    assert [e['omega'] for e in rotation] == [8.0, -9.0]
    # sent once tick 10 was under way or done: applied by tick 10 at the earliest
    assert all(e['tick'] >= 10 for e in rotation)
    spawn = next(e for e in recorded if e['event'] == 'spawn')
    assert spawn['positions'] == [[0.05, 0.02, 0.05], [-0.08, 0.03, 0.04]]
    for e in recorded:
        if e['event'] in INPUT_EVENTS:  # logged at the start of the tick that applied it
            assert e['t'] == pytest.approx(e['tick'] * 0.02, abs=1e-12)
    # metadata: every parameter as text, version, seed, re-simulation data
    meta = read_metadata(path)
    run = meta[METADATA_NAME]
    assert run['model.cone_diameter'] == '0.45'
    assert run['model.channel_count'] == '14'
    assert run['model.channel_boundary'] == '108.0'
    assert run['model.channel_numbering'] == 'clockwise'
    assert run['model.normal_force'] == 'newton'
    assert run['feed.seed'] == '0' and run['seed'] == '0'
    assert run['feed.rate'] == '2.0'  # as started; the change is an event
    assert run['publish_clock'] == 'true'
    assert run['record_path'] == str(path)
    assert run['source'] == 'sim_node' and run['version'] == '0.1.0'
    assert run['node'] == '/line/sim_node'
    params = json.loads(run['parameters_json'])
    assert set(params) == {spec.name for spec in parameter_specs()}  # every parameter
    assert json.loads(run['engine_config'])['seed'] == 0
    assert json.loads(run['input_topics']) == [
        '/line/channel_feed', '/line/rotation_cmd', '/line/spawn']
    assert meta[END_METADATA_NAME]['ticks'] == str(ticks)
    with path.open('rb') as stream:
        summary = mcap.reader.make_reader(stream).get_summary()
    assert summary is not None and summary.statistics.message_count == sum(
        len(v) for v in bag.values())


def resimulate(source: Path, again: Path, **params: Any) -> int:
    """Re-simulate ``source`` into ``again`` until the end; return the ticks it made."""
    ros = Ros()
    try:
        sim = ros.sim(replay_commands=str(source), record_path=str(again),
                      real_time_factor=0.0, **params)
        assert ros.spin_until(lambda: not sim.replaying, 120.0)
        return sim.engine.tick_index
    finally:
        ros.close()


def test_resimulation_reproduces_the_recorded_run(tmp_path: Path) -> None:
    original = tmp_path / 'original.mcap'
    again = tmp_path / 'again.mcap'
    first = Ros()
    try:
        sim = first.sim(record_path=str(original), real_time_factor=0.0, start_paused=True,
                        cmd_timeout=0.0)
        drive(first, sim, 160)
        ticks = sim.engine.tick_index
    finally:
        first.close()

    second = Ros()
    try:
        # given values of recorded parameters are ignored: the recording's count
        sim = second.sim(replay_commands=str(original), record_path=str(again),
                         real_time_factor=0.0, cmd_timeout=3.0)
        assert sim.replaying
        assert sim.get_parameter('cmd_timeout').value == 0.0
        assert second.spin_until(lambda: not sim.replaying, 120.0)
        assert sim.paused and sim.engine.tick_index == ticks
    finally:
        second.close()

    a, b = read_bag(original), read_bag(again)
    for topic in ('/particle_states', '/exit_events', '/channel_mass', '/cone_state',
                  '/particles', '/markers', '/hopper_weights', '/pack_events'):
        assert [t for t, _ in a[topic]] == [t for t, _ in b[topic]], topic
        for (_, ma), (_, mb) in zip(a[topic], b[topic]):
            assert plain(ma) == plain(mb), topic
    assert len(a['/exit_events']) > 0
    assert len(a['/particle_states']) == ticks == len(a['/hopper_weights'])  # the weigher
    applied_a = [e for e in events(a, '/sim_node/events') if e['event'] in INPUT_EVENTS]
    applied_b = [e for e in events(b, '/sim_node/events') if e['event'] in INPUT_EVENTS]
    assert applied_a == applied_b
    assert sorted(e['event'] for e in applied_a) == [
        'reconfigure', 'reconfigure', 'reset', 'rotation', 'rotation', 'spawn']
    # the re-simulated run has no received commands of its own
    assert b['/rotation_cmd'] == [] and b['/spawn'] == []
    assert read_metadata(again)[METADATA_NAME]['replay_commands'] == str(original)


def test_live_inputs_are_refused_while_resimulating(ros: Ros, tmp_path: Path) -> None:
    original = tmp_path / 'short.mcap'
    sim = ros.sim(record_path=str(original), real_time_factor=0.0, start_paused=True)
    for _ in range(5):
        sim.step()
    ros.executor.remove_node(sim)
    ros.nodes.remove(sim)
    sim.destroy_node()

    sim = ros.sim(namespace='/again', replay_commands=str(original), record_path='',
                  start_paused=True)
    received: list[Any] = []
    sim.add_message_hook(lambda r: received.append(r) if r.direction == 'in' else None)
    cmd = ros.client.create_publisher(Float64, '/again/rotation_cmd', 10)
    assert ros.spin_until(lambda: cmd.get_subscription_count() > 0)
    cmd.publish(Float64(data=1.0))
    assert ros.spin_until(lambda: bool(received))
    assert sim.engine.pending == ()
    result = sim.set_parameters([Parameter('feed.rate', value=9.0)])[0]
    assert not result.successful and 're-simulating' in result.reason
    for _ in range(5):
        sim.step()
    assert not sim.replaying and sim.paused  # done after the 5 recorded ticks
    cmd.publish(Float64(data=1.0))
    assert ros.spin_until(lambda: len(received) == 2)
    assert len(sim.engine.pending) == 1  # live again


def test_record_path_default_template_and_off(
        ros: Ros, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    template = 'runs/sim_node_%Y%m%dT%H%M%S.mcap'
    first = ros.sim(namespace='/a', record_path=template, start_paused=True)
    second = ros.sim(namespace='/b', record_path=template, start_paused=True)
    off = ros.sim(namespace='/c', record_path='', start_paused=True)
    assert first.recording_path.parent == tmp_path / 'runs'
    assert first.recording_path.name.startswith('sim_node_2')
    assert second.recording_path != first.recording_path  # same second: _2 appended
    assert off.recording_path is None
    first.step()
    for node in (first, second, off):
        ros.executor.remove_node(node)
        ros.nodes.remove(node)
        node.destroy_node()
    assert sorted(p.name for p in (tmp_path / 'runs').iterdir()) == sorted(
        [first.recording_path.name, second.recording_path.name])
    assert len(read_bag(first.recording_path)['/a/particle_states']) == 1


@pytest.mark.parametrize('compression', ['zstd', 'lz4', 'none'])
def test_compression_and_file_size_are_the_node_s_parameters(
        ros: Ros, tmp_path: Path, compression: str) -> None:
    # record_compression and record_max_file_size set through the node: every chunk of
    # every part is compressed so, and the run is split into parts of at most that size
    path = tmp_path / 'run.mcap'
    sim = ros.sim(record_path=str(path), real_time_factor=0.0, record_compression=compression,
                  record_max_file_size=150_000, **{'feed.rate': 20.0})
    assert ros.spin_until(lambda: len(sim.recording.paths) >= 3, 60.0)
    sim.close_recording()
    paths = sim.recording.paths
    for part in paths:
        with part.open('rb') as stream:
            chunks = [r for r in StreamReader(stream, emit_chunks=True).records
                      if isinstance(r, Chunk)]
        assert chunks and {c.compression for c in chunks} == {
            '' if compression == 'none' else compression}
    # a part's data ends before the message that would take it past the size (its index
    # and summary come after: the file is a little larger, as rosbag2's are)
    for part in paths[:-1]:
        with part.open('rb') as stream:
            footer = [r for r in StreamReader(stream, emit_chunks=True).records
                      if isinstance(r, Footer)][-1]
        assert footer.summary_start <= 150_000 + 2_000, (part, footer)
    assert sum(len(v) for p in paths for v in read_bag(p).values()) > 0


def test_min_free_space_is_the_node_s_parameter(ros: Ros, tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    # more free space asked for than any disk has: the start is refused, no file left
    with pytest.raises(RecordingError, match='record_min_free_space'):
        ros.sim(record_path=str(tmp_path / 'full.mcap'), record_min_free_space=2 ** 62)
    assert not (tmp_path / 'full.mcap').exists()
    # the disk fills during the run: the recording stops, the simulation goes on
    free = [10 ** 12]
    monkeypatch.setattr(run_recorder, '_free_bytes', lambda _: free[0])
    monkeypatch.setattr(run_recorder, '_SPACE_CHECK_S', 0.0)
    sim = ros.sim(record_path=str(tmp_path / 'run.mcap'), real_time_factor=0.0,
                  record_min_free_space=10 ** 9)
    assert ros.spin_until(lambda: sim.engine.tick_index >= 10, 60.0)
    free[0] = 10 ** 8
    assert ros.spin_until(lambda: sim.recording.error is not None, 60.0)
    assert 'record_min_free_space' in sim.recording.error
    ticks = sim.engine.tick_index
    assert ros.spin_until(lambda: sim.engine.tick_index > ticks + 20, 60.0)  # goes on
    assert open_recording(tmp_path / 'run.mcap').message_count > 0


def test_unwritable_record_path_is_refused_at_start(ros: Ros, tmp_path: Path) -> None:
    blocked = tmp_path / 'file'
    blocked.write_text('not a directory')
    with pytest.raises(RecordingError, match='cannot create the directory'):
        ros.sim(record_path=str(blocked / 'run.mcap'))
    # /proc takes no new files, not even from root
    with pytest.raises(RecordingError, match="cannot open MCAP file '/proc/run.mcap'"):
        ros.sim(namespace='/proc_test', record_path='/proc/run.mcap')


def test_read_only_directory_is_refused_at_start(ros: Ros, tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    # a directory this user may not write into: the file's open fails with EACCES. Root may
    # write anywhere, so the error is also injected where the recorder opens the file
    readonly = tmp_path / 'readonly'
    readonly.mkdir()
    readonly.chmod(0o500)
    real_open = open

    def refusing(file: Any, mode: str = 'r', *args: Any, **kwargs: Any) -> Any:
        if Path(file).parent == readonly and set(mode) & set('wax+'):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(file))
        return real_open(file, mode, *args, **kwargs)

    monkeypatch.setattr(mcap_writer, 'open', refusing, raising=False)
    try:
        with pytest.raises(RecordingError, match='Permission denied'):
            ros.sim(record_path=str(readonly / 'run.mcap'))
        assert not (readonly / 'run.mcap').exists()
    finally:
        readonly.chmod(0o700)


def test_resimulation_reproduces_failed_pieces(tmp_path: Path) -> None:
    original = tmp_path / 'original.mcap'
    again = tmp_path / 'again.mcap'
    first = Ros()
    try:
        # max_steps = 1: pieces that need more than one step in a tick fail
        sim = first.sim(record_path=str(original), real_time_factor=0.0,
                        **{'solver.max_steps': 1, 'feed.rate': 50.0})
        assert first.spin_until(lambda: sim.engine.tick_index >= 30, 60.0)
        sim.set_paused(True)
        ticks = sim.engine.tick_index
    finally:
        first.close()
    assert resimulate(original, again) == ticks
    a, b = read_bag(original), read_bag(again)
    failed_a = [e for e in events(a, '/sim_node/events') if e['event'] == 'failure']
    failed_b = [e for e in events(b, '/sim_node/events') if e['event'] == 'failure']
    assert failed_a and failed_a == failed_b
    assert {'id', 't', 'position', 'velocity', 'mass', 'reason'} <= set(failed_a[0])


def test_a_split_run_is_read_by_rosbags_and_resimulated_exactly(tmp_path: Path) -> None:
    original = tmp_path / 'split' / 'run.mcap'
    again = tmp_path / 'again.mcap'
    first = Ros()
    try:
        # 160 ticks of 20 ms in files of 0.7 s: 5 files
        sim = first.sim(record_path=str(original), real_time_factor=0.0, start_paused=True,
                        cmd_timeout=0.0, record_max_file_duration=0.7)
        drive(first, sim, 160)
        ticks = sim.engine.tick_index
        sim.close_recording()
        parts = sim.recording.paths
    finally:
        first.close()
    assert len(parts) >= 3
    for part in parts:
        bag = read_bag(part)  # each file on its own: complete and readable
        assert bag['/particle_states'] and read_metadata(part)[METADATA_NAME]
    assert resimulate(tmp_path / 'split', again, record_max_file_duration=0.0) == ticks
    b = read_bag(again)
    a: dict[str, list[tuple[int, Any]]] = {}
    for part in parts:
        for topic, messages in read_bag(part).items():
            a.setdefault(topic, []).extend(messages)
    for topic in ('/particle_states', '/exit_events', '/channel_mass', '/cone_state'):
        assert [t for t, _ in a[topic]] == [t for t, _ in b[topic]], topic
        for (_, ma), (_, mb) in zip(a[topic], b[topic]):
            assert plain(ma) == plain(mb), topic
    assert len(a['/particle_states']) == ticks


def test_a_vanished_directory_stops_the_recording_not_the_simulation(
        ros: Ros, tmp_path: Path) -> None:
    folder = tmp_path / 'usb'
    sim = ros.sim(record_path=str(folder / 'run.mcap'), real_time_factor=0.0,
                  record_max_file_duration=0.2, **{'diagnostics.period': 0.1})
    statuses: list[Any] = []
    ros.client.create_subscription(DiagnosticArray, '/diagnostics',
                                   lambda msg: statuses.extend(msg.status), 10)
    assert ros.spin_until(lambda: len(sim.recording.paths) >= 3, 60.0)
    folder.rename(tmp_path / 'moved')
    assert ros.spin_until(lambda: sim.recording.error is not None, 60.0)
    ticks = sim.engine.tick_index
    assert ros.spin_until(lambda: sim.engine.tick_index > ticks + 50, 60.0)  # goes on
    assert ros.spin_until(lambda: any(
        s.level == DiagnosticStatus.ERROR and s.name.endswith('recording') for s in statuses),
        30.0)
    recording = open_recording(tmp_path / 'moved' / 'run.mcap')
    assert recording.message_count > 0
