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
Tests of the MCAP recorder: read back with mcap and rosbags, flushing, truncation, crashes.

Files are checked with two independent readers: the ``mcap`` package (its seeking
reader for complete files, its streaming reader for truncated ones) and
``rosbags`` (its rosbag2 MCAP storage reader through ``AnyReader``, which also
parses the ``ros2msg`` schema text).
"""

import io
import os
import pathlib
import re
import signal
import struct
import subprocess
import sys
import textwrap
from typing import Any

from cone_feeder_sim.errors import ConeFeederError
from cone_feeder_sim.errors import RecordingError
from cone_feeder_sim.formats.cdr import decode, default_message
from cone_feeder_sim.formats.mcap_reader import recover_mcap
from cone_feeder_sim.formats.mcap_writer import McapRecorder
from cone_feeder_sim.formats.msgtypes import default_registry
from cone_feeder_sim.formats.topics import QosProfile
import mcap.exceptions
import mcap.reader
from msg_compare import normalize
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.rosbag2.metadata import parse_qos
from yaml import safe_load
from zstandard import ZstdError

REPO = pathlib.Path(__file__).resolve().parents[2]
READ_ERRORS = (mcap.exceptions.McapError, ValueError, struct.error, ZstdError)


class FakeClock:
    """A settable clock for deterministic flush timing."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def header(frame_id: str, stamp_ns: int) -> dict:
    return {
        'stamp': {'sec': stamp_ns // 1_000_000_000, 'nanosec': stamp_ns % 1_000_000_000},
        'frame_id': frame_id}


def sample_stream() -> list:
    """Return (topic, type, message) triples covering every recorded type."""
    marker = default_message('visualization_msgs/msg/Marker')
    marker.update(ns='pieces', type=7, text='Stück 7',
                  points=[{'x': 0.5, 'y': 0.25, 'z': 0.125}, {'x': 1.0, 'y': 2.0, 'z': 3.0}])
    cloud = default_message('sensor_msgs/msg/PointCloud2')
    cloud.update(
        header=header('cone', 5), height=1, width=2, point_step=12, row_step=24,
        fields=[{'name': n, 'offset': 4 * i, 'datatype': 7, 'count': 1}
                for i, n in enumerate('xyz')],
        data=np.arange(6, dtype=np.float32).view(np.uint8), is_dense=True)
    return [
        ('/clock', 'rosgraph_msgs/msg/Clock', {'clock': {'sec': 1, 'nanosec': 2}}),
        ('/speed', 'std_msgs/msg/Float64', {'data': 2.5}),
        ('/layout', 'std_msgs/msg/Float64MultiArray', {
            'layout': {'dim': [{'label': 'n', 'size': 3, 'stride': 3}], 'data_offset': 0},
            'data': np.array([1.0, 2.0, 3.0])}),
        ('/header', 'std_msgs/msg/Header', header('abc', 7)),
        ('/status_text', 'std_msgs/msg/String', {'data': 'läuft ✓'}),
        ('/time', 'builtin_interfaces/msg/Time', {'sec': 3, 'nanosec': 4}),
        ('/pieces', 'geometry_msgs/msg/PoseArray', {
            'header': header('cone', 9), 'poses': [
                {'position': {'x': 1.0, 'y': 2.0, 'z': 3.0},
                 'orientation': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}}] * 2}),
        ('/pose', 'geometry_msgs/msg/PoseStamped', {
            'header': header('c', 11),
            'pose': {'position': {'x': 1.0, 'y': 2.0, 'z': 3.0},
                     'orientation': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}}}),
        ('/cloud', 'sensor_msgs/msg/PointCloud2', cloud),
        ('/joints', 'sensor_msgs/msg/JointState', {
            'header': header('', 13), 'name': ['cone'], 'position': [0.5], 'velocity': [],
            'effort': []}),
        ('/markers', 'visualization_msgs/msg/MarkerArray', {'markers': [marker]}),
        ('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', {
            'header': header('x', 15),
            'status': [{'level': 0, 'name': 'sim', 'message': 'ok', 'hardware_id': '',
                        'values': [{'key': 'k', 'value': 'v'}]}]}),
    ]


def stream_messages(data: bytes) -> list:
    """Read messages with mcap's non-seeking reader until the data end or break off."""
    reader = mcap.reader.NonSeekingReader(io.BytesIO(data), validate_crcs=True)
    result = []
    try:
        for _, channel, message in reader.iter_messages(log_time_order=False):
            result.append((channel.topic, message.log_time, message.data))
    except READ_ERRORS:
        pass
    return result


