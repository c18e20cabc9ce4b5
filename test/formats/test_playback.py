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
Tests of reading run logs back: complete, truncated and damaged files, re-simulation plans.

Recordings are written with the package's recorders; what the readers return is checked
against what was written.
"""

import json
from pathlib import Path
import struct

from cone_feeder_sim.cli import main as cli_main
from cone_feeder_sim.errors import RecordingError
from cone_feeder_sim.formats.cdr import default_message, encode
from cone_feeder_sim.formats.mcap_reader import open_recording
from cone_feeder_sim.formats.mcap_writer import McapRecorder
from cone_feeder_sim.formats.run_recorder import RunRecorder
from cone_feeder_sim.formats.runlog import event_text, FORMAT_VERSION, METADATA_NAME
from cone_feeder_sim.formats.topics import qos_from_yaml, QosProfile, TOPICS
from cone_feeder_sim.ros.resim import load_resim_plan
import mcap.reader
import pytest

STEP = 20_000_000


def counter_file(path: Path, count: int = 200, chunk_size: int = 1024 * 1024) -> Path:
    """Write /n (data = i at 1 s + 20 ms * i) and /other (every 10th) with metadata."""
    with McapRecorder(path, chunk_size=chunk_size) as rec:
        rec.add_topic('/n', 'std_msgs/msg/Float64', {'depth': 7, 'durability':
                                                     'transient_local'})
        rec.add_metadata('info', {'a': 'b'})
        for i in range(count):
            rec.write('/n', 'std_msgs/msg/Float64', {'data': float(i)}, 10 ** 9 + i * STEP)
            if i % 10 == 0:
                rec.write('/other', 'std_msgs/msg/String', {'data': str(i)},
                          10 ** 9 + i * STEP)
    return path


def data(messages: list) -> list[float]:
    return [struct.unpack_from('<d', m.data, 4)[0] for m in messages]


def test_complete_file_is_read_through_its_index(tmp_path: Path) -> None:
    recording = open_recording(counter_file(tmp_path / 'c.mcap'))
    assert recording.complete and recording.problem is None
    assert set(recording.topics) == {'/n', '/other'}
    assert recording.topics['/n'].type_name == 'std_msgs/msg/Float64'
    assert recording.topics['/n'].message_count == 200
    assert recording.topics['/other'].message_count == 20
    assert qos_from_yaml(recording.topics['/n'].offered_qos) == QosProfile(
        depth=7, durability='transient_local')
    assert recording.metadata == {'info': {'a': 'b'}}
    assert (recording.start_ns, recording.end_ns) == (10 ** 9, 10 ** 9 + 199 * STEP)
    assert recording.message_count == 220
    # bounds are inclusive; topics filter
    selected = list(recording.messages({'/n'}, 10 ** 9 + 10 * STEP, 10 ** 9 + 20 * STEP))
    assert data(selected) == [float(i) for i in range(10, 21)]
    everything = list(recording.messages())
    assert [m.log_time_ns for m in everything] == sorted(m.log_time_ns for m in everything)


def test_truncated_file_gives_its_readable_beginning(tmp_path: Path) -> None:
    path = counter_file(tmp_path / 't.mcap', count=1000, chunk_size=2000)
    whole = path.read_bytes()
    path.write_bytes(whole[:len(whole) // 2])
    recording = open_recording(path)
    assert not recording.complete and 'not finished' in recording.problem
    assert recording.metadata == {'info': {'a': 'b'}}
    got = data(list(recording.messages({'/n'})))
    assert 300 < len(got) < 1000 and got == [float(i) for i in range(len(got))]
    assert recording.topics['/n'].message_count == len(got)
    assert recording.end_ns == 10 ** 9 + (len(got) - 1) * STEP


def test_damaged_chunk_stops_reading_with_the_reason(tmp_path: Path) -> None:
    path = counter_file(tmp_path / 'd.mcap', count=1000, chunk_size=2000)
    with path.open('rb') as stream:
        chunks = sorted(mcap.reader.make_reader(stream).get_summary().chunk_indexes,
                        key=lambda index: index.chunk_start_offset)
    middle = chunks[len(chunks) // 2]  # zeros inside the records of the middle chunk
    start = middle.chunk_start_offset + middle.chunk_length // 2
    raw = bytearray(path.read_bytes())
    raw[start:start + 64] = bytes(64)
    path.write_bytes(bytes(raw))
    recording = open_recording(path)
    assert recording.complete  # summary and footer are intact
    got = data(list(recording.messages({'/n'})))
    assert 100 < len(got) < 1000 and got == [float(i) for i in range(len(got))]
    assert recording.problem and 'damaged' in recording.problem


def test_what_is_not_a_recording_is_refused(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match='cannot open the recording'):
        open_recording(tmp_path / 'missing.mcap')
    junk = tmp_path / 'junk.mcap'
    junk.write_bytes(b'\x89PNG not mcap')
    with pytest.raises(RecordingError, match='not an MCAP file'):
        open_recording(junk)
    header_only = tmp_path / 'header.mcap'
    header_only.write_bytes(counter_file(tmp_path / 'x.mcap').read_bytes()[:8])
    with pytest.raises(RecordingError, match='not a readable MCAP file'):
        open_recording(header_only)


def test_qos_from_yaml_ignores_what_it_cannot_use() -> None:
    assert qos_from_yaml('') is None
    assert qos_from_yaml('not: [yaml') is None
    assert qos_from_yaml('- history: keep_all\n  depth: 3\n  reliability: best_effort\n') \
        == QosProfile(history='keep_all', depth=3, reliability='best_effort')
    assert qos_from_yaml('- reliability: sometimes\n') is None


def fake_sim_recording(path: Path, ticks: int, events: list[dict],
                       chunk_size: int = 1024 * 1024) -> Path:
    """Write what load_resim_plan reads of a sim_node recording (topics, metadata, events)."""
    topics = {'particle_states': '/particle_states', '~/events': '/sim_node/events'}
    meta = {'format': FORMAT_VERSION, 'source': 'sim_node',
            'parameters_json': json.dumps({'update_rate': 50.0, 'feed.rate': 2.0}),
            'topics': json.dumps(topics), 'engine_config': '{}'}
    recorder = RunRecorder(path, [
        ('/particle_states', 'sensor_msgs/msg/PointCloud2', TOPICS['particle_states'].qos),
        ('/sim_node/events', 'std_msgs/msg/String', TOPICS['~/events'].qos)],
        {METADATA_NAME: meta}, chunk_size=chunk_size)
    cloud = encode('sensor_msgs/msg/PointCloud2', default_message('sensor_msgs/msg/PointCloud2'))
    for event in events:
        recorder.write('/sim_node/events', 'std_msgs/msg/String', encode(
            'std_msgs/msg/String', {'data': event_text(event)}), event['tick'] * STEP)
    for k in range(ticks):
        recorder.write('/particle_states', 'sensor_msgs/msg/PointCloud2', cloud,
                       (k + 1) * STEP)
    recorder.close(end_metadata={'ticks': str(ticks)})
    return path


def test_resim_plan_has_the_inputs_by_tick(tmp_path: Path) -> None:
    events = [{'event': 'rotation', 'tick': 3, 't': 0.06, 'omega': 1.0},
              {'event': 'pause', 'tick': 3, 't': 0.06},
              {'event': 'reset', 'tick': 3, 't': 0.06},
              {'event': 'rotation', 'tick': 9, 't': 0.18, 'omega': -1.0}]
    plan = load_resim_plan(fake_sim_recording(tmp_path / 's.mcap', 12, events))
    assert plan.ticks == 12 and plan.problem is None
    assert plan.parameters == {'update_rate': 50.0, 'feed.rate': 2.0}
    assert [e['event'] for e in plan.events[3]] == ['rotation', 'pause', 'reset']
    assert plan.events[9][0]['omega'] == -1.0


def test_resim_plan_of_a_cut_recording_stops_at_its_last_tick(tmp_path: Path) -> None:
    events = [{'event': 'rotation', 'tick': k, 't': k * 0.02, 'omega': float(k)}
              for k in range(0, 2000, 50)]
    path = fake_sim_recording(tmp_path / 'cut.mcap', 2000, events, chunk_size=4000)
    whole = path.read_bytes()
    path.write_bytes(whole[:len(whole) // 2])
    plan = load_resim_plan(path)
    assert plan.problem and 0 < plan.ticks < 2000
    assert max(plan.events) < plan.ticks


def test_resim_plan_refuses_other_recordings(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match='not a recording of sim_node'):
        load_resim_plan(counter_file(tmp_path / 'c.mcap'))
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text('duration: 0.1\nrotation: [[0.0, 0.0]]\n'
                        'particles:\n  - {position: [0.11, -0.01, 0.03]}\n')
    path = tmp_path / 'runner.mcap'
    assert cli_main(['run', str(scenario), '--events', str(tmp_path / 'e.csv'), '--quiet',
                     '--mcap', str(path)]) == 0
    with pytest.raises(RecordingError, match='only sim_node recordings can be re-simulated'):
        load_resim_plan(path)
