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
Tests of replay_node: timing and rate, offsets, inputs, /clock, loop, progress, damaged files.

Recordings are written with the package's recorder (synthetic ones with known log times) or
by the headless runner; the node runs in process with a private rclpy Context, except for
the exit-status checks, which run ``python -m cone_feeder_sim.ros.replay_node``. Wall-clock
bounds are loose: the machine is shared.
"""

from collections.abc import Iterator
import os
from pathlib import Path
import subprocess
import sys
import time
from typing import Any

from cone_feeder_sim.cli import main as cli_main
from cone_feeder_sim.errors import ConeFeederError
from cone_feeder_sim.formats.cdr import encode
from cone_feeder_sim.formats.mcap_writer import McapRecorder
from cone_feeder_sim.formats.run_recorder import RecordingLimits, RunRecorder
from cone_feeder_sim.formats.topics import QosProfile
from cone_feeder_sim.ros.replay_node import ReplayNode
from diagnostic_msgs.msg import DiagnosticArray
import mcap.reader
import pytest
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2
import sim_process
from std_msgs.msg import Float64
from visualization_msgs.msg import MarkerArray

ROOT = Path(__file__).resolve().parents[2]
#: Log time of the first synthetic message (offsets count from here, not from 0).
FIRST_NS = 5_000_000_000
STEP_NS = 20_000_000
COUNT = 51  # 1 s of recorded time at 50 Hz


def synthetic(path: Path, count: int = COUNT, chunk_size: int = 1024 * 1024) -> Path:
    """Write /counter (data = index, every 20 ms from 5 s) and one received /rotation_cmd."""
    with McapRecorder(path, chunk_size=chunk_size) as rec:
        rec.add_topic('/counter', 'std_msgs/msg/Float64', {'depth': 100})
        rec.add_topic('/rotation_cmd', 'std_msgs/msg/Float64')
        rec.add_metadata('cone_feeder_sim', {'input_topics': '["/rotation_cmd"]'})
        for i in range(count):
            rec.write('/counter', 'std_msgs/msg/Float64', {'data': float(i)},
                      FIRST_NS + i * STEP_NS)
            if i == 15:
                rec.write('/rotation_cmd', 'std_msgs/msg/Float64', {'data': 2.5},
                          FIRST_NS + i * STEP_NS + 1)
    return path


class Ros(sim_process.InProcess):
    """A private context and executor with a listening client node."""

    def __init__(self) -> None:
        super().__init__('replay_test_client', timeout=30.0, spin_step=0.005)

    def listen(self, msg_type: Any, topic: str, qos: Any = 100) -> list[tuple[float, Any]]:
        """Subscribe; return the list that collects (arrival monotonic s, message)."""
        received: list[tuple[float, Any]] = []
        self.client.create_subscription(
            msg_type, topic, lambda m: received.append((time.monotonic(), m)), qos)
        return received

    def replay(self, **params: Any) -> ReplayNode:
        overrides = [Parameter(k, value=v) for k, v in params.items()]
        return self.add(ReplayNode(context=self.context, parameter_overrides=overrides))


@pytest.fixture
def ros() -> Iterator[Ros]:
    with Ros() as harness:
        yield harness


def values(received: list[tuple[float, Any]]) -> list[float]:
    return [m.data for _, m in received]


@pytest.mark.parametrize('rate', [1.0, 2.5])
def test_replays_in_order_with_the_recorded_timing_scaled_by_rate(
        ros: Ros, tmp_path: Path, rate: float) -> None:
    path = synthetic(tmp_path / 'counter.mcap')
    counter = ros.listen(Float64, '/counter')
    commands = ros.listen(Float64, '/rotation_cmd')
    node = ros.replay(path=str(path), rate=rate, delay=0.5)
    assert ros.spin_until(lambda: node.done.done(), 30.0)
    ros.spin_until(lambda: len(counter) == COUNT, 5.0)
    assert values(counter) == [float(i) for i in range(COUNT)]
    assert commands == []  # what the recorded node received is not replayed by default
    span = counter[-1][0] - counter[0][0]
    expected = (COUNT - 1) * STEP_NS * 1e-9 / rate
    assert 0.7 * expected < span < 0.7 * expected + 1.0, span
    # evenly spread, not in bursts: the middle message arrives about half-way
    middle = counter[COUNT // 2][0] - counter[0][0]
    assert abs(middle - expected / 2) < 0.25 * expected + 0.2
    assert node.published == COUNT and node.progress() == 1.0


@pytest.mark.parametrize('rate', [1.0, 2.5])
def test_each_message_is_due_at_its_recorded_time_over_the_rate(
        ros: Ros, tmp_path: Path, rate: float) -> None:
    # on a made-up steady clock: message k is published when the clock reaches
    # start + delay + k * step / rate, not a nanosecond before
    now = [10 ** 12]
    path = synthetic(tmp_path / 'counter.mcap')
    counter = ros.listen(Float64, '/counter')
    overrides = [Parameter('path', value=str(path)), Parameter('rate', value=rate),
                 Parameter('delay', value=0.1)]
    node = ros.add(ReplayNode(context=ros.context, parameter_overrides=overrides,
                              clock_ns=lambda: now[0]))
    start = now[0] + 100_000_000
    for k in (0, 1, 2, 16, COUNT - 1):
        due = start + int(k * STEP_NS / rate)
        now[0] = due - 1
        assert ros.spin_until(lambda k=k: node.published >= k, 10.0)
        ros.spin_for(0.05)
        assert node.published == k, (k, node.published)  # not due yet
        now[0] = due
        assert ros.spin_until(lambda k=k: node.published == k + 1, 10.0), k
    assert ros.spin_until(lambda: len(counter) == COUNT and node.done.done(), 10.0)
    assert values(counter) == [float(i) for i in range(COUNT)]


def test_offsets_inputs_and_clock(ros: Ros, tmp_path: Path) -> None:
    path = synthetic(tmp_path / 'counter.mcap')
    counter = ros.listen(Float64, '/counter')
    commands = ros.listen(Float64, '/rotation_cmd')
    clock = ros.listen(Clock, '/clock', QoSProfile(depth=1000,
                                                   reliability=ReliabilityPolicy.RELIABLE))
    node = ros.replay(path=str(path), rate=4.0, delay=0.5, start_offset=0.2, stop_offset=0.6,
                      include_inputs=True, publish_clock=True)
    assert ros.spin_until(lambda: node.done.done(), 30.0)
    ros.spin_until(lambda: len(counter) == 21 and len(clock) == 22, 5.0)
    # [0.2 s, 0.6 s] after the first message: indices 10..30
    assert values(counter) == [float(i) for i in range(10, 31)]
    assert values(commands) == [2.5]
    stamps = [m.clock.sec * 10 ** 9 + m.clock.nanosec for _, m in clock]
    expected = sorted([FIRST_NS + i * STEP_NS for i in range(10, 31)]
                      + [FIRST_NS + 15 * STEP_NS + 1])
    assert stamps == expected


def test_topics_selects_what_is_replayed(ros: Ros, tmp_path: Path) -> None:
    path = synthetic(tmp_path / 'counter.mcap')
    counter = ros.listen(Float64, '/counter')
    commands = ros.listen(Float64, '/rotation_cmd')
    node = ros.replay(path=str(path), rate=10.0, delay=0.5, topics=['/rotation_cmd'])
    assert ros.spin_until(lambda: node.done.done(), 30.0)
    ros.spin_until(lambda: bool(commands), 5.0)
    assert values(commands) == [2.5] and counter == []
    with pytest.raises(ConeFeederError, match=r"topics \['/nothing'\] are not in the recording"):
        ros.replay(path=str(path), topics=['/nothing'])


def test_loop_and_progress_reports(ros: Ros, tmp_path: Path) -> None:
    path = synthetic(tmp_path / 'counter.mcap')
    counter = ros.listen(Float64, '/counter')
    reports = ros.listen(DiagnosticArray, '/diagnostics')
    node = ros.replay(path=str(path), rate=5.0, delay=0.5, loop=True, progress_period=0.1)
    assert ros.spin_until(lambda: len(counter) >= 2 * COUNT + 5, 30.0)
    assert not node.done.done() and node.passes >= 3
    assert values(counter)[:2 * COUNT] == [float(i) for i in range(COUNT)] * 2
    ours = [s for _, m in reports for s in m.status
            if s.name == f'{node.get_fully_qualified_name()}: replay']
    assert len(ours) >= 3
    progress = [float(next(kv.value for kv in s.values if kv.key == 'progress')) for s in ours]
    assert all(0.0 <= p <= 1.0 for p in progress) and max(progress) > 0.0
    assert all(s.level == b'\x00' for s in ours)  # OK: the file is complete


def test_truncated_file_replays_its_readable_part(ros: Ros, tmp_path: Path) -> None:
    path = synthetic(tmp_path / 'long.mcap', count=500, chunk_size=600)
    data = path.read_bytes()
    path.write_bytes(data[:int(len(data) * 0.6)])  # a copy cut short: no summary, no footer
    # a queue for every message: on a loaded machine the replay's catch-up bursts outrun
    # this executor's subscription callbacks
    counter = ros.listen(Float64, '/counter', 1000)
    reports = ros.listen(DiagnosticArray, '/diagnostics')
    node = ros.replay(path=str(path), rate=20.0, delay=0.5, progress_period=0.1)
    assert ros.spin_until(lambda: node.done.done(), 30.0)
    ros.spin_until(lambda: len(counter) == node.published, 5.0)
    got = values(counter)
    assert 100 < len(got) < 400
    assert got == [float(i) for i in range(len(got))]  # the readable beginning, in order
    ours = [s for _, m in reports for s in m.status if s.name.endswith(': replay')]
    assert ours and all(s.level == b'\x01' for s in ours)  # WARN: damaged file
    assert 'damaged' in ours[-1].message


def test_runner_recording_replays_with_the_recorded_types_and_qos(
        ros: Ros, tmp_path: Path) -> None:
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text('duration: 0.5\nrotation: [[0.0, 0.0], [0.2, -10.0]]\n'
                        'particles:\n  - {position: [0.11, -0.01, 0.03]}\n'
                        '  - {position: [0.14, 0.06, 0.03]}\n')
    path = tmp_path / 'run.mcap'
    assert cli_main(['run', str(scenario), '--events', str(tmp_path / 'e.csv'), '--quiet',
                     '--mcap', str(path)]) == 0
    states = ros.listen(PointCloud2, '/particle_states')
    node = ros.replay(path=str(path), rate=5.0, delay=0.5)
    assert ros.spin_until(lambda: node.done.done(), 30.0)
    ros.spin_until(lambda: len(states) == 50, 5.0)
    assert len(states) == 50  # one per output interval of 10 ms
    # the latched markers reach a subscriber that joins after the replay
    markers = ros.listen(MarkerArray, '/markers', QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    assert ros.spin_until(lambda: bool(markers), 10.0)
    # what arrives is what was recorded (rclpy's own deserialization of the file's bytes)
    with path.open('rb') as stream:
        recorded = [deserialize_message(m.data, PointCloud2) for _, _, m in
                    mcap.reader.make_reader(stream).iter_messages(topics=['/particle_states'])]
    assert [m for _, m in states] == recorded
    assert states[0][1].width == 2 and states[0][1].point_step == 32


def run_replay(tmp_path: Path, *params: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([str(ROOT)] + (
        [env['PYTHONPATH']] if env.get('PYTHONPATH') else []))
    env['ROS_DOMAIN_ID'] = str(sim_process.random_domain())
    args = [sys.executable, '-m', 'cone_feeder_sim.ros.replay_node', '--ros-args']
    for param in params:
        args += ['-p', param]
    return subprocess.run(args, env=env, cwd=tmp_path, capture_output=True, text=True,
                          timeout=120)


def test_process_exit_status_and_errors(tmp_path: Path) -> None:
    good = synthetic(tmp_path / 'counter.mcap')
    done = run_replay(tmp_path, f'path:={good}', 'rate:=10.0')
    assert done.returncode == 0, done.stderr
    assert f'replay of {good} finished: {COUNT} messages' in done.stdout + done.stderr
    garbage = tmp_path / 'garbage.mcap'
    garbage.write_bytes(b'this is not an MCAP file at all')
    bad = run_replay(tmp_path, f'path:={garbage}')
    assert bad.returncode == 1
    assert 'cannot replay' in bad.stderr and 'is not an MCAP file' in bad.stderr
    missing = run_replay(tmp_path)
    assert missing.returncode == 1 and 'parameter path is required' in missing.stderr
    late = run_replay(tmp_path, f'path:={good}', 'start_offset:=5.0')
    assert late.returncode == 1 and 'past the end of the recording' in late.stderr


@pytest.mark.parametrize('how', ['first file', 'directory', 'list'])
def test_a_split_run_is_replayed_whole(ros: Ros, tmp_path: Path, how: str) -> None:
    folder = tmp_path / 'split'
    recorder = RunRecorder(folder / 'run.mcap', [('/counter', 'std_msgs/msg/Float64',
                                                  QosProfile(depth=100))],
                           {'cone_feeder_sim': {}},
                           limits=RecordingLimits(max_file_duration_ns=300_000_000))
    for i in range(COUNT):
        recorder.write('/counter', 'std_msgs/msg/Float64',
                       encode('std_msgs/msg/Float64', {'data': float(i)}),
                       FIRST_NS + i * STEP_NS)
    recorder.close(end_metadata={})
    assert len(recorder.paths) >= 3
    source = {'first file': str(recorder.path), 'directory': str(folder),
              'list': ','.join(str(p) for p in recorder.paths)}[how]
    counter = ros.listen(Float64, '/counter')
    node = ros.replay(path=source, rate=4.0, delay=0.5)
    assert ros.spin_until(lambda: node.done.done(), 30.0)
    ros.spin_until(lambda: len(counter) == COUNT, 5.0)
    assert values(counter) == [float(i) for i in range(COUNT)]
