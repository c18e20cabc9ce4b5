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
Tests of cone_feeder_sim.formats.run_recorder: split files, guards, nothing overwritten.

Every file is written and read back: by rosbags (an independent reader), by mcap's
indexed reader, and by the package's own reader of split runs.
"""

from pathlib import Path

from cone_feeder_sim.errors import RecordingError
from cone_feeder_sim.formats import run_recorder
from cone_feeder_sim.formats.cdr import encode
from cone_feeder_sim.formats.mcap_reader import open_recording, run_parts, SplitRecording
from cone_feeder_sim.formats.run_recorder import (
    END_METADATA_NAME, PART_METADATA_NAME, RecordingLimits, RunRecorder)
from cone_feeder_sim.formats.topics import TOPICS
import mcap.reader
import pytest
from rosbags.highlevel import AnyReader

TOPIC = [('/n', 'std_msgs/msg/Float64', TOPICS['rotation_cmd'].qos)]
META = {'cone_feeder_sim': {'k': 'v'}}
MS = 1_000_000


def record(path: Path, count: int, limits: RecordingLimits, **kwargs: object) -> RunRecorder:
    """Record ``count`` Float64 messages 10 ms apart and close the recorder."""
    recorder = RunRecorder(path, TOPIC, META, limits=limits, **kwargs)
    for i in range(count):
        recorder.write('/n', 'std_msgs/msg/Float64', encode('std_msgs/msg/Float64',
                                                            {'data': float(i)}), 10 * MS * i)
    recorder.close(end_metadata={'ticks': str(count)})
    return recorder


def summary_and_metadata(path: Path) -> tuple[object, dict[str, dict[str, str]]]:
    with path.open('rb') as stream:
        reader = mcap.reader.make_reader(stream)
        return reader.get_summary(), {m.name: dict(m.metadata) for m in reader.iter_metadata()}


def test_a_run_is_split_by_duration_into_complete_files(tmp_path: Path) -> None:
    first = tmp_path / 'run.mcap'
    recorder = record(first, 100, RecordingLimits(max_file_duration_ns=300 * MS))
    assert recorder.error is None
    paths = list(recorder.paths)
    assert [p.name for p in paths] == ['run.mcap', 'run_2.mcap', 'run_3.mcap', 'run_4.mcap']
    runs = set()
    values = []
    for k, path in enumerate(paths, start=1):
        summary, metadata = summary_and_metadata(path)
        assert summary is not None  # complete: summary and footer
        assert metadata['cone_feeder_sim'] == {'k': 'v'}
        assert metadata[PART_METADATA_NAME]['part'] == str(k)
        runs.add(metadata[PART_METADATA_NAME]['run'])
        with AnyReader([path]) as reader:
            times = [t for _, t, _ in reader.messages()]
            values += [reader.deserialize(raw, c.msgtype).data for c, _, raw in
                       reader.messages()]
        assert times and times[-1] - times[0] < 300 * MS
    assert len(runs) == 1
    assert values == [float(i) for i in range(100)]
    assert END_METADATA_NAME in summary_and_metadata(paths[-1])[1]
    assert summary_and_metadata(paths[-1])[1][END_METADATA_NAME]['parts'] == '4'
    # the run is found from its first file, its directory or the list
    assert run_parts(first) == paths
    assert run_parts(tmp_path) == paths
    assert run_parts([str(p) for p in paths[:2]]) == paths[:2]
    recording = open_recording(first)
    assert isinstance(recording, SplitRecording)
    assert [m.log_time_ns for m in recording.messages()] == [10 * MS * i for i in range(100)]
    assert recording.topics['/n'].message_count == 100
    assert recording.metadata[END_METADATA_NAME]['ticks'] == '100'
    assert recording.start_ns == 0 and recording.end_ns == 990 * MS


def test_a_run_is_split_by_size(tmp_path: Path) -> None:
    recorder = record(tmp_path / 'big.mcap', 2000, RecordingLimits(max_file_size=20_000),
                      chunk_size=4_000, compression='none')
    assert len(recorder.paths) >= 3
    for path in recorder.paths[:-1]:
        assert path.stat().st_size < 20_000 + 8_000  # the limit, give or take the summary
    assert open_recording(recorder.path).message_count == 2000


def test_an_unrelated_file_is_not_taken_for_a_part(tmp_path: Path) -> None:
    record(tmp_path / 'a.mcap', 5, RecordingLimits())
    record(tmp_path / 'a-2.mcap', 5, RecordingLimits())
    (tmp_path / 'b.mcap').write_bytes((tmp_path / 'a.mcap').read_bytes())
    (tmp_path / 'b_2.mcap').write_bytes((tmp_path / 'a-2.mcap').read_bytes())
    assert run_parts(tmp_path / 'b.mcap') == [tmp_path / 'b.mcap']  # another run id


def test_nothing_is_ever_overwritten(tmp_path: Path) -> None:
    existing = tmp_path / 'run.mcap'
    existing.write_bytes(b'precious')
    with pytest.raises(RecordingError, match='exists: a recording never overwrites'):
        RunRecorder(existing, TOPIC, META)
    assert existing.read_bytes() == b'precious'
    (tmp_path / 'other_3.mcap').write_bytes(b'precious')
    with pytest.raises(RecordingError, match='other_3.mcap'):
        RunRecorder(tmp_path / 'other.mcap', TOPIC, META)
    with pytest.raises(RecordingError, match='not a regular file'):
        RunRecorder('/dev/full', TOPIC, META)


def test_too_little_free_space_is_refused_at_the_start(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match='less than the .* MB kept free'):
        RunRecorder(tmp_path / 'r.mcap', TOPIC, META,
                    limits=RecordingLimits(min_free_bytes=2 ** 62))
    assert not list(tmp_path.iterdir())  # no file left behind


def test_the_free_space_guard_stops_the_recording_and_keeps_the_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(run_recorder, '_SPACE_CHECK_S', 0.0)
    free = [10 ** 12]
    monkeypatch.setattr(run_recorder, '_free_bytes', lambda _: free[0])
    path = tmp_path / 'guarded.mcap'
    recorder = RunRecorder(path, TOPIC, META, limits=RecordingLimits(min_free_bytes=10 ** 9))
    data = encode('std_msgs/msg/Float64', {'data': 1.0})
    for i in range(50):
        recorder.write('/n', 'std_msgs/msg/Float64', data, i * MS)
    recorder.maybe_flush()
    deadline = 200
    while recorder.message_count < 50 and deadline:
        deadline -= 1
        run_recorder.time.sleep(0.05)
    free[0] = 10 ** 6  # the disk fills up
    for i in range(50, 100):
        recorder.write('/n', 'std_msgs/msg/Float64', data, i * MS)
    recorder.close(end_metadata={'ticks': '100'})  # does not raise
    assert isinstance(recorder.error, RecordingError)
    assert 'kept free' in str(recorder.error)
    summary, _ = summary_and_metadata(path)
    assert summary is not None and summary.statistics.message_count >= 50
    assert open_recording(path).message_count == summary.statistics.message_count


def test_a_vanished_directory_ends_the_recording_and_keeps_what_was_written(
        tmp_path: Path) -> None:
    folder = tmp_path / 'usb'
    recorder = RunRecorder(folder / 'run.mcap', TOPIC, META,
                           limits=RecordingLimits(max_file_duration_ns=100 * MS))
    data = encode('std_msgs/msg/Float64', {'data': 1.0})
    for i in range(25):
        recorder.write('/n', 'std_msgs/msg/Float64', data, 10 * MS * i)
    deadline = 200
    while recorder.message_count < 25 and deadline:
        deadline -= 1
        run_recorder.time.sleep(0.05)
    assert len(recorder.paths) == 3
    moved = tmp_path / 'moved'
    folder.rename(moved)  # unplugged, or removed by someone
    for i in range(25, 60):
        recorder.write('/n', 'std_msgs/msg/Float64', data, 10 * MS * i)
    recorder.close(end_metadata={})
    assert isinstance(recorder.error, RecordingError)
    for name in ('run.mcap', 'run_2.mcap'):
        assert summary_and_metadata(moved / name)[0] is not None
    assert open_recording(moved / 'run.mcap').message_count >= 25
