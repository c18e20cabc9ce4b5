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
Recording of a real sim_node process that is stopped by SIGINT, SIGTERM or SIGKILL.

Each test starts ``python -m cone_feeder_sim.ros.sim_node`` from this source tree with its own
ROS_DOMAIN_ID and namespace, follows its simulation time on ``cone_state`` and ends it with a
signal; the process is always killed in teardown. The file is read back with the mcap
package and with rosbags (the independent reader), which decodes every message.
"""

from collections.abc import Iterator, Sequence
import os
from pathlib import Path
import random
import signal
import struct
import subprocess
import sys
import time
from typing import Any

from cone_feeder_sim.formats.mcap_reader import open_recording
from cone_feeder_sim.formats.mcap_reader import recover_mcap
from cone_feeder_sim.formats.runlog import END_METADATA_NAME, METADATA_NAME
from crowds import crowd_in_layers
import mcap.exceptions
import mcap.reader
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
import pytest
from rosbags.highlevel import AnyReader
from sensor_msgs.msg import JointState
from sim_process import Client, FIRST_MESSAGE_TIMEOUT, random_domain, SimProcess

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / 'config' / 'sim_node.yaml'
#: How long a node stopped in a long tick may take to exit: generous (the recording closed,
#: on a loaded machine); the tick it stops would take minutes to hours.
STOP_TIMEOUT = 30.0


class Run:
    """A recording sim_node process and a client that follows its simulation time."""

    def __init__(self, tmp_path: Path, record_path: str, extra: Sequence[str] = ()) -> None:
        domain = random_domain()
        self.namespace = f'/rec{random.randrange(1_000_000)}'
        args = [sys.executable, '-m', 'cone_feeder_sim.ros.sim_node', '--ros-args',
                '--params-file', str(CONFIG), '-r', f'__ns:={self.namespace}',
                '-p', f'record_path:={record_path}', '-p', 'feed.rate:=20.0', *extra]
        env = dict(os.environ)
        env['PYTHONPATH'] = os.pathsep.join([str(ROOT)] + (
            [env['PYTHONPATH']] if env.get('PYTHONPATH') else []))
        self.process = SimProcess(args, domain, tmp_path / 'sim_node.log', env=env,
                                  cwd=tmp_path)
        self.client: Client | None = None
        self.domain = domain
        self.last_ns = 0

    def follow(self, until_s: float) -> None:
        """Wait until the node's simulation time (cone_state stamps) reaches until_s."""
        if self.client is None:
            self.client = Client(self.domain, namespace=self.namespace)

            def seen(msg: Any) -> None:
                stamp = msg.header.stamp
                self.last_ns = max(self.last_ns, stamp.sec * 1_000_000_000 + stamp.nanosec)

            self.client.node.create_subscription(JointState, 'cone_state', seen, 10)
            assert self.client.spin_until(
                lambda: self.last_ns > 0 or not self.process.alive(),
                FIRST_MESSAGE_TIMEOUT), self.process.log()
        assert self.client.spin_until(
            lambda: self.last_ns >= until_s * 1e9 or not self.process.alive(), 60.0)
        assert self.process.alive(), self.process.log()

    def signal(self, signum: int, timeout: float = 30.0) -> int:
        """Send a signal and return the exit status."""
        self.process.proc.send_signal(signum)
        return self.process.proc.wait(timeout)

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
        if self.process.alive():
            self.process.proc.kill()
        self.process.stop()


@pytest.fixture
def start(tmp_path: Path) -> Iterator[Any]:
    runs: list[Run] = []

    def make(record_path: str, extra: Sequence[str] = ()) -> Run:
        runs.append(Run(tmp_path, record_path, extra))
        return runs[-1]

    try:
        yield make
    finally:
        for run in runs:
            run.close()


def decode_all(path: Path) -> dict[str, list[tuple[int, Any]]]:
    """Decode every message with rosbags; return topic -> [(log time, message)]."""
    out: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([path]) as reader:
        for connection, log_time, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            out.setdefault(connection.topic, []).append((log_time, message))
    return out


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_signal_finishes_the_file(start: Any, tmp_path: Path, signum: int) -> None:
    path = tmp_path / 'run.mcap'
    run = start(str(path))
    run.follow(1.0)
    status = run.signal(signum)
    assert status == 0, run.process.log()
    assert 'recorded' in run.process.log()
    # complete: summary with statistics, the end metadata, readable by index
    with path.open('rb') as stream:
        reader = mcap.reader.make_reader(stream)
        summary = reader.get_summary()
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    assert summary is not None and summary.statistics is not None
    assert METADATA_NAME in metadata and END_METADATA_NAME in metadata
    ticks = int(metadata[END_METADATA_NAME]['ticks'])
    messages = decode_all(path)
    states = messages[f'{run.namespace}/particle_states']
    assert len(states) == ticks
    assert states[-1][0] >= run.last_ns  # everything up to the signal
    assert sum(len(v) for v in messages.values()) == summary.statistics.message_count


