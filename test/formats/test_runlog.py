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
Tests of run logs: events, metadata, the node's recorder and the runner's MCAP output.

The node's recorder writes from a thread; the headless runner's ``--mcap`` output is read
back with rosbags, the independent reader.
"""

import csv
import datetime
import json
import os
from pathlib import Path
import subprocess
import sys
import time
from typing import Any

from cone_feeder_sim.cli import main as cli_main
from cone_feeder_sim.errors import ConeFeederError
from cone_feeder_sim.feeder.engine import (
    ChannelFeed, DriveParams, EngineConfig, FeederEngine, FeedParams, PieceSpec, Reconfigure,
    ResetRequest, RotationCommand, SpawnRequest)
from cone_feeder_sim.formats.cdr import encode
from cone_feeder_sim.formats.pointcloud import EXIT_DTYPE
from cone_feeder_sim.formats.run_recorder import RunRecorder
from cone_feeder_sim.formats.runlog import (
    END_METADATA_NAME, engine_config_json, engine_input_from_event, event_text, expand_record_path,
    input_event, METADATA_NAME, parameter_text)
from cone_feeder_sim.formats.topics import RUNNER_TOPICS, TOPICS
from cone_feeder_sim.physics.params import ProductParams
from cone_feeder_sim.weigher.machine import WeigherParams
import mcap.exceptions
import mcap.reader
from mcap.records import Message
from mcap.stream_reader import StreamReader
import numpy as np
import pytest
from rosbags.highlevel import AnyReader

SCENARIO = """\
duration: 2.0
output_interval: 0.02
rotation: [[0.0, 0.0], [0.4, -10.47]]
particles:
  - {position: [0.11, -0.01, 0.03], d: 225.0}
  - {position: [0.14, 0.06, 0.03], d: 30.0}
  - {position: [0.02, 0.0, 0.0], on_surface: true}