def rosbags_messages(path: pathlib.Path) -> list:
    with AnyReader([path]) as reader:
        return [
            (connection.topic, timestamp, normalize(reader.deserialize(raw, connection.msgtype)))
            for connection, timestamp, raw in reader.messages(connections=reader.connections)]


def record_samples(path: pathlib.Path, **options: Any) -> list:
    written = []
    qos = {'/diagnostics': {'reliability': 'best_effort', 'durability': 'transient_local',
                            'depth': 1, 'deadline_ns': 1_500_000_000}}
    with McapRecorder(path, qos=qos, **options) as recorder:
        recorder.add_metadata('run', {'scenario': 'unit test', 'seed': '7'})
        for index, (topic, type_name, message) in enumerate(sample_stream()):
            log_time = 1_000_000_000 + 1000 * index
            recorder.write(topic, type_name, message, log_time, publish_time_ns=log_time - 5)
            written.append((topic, type_name, log_time, message))
    return written


@pytest.mark.parametrize('compression', ['zstd', 'lz4', 'none'])
def test_read_back_with_mcap(tmp_path: pathlib.Path, compression: str) -> None:
    path = tmp_path / 'run.mcap'
    written = record_samples(path, compression=compression)
    with open(path, 'rb') as stream:
        reader = mcap.reader.make_reader(stream, validate_crcs=True)
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        assert summary.statistics.message_count == len(written)
        assert summary.statistics.channel_count == len(written)
        schemas = {schema.name: schema for schema in summary.schemas.values()}
        for _, type_name, _, _ in written:
            assert schemas[type_name].encoding == 'ros2msg'
            assert schemas[type_name].data.decode() == default_registry().full_text(type_name)
        channels = {channel.topic: channel for channel in summary.channels.values()}
        assert {channel.message_encoding for channel in channels.values()} == {'cdr'}
        qos = safe_load(channels['/diagnostics'].metadata['offered_qos_profiles'])
        assert qos[0]['reliability'] == 'best_effort'
        assert qos[0]['deadline'] == {'sec': 1, 'nsec': 500_000_000}
        messages = list(reader.iter_messages())
        metadata = list(reader.iter_metadata())
    assert [(m.name, m.metadata) for m in metadata] == [
        ('run', {'scenario': 'unit test', 'seed': '7'})]
    assert len(messages) == len(written)
    for (schema, channel, message), (topic, type_name, log_time, original) in zip(
            messages, written):
        assert (channel.topic, schema.name) == (topic, type_name)
        assert (message.log_time, message.publish_time) == (log_time, log_time - 5)
        assert normalize(decode(type_name, message.data)) == normalize(original)


def test_read_back_with_rosbags(tmp_path: pathlib.Path) -> None:
    path = tmp_path / 'run.mcap'
    written = record_samples(path)
    assert rosbags_messages(path) == [
        (topic, log_time, normalize(message)) for topic, _, log_time, message in written]
    with AnyReader([path]) as reader:
        connection = next(c for c in reader.connections if c.topic == '/diagnostics')
        (qos,) = connection.ext.offered_qos_profiles
        assert (qos.history, qos.depth) == (QosHistory.KEEP_LAST, 1)
        assert (qos.reliability, qos.durability) == (
            QosReliability.BEST_EFFORT, QosDurability.TRANSIENT_LOCAL)
        assert qos.liveliness == QosLiveliness.AUTOMATIC
        assert (qos.deadline.sec, qos.deadline.nsec) == (1, 500_000_000)
        assert (qos.lifespan.sec, qos.lifespan.nsec) == (9223372036, 854775807)
        assert qos.avoid_ros_namespace_conventions is False


def test_qos_profile_yaml_and_validation() -> None:
    text = QosProfile(history='keep_all', depth=0, avoid_ros_namespace_conventions=True,
                      liveliness_lease_duration_ns=2_000_000_001).to_yaml()
    assert safe_load(text) == [{
        'history': 'keep_all', 'depth': 0, 'reliability': 'reliable', 'durability': 'volatile',
        'deadline': {'sec': 9223372036, 'nsec': 854775807},
        'lifespan': {'sec': 9223372036, 'nsec': 854775807},
        'liveliness': 'automatic',
        'liveliness_lease_duration': {'sec': 2, 'nsec': 1},
        'avoid_ros_namespace_conventions': True,
    }]
    (parsed,) = parse_qos(text)
    assert parsed.history == QosHistory.KEEP_ALL
    assert QosProfile.from_value({'depth': 3}) == QosProfile(depth=3)
    assert QosProfile.from_value(None) == QosProfile()
    with pytest.raises(RecordingError, match='reliability must be one of'):
        QosProfile(reliability='sometimes')
    with pytest.raises(RecordingError, match='unknown QoS keys'):
        QosProfile.from_value({'deepth': 3})
    with pytest.raises(RecordingError, match='depth'):
        QosProfile(depth=-1)