def long_tick(case: str) -> list[str]:
    """
    Return the node's arguments for ticks that would compute far longer than a test waits.

    No step may exceed h_max = 1e-8 s: each of the five pieces alone takes 2e6 steps in a
    0.02-s tick (seconds each); the island of 70 pieces of a crowd, coupled exactly, takes
    2e6 steps of its 700+ unknowns (hours).
    """
    args = ['-p', 'solver.h_max:=1.0e-8', '-p', 'solver.max_steps:=1000000000000',
            '-p', 'feed.rate:=0.0', '-p', 'real_time_factor:=0.0']
    if case == 'crowd-exact':
        crowd = crowd_in_layers(2, lift=0.0)
        flat = ', '.join(repr(float(v)) for v in crowd.reshape(-1))  # doubles: 0.0, not 0
        args += ['-p', f'initial_pieces.positions:=[{flat}]',
                 '-p', f'initial_pieces.d:=[{", ".join(["225.0"] * len(crowd))}]',
                 '-p', 'interactions.coupling:=exact']
    return args


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize('case', ['alone', 'crowd-exact'])
def test_a_signal_stops_the_tick_under_way(start: Any, tmp_path: Path, case: str,
                                           signum: int) -> None:
    # the node drops the tick under way (its kernels read the engine's stop flag) and
    # finishes its recording: answered at once, not after the tick (ros2 launch kills a
    # node 5 s after its SIGINT)
    path = tmp_path / 'run.mcap'
    run = start(str(path), long_tick(case))
    deadline = time.monotonic() + FIRST_MESSAGE_TIMEOUT
    while 'simulating' not in run.process.log():  # started: its first tick is under way
        assert run.process.alive() and time.monotonic() < deadline, run.process.log()
        time.sleep(0.05)
    time.sleep(0.5)
    sent = time.monotonic()
    status = run.signal(signum, timeout=STOP_TIMEOUT)
    took = time.monotonic() - sent
    assert status == 0, run.process.log()
    assert took < STOP_TIMEOUT and 'recorded' in run.process.log()
    with path.open('rb') as stream:
        reader = mcap.reader.make_reader(stream)
        summary = reader.get_summary()
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    assert summary is not None and summary.statistics is not None
    assert metadata[END_METADATA_NAME]['ticks'] == '0'  # the tick under way was dropped
    messages = decode_all(path)
    assert sum(len(v) for v in messages.values()) == summary.statistics.message_count


def test_sigkill_loses_at_most_about_a_second(start: Any, tmp_path: Path) -> None:
    path = tmp_path / 'killed.mcap'
    run = start(str(path))
    run.follow(3.0)
    seen_ns = run.last_ns
    status = run.signal(signal.SIGKILL)
    assert status == -signal.SIGKILL
    # the file is not finished: the indexed reader refuses it, a streaming reader reads it
    with path.open('rb') as stream, pytest.raises(
            (mcap.exceptions.McapError, OSError, ValueError, struct.error)):
        mcap.reader.make_reader(stream).get_summary()
    last_state = 0
    count = 0
    topic_ids: dict[int, str] = {}
    with path.open('rb') as stream:
        try:
            for record in StreamReader(stream, validate_crcs=True).records:
                if isinstance(record, Channel):
                    topic_ids[record.id] = record.topic
                if isinstance(record, Message):
                    count += 1
                    if topic_ids[record.channel_id].endswith('/particle_states'):
                        last_state = max(last_state, record.log_time)
        except (mcap.exceptions.McapError, EOFError, ValueError):
            pass  # the incomplete end of the file
    assert seen_ns - last_state <= 1.5e9, (seen_ns, last_state)
    assert count > 0
    recording = open_recording(path)
    assert not recording.complete and recording.problem
    assert recording.message_count == count
    # recovered into a complete file, every message decodes with rosbags
    recovered = tmp_path / 'recovered.mcap'
    assert recover_mcap(path, recovered) == count
    messages = decode_all(recovered)
    assert sum(len(v) for v in messages.values()) == count
    states = messages[f'{run.namespace}/particle_states']
    assert states[-1][0] == last_state
    assert [t for t, _ in states] == sorted(t for t, _ in states)


def start_failing(tmp_path: Path, record_path: str) -> subprocess.CompletedProcess:
    """Run sim_node with ``record_path`` until it exits; return what it printed."""
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([str(ROOT)] + (
        [env['PYTHONPATH']] if env.get('PYTHONPATH') else []))
    env['ROS_DOMAIN_ID'] = str(random_domain())
    return subprocess.run(
        [sys.executable, '-m', 'cone_feeder_sim.ros.sim_node', '--ros-args', '-r',
         f'__ns:=/refused{random.randrange(1_000_000)}', '-p', f'record_path:={record_path}'],
        env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120)


def test_unwritable_path_exits_with_an_error(tmp_path: Path) -> None:
    proc = start_failing(tmp_path, '/proc/run.mcap')
    assert proc.returncode == 1
    output = proc.stdout + proc.stderr
    assert "cannot start: cannot open MCAP file '/proc/run.mcap' for writing" in output


@pytest.mark.parametrize('record_path, reason', [
    ('/dev/full', "'/dev/full' is not a regular file"),
    ('/dev/full/run.mcap', 'cannot create the directory'),
])
def test_a_full_or_impossible_destination_is_one_line_and_status_1(
        tmp_path: Path, record_path: str, reason: str) -> None:
    proc = start_failing(tmp_path, record_path)
    assert proc.returncode == 1
    output = proc.stdout + proc.stderr
    assert 'Traceback' not in output
    fatal = [line for line in output.splitlines() if '[FATAL]' in line]
    assert len(fatal) == 1 and 'cannot start' in fatal[0] and reason in fatal[0]