"""


def inputs() -> list[Any]:
    """Return one engine input of every kind, with non-trivial values."""
    product = ProductParams(m=0.2, d=135.0)
    return [
        RotationCommand(-7.123456789012345),
        SpawnRequest(np.array([[0.05, 0.01, 0.06], [-0.07, 0.02, 0.05]]),
                     np.array([[0.0, 0.1, 0.0], [0.0, 0.0, 0.0]]), (product, product)),
        SpawnRequest(np.array([[0.1 / 3.0, -0.02, 0.07]])),
        Reconfigure(drive=DriveParams(cmd_timeout=0.0, pattern=((0.3, 4.0), (0.1, -2.5))),
                    feed=FeedParams(rate=30.0, d_values=(30.0, 750.0), mass_rel_std=0.1)),
        Reconfigure(feed=FeedParams(rate=0.0)),
        ResetRequest(),
        ChannelFeed(tuple(0.1 * k / 3.0 for k in range(14))),  # (a reset restores 1.0)
    ]


def test_input_events_round_trip_through_json_exactly() -> None:
    config = EngineConfig(feed=FeedParams(rate=20.0), seed=7,
                          initial_pieces=(PieceSpec((0.1, 0.0, 0.03)),),
                          weigher=WeigherParams())
    direct, again = FeederEngine(config), FeederEngine(config)
    for tick, item in enumerate(inputs() * 2):
        text = event_text(input_event(tick, tick * config.dt, item))
        event = json.loads(text)
        assert event['tick'] == tick
        direct.submit(item)
        again.submit(engine_input_from_event(event))
        for _ in range(3):
            a, b = direct.tick(), again.tick()
            np.testing.assert_array_equal(a.positions, b.positions)
            np.testing.assert_array_equal(a.velocities, b.velocities)
            np.testing.assert_array_equal(a.masses, b.masses)
            assert (a.angle, a.omega) == (b.angle, b.omega)
    assert direct.drive == again.drive and direct.feed == again.feed
    np.testing.assert_array_equal(direct.weigher.amplitude, again.weigher.amplitude)
    assert direct.weigher.amplitude[3] == 0.1 * 3 / 3.0


def test_malformed_or_unknown_events_are_refused() -> None:
    with pytest.raises(ConeFeederError, match='not an engine input'):
        engine_input_from_event({'event': 'pause', 'tick': 3})
    with pytest.raises(ConeFeederError, match='malformed rotation event'):
        engine_input_from_event({'event': 'rotation', 'tick': 3})
    with pytest.raises(ConeFeederError, match='malformed reconfigure event'):
        engine_input_from_event({'event': 'reconfigure', 'tick': 1, 'drive': {'x': 1}})


def test_parameter_text() -> None:
    assert parameter_text('clockwise') == 'clockwise'
    assert parameter_text(True) == 'true' and parameter_text(False) == 'false'
    assert parameter_text(14) == '14'
    assert parameter_text(0.45) == '0.45' and float(parameter_text(0.1 + 0.2)) == 0.1 + 0.2
    assert parameter_text([2.0, -8.0]) == '[2.0, -8.0]'
    assert parameter_text(None) == '[]'


def test_engine_config_json_is_complete() -> None:
    config = EngineConfig(seed=3, initial_pieces=(PieceSpec((0.1, 0.0, 0.03)),))
    data = json.loads(engine_config_json(config))
    assert data['seed'] == 3 and data['dt'] == 0.02
    assert data['model']['channels'] == {'count': 14, 'boundary': 108.0,
                                         'numbering': 'clockwise'}
    assert data['initial_pieces'][0]['position'] == [0.1, 0.0, 0.03]
    assert set(data) == {'model', 'solver', 'dt', 'drive', 'feed', 'initial_pieces', 'seed',
                         'spawn_max_height', 'weigher'}
    assert data['weigher'] is None
    from cone_feeder_sim.weigher.machine import WeigherParams
    data = json.loads(engine_config_json(EngineConfig(weigher=WeigherParams(target=0.4))))
    assert data['weigher']['target'] == 0.4 and data['weigher']['seed'] == 0


def test_expand_record_path(tmp_path: Path) -> None:
    now = datetime.datetime(2026, 11, 22, 10, 15, 0)
    template = str(tmp_path / 'runs' / 'sim_node_%Y%m%dT%H%M%S.mcap')
    first = expand_record_path(template, now)
    assert first == tmp_path / 'runs' / 'sim_node_20261122T101500.mcap'
    first.parent.mkdir()
    first.write_bytes(b'')
    # -2, not _2: <stem>_2.mcap is the second file of a split run
    assert expand_record_path(template, now).name == 'sim_node_20261122T101500-2.mcap'
    fixed = tmp_path / 'fixed.mcap'
    fixed.write_bytes(b'')
    assert expand_record_path(str(fixed), now) == fixed  # kept (the recorder refuses it)


def stream_messages(path: Path) -> list[Message]:
    """Return the messages a streaming reader gets from a file that may be unfinished."""
    out = []
    with path.open('rb') as stream:
        try:
            for record in StreamReader(stream).records:
                if isinstance(record, Message):
                    out.append(record)
        except (mcap.exceptions.McapError, EOFError, ValueError):
            pass
    return out


def test_run_recorder_loses_nothing_when_the_writer_falls_behind(tmp_path: Path) -> None:
    path = tmp_path / 'many.mcap'
    recorder = RunRecorder(path, [('/a', 'std_msgs/msg/String', TOPICS['~/events'].qos)],
                           {METADATA_NAME: {'k': 'v'}}, max_backlog_bytes=2_000)
    payloads = [f'message {i}'.encode() for i in range(3000)]
    for i, payload in enumerate(payloads):
        recorder.write('/a', 'std_msgs/msg/String', encode('std_msgs/msg/String', {
            'data': payload.decode()}), 1_000 * i)
    recorder.close(end_metadata={'note': 'done'})
    recorder.close()  # idempotent
    with AnyReader([path]) as reader:
        got = [(t, reader.deserialize(raw, c.msgtype).data) for c, t, raw in reader.messages()]
    assert got == [(1_000 * i, p.decode()) for i, p in enumerate(payloads)]
    with path.open('rb') as stream:
        meta = {m.name: dict(m.metadata) for m in
                mcap.reader.make_reader(stream).iter_metadata()}
    assert meta[METADATA_NAME] == {'k': 'v'}
    assert meta[END_METADATA_NAME] == {'note': 'done', 'messages': '3000', 'parts': '1'}


def test_run_recorder_flushes_while_idle(tmp_path: Path) -> None:
    path = tmp_path / 'idle.mcap'
    qos = TOPICS['rotation_cmd'].qos
    recorder = RunRecorder(path, [('/cmd', 'std_msgs/msg/Float64', qos)], {},
                           flush_interval_s=0.2)
    try:
        for i in range(5):
            recorder.write('/cmd', 'std_msgs/msg/Float64',
                           encode('std_msgs/msg/Float64', {'data': float(i)}), i)
        # nothing else is written: the writer thread finishes the chunk on its own
        end = time.monotonic() + 5.0
        while len(stream_messages(path)) < 5 and time.monotonic() < end:
            time.sleep(0.05)
        assert [m.log_time for m in stream_messages(path)] == list(range(5))
    finally:
        recorder.close()


def test_run_recorder_keeps_a_write_error_and_still_finishes_the_file(tmp_path: Path) -> None:
    path = tmp_path / 'error.mcap'
    qos = TOPICS['rotation_cmd'].qos
    recorder = RunRecorder(path, [('/cmd', 'std_msgs/msg/Float64', qos)], {})
    data = encode('std_msgs/msg/Float64', {'data': 1.0})
    recorder.write('/cmd', 'std_msgs/msg/Float64', data, 1)
    recorder.write('/bad', 'no_such_pkg/msg/Nothing', data, 2)
    end = time.monotonic() + 5.0
    while recorder.error is None and time.monotonic() < end:
        time.sleep(0.02)
    assert 'no_such_pkg/msg/Nothing' in str(recorder.error)
    recorder.write('/cmd', 'std_msgs/msg/Float64', data, 3)  # ignored after the error
    recorder.close()
    with AnyReader([path]) as reader:
        assert [t for _, t, _ in reader.messages()] == [1]


def test_runner_mcap_has_the_topics_schemas_and_qos_of_the_node(tmp_path: Path) -> None:
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text(SCENARIO)
    events, path = tmp_path / 'events.csv', tmp_path / 'out' / 'run.mcap'
    assert cli_main(['run', str(scenario), '--events', str(events), '--quiet',
                     '--mcap', str(path)]) == 0
    with AnyReader([path]) as reader:
        connections = {c.topic: c for c in reader.connections}
        messages: dict[str, list[tuple[int, Any]]] = {}
        for connection, log_time, raw in reader.messages():
            messages.setdefault(connection.topic, []).append(
                (log_time, reader.deserialize(raw, connection.msgtype)))
    assert set(connections) == {'/' + name for name in RUNNER_TOPICS}
    for name in RUNNER_TOPICS:
        connection = connections['/' + name]
        spec = TOPICS[name]
        assert connection.msgtype == spec.type_name
        qos = connection.ext.offered_qos_profiles[0]
        assert (qos.depth, qos.reliability.name.lower(), qos.durability.name.lower()) == (
            spec.qos.depth, spec.qos.reliability, spec.qos.durability)
    assert len(messages['/particle_states']) == 100  # 2 s at 0.02 s per interval
    assert len(messages['/markers']) == 20  # 10 per simulated second
    for log_time, message in messages['/particle_states'] + messages['/cone_state']:
        assert log_time == message.header.stamp.sec * 10 ** 9 + message.header.stamp.nanosec
    assert messages['/particle_states'][0][1].width == 3
    # the exits in the file are the rows of the CSV; channel_mass sums them per channel
    rows = np.concatenate([np.frombuffer(m.data.tobytes(), dtype=EXIT_DTYPE)
                           for _, m in messages['/exit_events']])
    with events.open() as stream:
        table = list(csv.DictReader(stream))
    assert sorted(rows['id'].tolist()) == sorted(int(r['particle']) for r in table)
    assert len(rows) == 2
    for row in rows:
        line = next(r for r in table if int(r['particle']) == row['id'])
        assert int(line['channel']) == row['channel']
        assert float(line['t']) == pytest.approx(row['exit_time'], abs=1e-9)
    total = np.zeros(14)
    np.add.at(total, rows['channel'].astype(int) - 1, rows['mass'])
    np.testing.assert_array_equal(messages['/channel_mass'][-1][1].data, total)
    with path.open('rb') as stream:
        meta = {m.name: dict(m.metadata) for m in
                mcap.reader.make_reader(stream).iter_metadata()}
    run = meta[METADATA_NAME]
    assert run['source'] == 'cone-feeder-sim run' and run['scenario'] == str(scenario)
    assert (run['model.cone_diameter'], run['model.channel_count'],
            run['model.channel_boundary'], run['model.channel_numbering']) == (
        '0.45', '14', '108.0', 'clockwise')
    assert json.loads(run['rotation']) == [[0.0, 0.0], [0.4, -10.47]]
    assert meta[END_METADATA_NAME]['intervals'] == '100'


def test_runner_mcap_refuses_an_unwritable_path(tmp_path: Path,
                                                capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text(SCENARIO)
    assert cli_main(['run', str(scenario), '--events', str(tmp_path / 'e.csv'), '--quiet',
                     '--mcap', '/proc/run.mcap']) == 2
    assert "cannot open MCAP file '/proc/run.mcap'" in capsys.readouterr().err


SIGNAL_SCRIPT = """
import json, signal, sys, threading, time
from cone_feeder_sim.formats.cdr import encode
from cone_feeder_sim.formats.topics import TOPICS
from cone_feeder_sim.formats.run_recorder import RunRecorder
from cone_feeder_sim.formats.runlog import METADATA_NAME