def test_flush_interval_bounds_unflushed_data(tmp_path: pathlib.Path) -> None:
    path = tmp_path / 'run.mcap'
    clock = FakeClock()
    recorder = McapRecorder(path, flush_interval_s=1.0, clock=clock)
    empty_size = path.stat().st_size
    for index in range(8):
        clock.now += 0.3
        recorder.write('/speed', 'std_msgs/msg/Float64', {'data': float(index)}, index + 1)
        flushed = 4 if index >= 3 else 0
        flushed = 8 if index >= 7 else flushed
        on_disk = stream_messages(path.read_bytes())
        assert [log_time for _, log_time, _ in on_disk] == list(range(1, flushed + 1))
        if not flushed:
            assert path.stat().st_size == empty_size
    assert recorder.maybe_flush() is False
    recorder.write('/speed', 'std_msgs/msg/Float64', {'data': 9.0}, 9)
    clock.now += 1.0
    assert recorder.maybe_flush() is True
    assert len(stream_messages(path.read_bytes())) == 9
    recorder.close()


def test_chunk_size_bounds_chunks(tmp_path: pathlib.Path) -> None:
    path = tmp_path / 'run.mcap'
    message = {'layout': {'dim': [], 'data_offset': 0}, 'data': np.zeros(100)}
    with McapRecorder(path, chunk_size=2000, clock=FakeClock()) as recorder:
        for index in range(20):
            recorder.write('/data', 'std_msgs/msg/Float64MultiArray', message, index)
        # No time-based flush happened, yet all but the last few messages are on disk.
        assert len(stream_messages(path.read_bytes())) >= 17
    with open(path, 'rb') as stream:
        assert mcap.reader.make_reader(stream).get_summary().statistics.chunk_count >= 7


def chunk_ends(data: bytes) -> list:
    """Return the end offset of every chunk record, walking the raw record framing."""
    ends = []
    position = 8  # magic
    while position < len(data):
        opcode, length = struct.unpack_from('<BQ', data, position)
        position += 9 + length
        if opcode == 0x06:
            ends.append(position)
    assert position == len(data), 'the file must end on a record boundary'
    return ends


def test_truncated_file_keeps_complete_chunks(tmp_path: pathlib.Path) -> None:
    path = tmp_path / 'run.mcap'
    clock = FakeClock()
    recorder = McapRecorder(path, flush_interval_s=1.0, clock=clock)
    written = []
    for index in range(12):
        clock.now += 0.34  # a flush every third message
        message = {'data': f'message {index} ' + 'x' * index}
        recorder.write('/text', 'std_msgs/msg/String', message, 100 + index)
        written.append(('/text', 100 + index, normalize(message)))
    snapshot = path.read_bytes()  # what a SIGKILL now would leave behind
    recorder.close()
    ends = chunk_ends(snapshot)
    assert len(ends) == 4
    boundaries = {end + delta for end in ends for delta in (-1, 0)}
    cuts = sorted(set(range(0, len(snapshot) + 1, 11)) | boundaries)
    for cut in cuts:
        complete = sum(1 for end in ends if end <= cut)
        messages = stream_messages(snapshot[:cut])
        assert [log_time for _, log_time, _ in messages] == [
            100 + index for index in range(3 * complete)], cut
        for _topic, log_time, data in messages:
            assert decode('std_msgs/msg/String', data) == written[log_time - 100][2]
    for cut in (ends[1] + 5, ends[2], len(snapshot) - 1):
        truncated = tmp_path / f'cut_{cut}.mcap'
        truncated.write_bytes(snapshot[:cut])
        recovered = tmp_path / f'recovered_{cut}.mcap'
        count = recover_mcap(truncated, recovered)
        expected = written[:3 * sum(1 for end in ends if end <= cut)]
        assert count == len(expected)
        assert rosbags_messages(recovered) == expected


def test_recover_rejects_non_mcap(tmp_path: pathlib.Path) -> None:
    source = tmp_path / 'junk.mcap'
    source.write_bytes(b'not an mcap file at all')
    with pytest.raises(RecordingError, match='not an MCAP file'):
        recover_mcap(source, tmp_path / 'out.mcap')
    with pytest.raises(RecordingError, match='missing.mcap'):
        recover_mcap(tmp_path / 'missing.mcap', tmp_path / 'out.mcap')