class Interrupt(Exception):
    pass

inside = False

def handler(signum, frame):
    if inside:  # raise only inside the recorder calls, like SIGINT inside a tick
        raise Interrupt()

recorder = RunRecorder(sys.argv[1], [('/a', 'std_msgs/msg/String', TOPICS['~/events'].qos)],
                       {METADATA_NAME: {'k': 'v'}})
data = encode('std_msgs/msg/String', {'data': 'x' * 64})
main = threading.main_thread().ident
stop = threading.Event()

def interrupt():
    while not stop.is_set():
        signal.pthread_kill(main, signal.SIGUSR1)
        time.sleep(0.0002)

signal.signal(signal.SIGUSR1, handler)
sender = threading.Thread(target=interrupt, daemon=True)
written = interrupted = 0
# the sender needs the GIL to send: at the default 5-ms switch interval a few interrupts a
# second land; at 0.1 ms hundreds do, and the writes between them stay few
sys.setswitchinterval(1e-4)
start = time.monotonic()
sender.start()
# a quarter of a second, and on, up to a generous cap, until enough interrupts landed (a
# loaded machine delivers fewer per second)
while (time.monotonic() < start + 0.25 or interrupted <= 100) and time.monotonic() < start + 60:
    try:
        inside = True
        recorder.write('/a', 'std_msgs/msg/String', data, written)
        recorder.maybe_flush()
        inside = False
        written += 1
    except Interrupt:
        inside = False
        interrupted += 1
stop.set()
sender.join()
closer = threading.Thread(target=recorder.close, daemon=True)
closer.start()
closer.join(timeout=20.0)
print(json.dumps({'hung': closer.is_alive(), 'interrupted': interrupted, 'written': written,
                  'recorded': recorder.message_count, 'error': repr(recorder.error)}))
"""


def test_run_recorder_survives_signals_in_the_writing_thread(tmp_path: Path) -> None:
    # Regression: SIGINT landing while the caller's thread held the recorder's lock left it
    # held, and close() then waited forever for the writer thread. A child process
    # interrupts write() and maybe_flush() thousands of times, then must close in time.
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2]))
    proc = subprocess.run([sys.executable, '-c', SIGNAL_SCRIPT, str(tmp_path / 's.mcap')],
                          capture_output=True, text=True, timeout=120, env=env, check=False)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert not result['hung'], result
    assert result['interrupted'] > 100 and result['error'] == 'None', result
    assert result['recorded'] >= result['written'], result