CHILD = textwrap.dedent("""
    import sys, time
    from cone_feeder_sim.formats.mcap_writer import McapRecorder
    recorder = McapRecorder(sys.argv[1], flush_interval_s=3600.0)
    index = 0
    while True:
        recorder.write('/speed', 'std_msgs/msg/Float64', {'data': float(index)}, index + 1)
        index += 1
        if index % 10 == 0:
            recorder.flush()
            print('flushed', index, flush=True)
        time.sleep(0.001)
""")


def test_sigkill_loses_only_the_unflushed_chunk(tmp_path: pathlib.Path) -> None:
    path = tmp_path / 'killed.mcap'
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(REPO)] + os.environ.get('PYTHONPATH', '').split(os.pathsep)))
    child = subprocess.Popen(
        [sys.executable, '-c', CHILD, str(path)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        reported = [int(child.stdout.readline().split()[1]) for _ in range(3)]
        os.kill(child.pid, signal.SIGKILL)
        child.wait(timeout=30)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
        child.stdout.close()
    assert child.returncode == -signal.SIGKILL
    assert reported == [10, 20, 30]
    messages = stream_messages(path.read_bytes())
    assert len(messages) >= 30 and len(messages) % 10 == 0
    assert [log_time for _, log_time, _ in messages] == list(range(1, len(messages) + 1))
    recovered = tmp_path / 'recovered.mcap'
    assert recover_mcap(path, recovered) == len(messages)
    values = [message['data'] for _, _, message in rosbags_messages(recovered)]
    assert values == [float(index) for index in range(len(messages))]


def test_close_is_idempotent_and_exit_completes_the_file(tmp_path: pathlib.Path) -> None:
    path = tmp_path / 'run.mcap'
    with pytest.raises(KeyError), McapRecorder(path) as recorder:
        recorder.write('/speed', 'std_msgs/msg/Float64', {'data': 1.0}, 5)
        raise KeyError('boom')
    assert recorder.closed
    recorder.close()
    with open(path, 'rb') as stream:
        assert mcap.reader.make_reader(stream).get_summary().statistics.message_count == 1
    with pytest.raises(RecordingError, match='closed'):
        recorder.write('/speed', 'std_msgs/msg/Float64', {'data': 2.0}, 6)
    with pytest.raises(RecordingError, match='closed'):
        recorder.add_metadata('late', {})


def test_unwritable_path_fails_at_construction(tmp_path: pathlib.Path) -> None:
    missing = tmp_path / 'no' / 'such' / 'dir' / 'run.mcap'
    with pytest.raises(RecordingError, match=re.escape(str(missing))) as info:
        McapRecorder(missing)
    assert isinstance(info.value, ConeFeederError)
    with pytest.raises(RecordingError, match=re.escape(str(tmp_path))):
        McapRecorder(tmp_path)


def test_invalid_use_is_reported(tmp_path: pathlib.Path) -> None:
    with McapRecorder(tmp_path / 'run.mcap') as recorder:
        recorder.write('/speed', 'std_msgs/Float64', {'data': 1.0}, 1)
        assert recorder.add_topic('/speed', 'std_msgs/msg/Float64') == 1
        with pytest.raises(RecordingError, match="'/speed' is recorded as std_msgs/msg/Float64"):
            recorder.write('/speed', 'std_msgs/msg/String', {'data': 'x'}, 2)
        with pytest.raises(RecordingError, match='nowhere_msgs/msg/Thing'):
            recorder.add_topic('/thing', 'nowhere_msgs/msg/Thing')
        with pytest.raises(RecordingError, match="'/speed'.*data"):
            recorder.write('/speed', 'std_msgs/msg/Float64', {}, 3)
        with pytest.raises(RecordingError, match='unsigned 64-bit'):
            recorder.write('/speed', 'std_msgs/msg/Float64', {'data': 1.0}, -1)
        with pytest.raises(RecordingError, match='must all be str'):
            recorder.add_metadata('run', {'seed': 7})
        assert recorder.message_count == 1
    with pytest.raises(RecordingError, match='flush_interval_s'):
        McapRecorder(tmp_path / 'other.mcap', flush_interval_s=0)
    with pytest.raises(RecordingError, match='compression'):
        McapRecorder(tmp_path / 'other.mcap', compression='gzip')
