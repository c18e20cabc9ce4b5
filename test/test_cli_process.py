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

"""`cone-feeder-sim run` as a real process: a signal ends it at once, keeping what it wrote."""

import csv
from pathlib import Path
import signal
import subprocess
import sys
import time

from cone_feeder_sim.formats.events_csv import EVENT_COLUMNS
from cone_feeder_sim.formats.runlog import END_METADATA_NAME
from crowds import crowd_in_layers
import mcap.reader
import pytest

# Two pieces thrown over the rim leave in the first output interval; two rest on the still
# cone for ever, so the run (1e4 s at 0.01 s intervals: the most outputs a run may ask for)
# ends only by the signal.
SCENARIO = """\
duration: 10000.0
rotation: [[0.0, 0.0]]
particles:
  - {position: [0.215, 0.0, 0.0], velocity: [1.0, 0.0, 0.0], on_surface: true}
  - {position: [0.0, 0.215, 0.0], velocity: [0.0, 1.0, 0.0], on_surface: true}
  - {position: [0.1, 0.0, 0.0], on_surface: true}
  - {position: [0.0, -0.1, 0.0], on_surface: true}
"""
#: Generous wait for the first row: a fresh process imports numpy and numba and loads (or,
#: on the first run, compiles) the kernels.
FIRST_ROW_TIMEOUT = 120.0
#: Generous wait for the end after the signal (one interval, then closing the files).
END_TIMEOUT = 60.0


def read_rows(path: Path) -> list[list[str]]:
    """Return the complete lines of a CSV written by another process, parsed."""
    if not path.exists():
        return []
    text = path.read_bytes().decode('utf-8')
    return list(csv.reader(text[:text.rfind('\n') + 1].splitlines()))


def default_sigint() -> None:
    """Let the child see SIGINT even where the test runner's parent ignores it."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


class Run:
    """``cone-feeder-sim run`` of a scenario in a process of its own, its files in tmp_path."""

    def __init__(self, tmp_path: Path, scenario_text: str) -> None:
        """Start the run (events CSV and MCAP recording), SIGINT not ignored."""
        scenario = tmp_path / 'scenario.yaml'
        scenario.write_text(scenario_text)
        self.events = tmp_path / 'events.csv'
        self.mcap = tmp_path / 'run.mcap'
        self.log_path = tmp_path / 'run.log'
        with self.log_path.open('wb') as log:
            self.proc = subprocess.Popen(
                [sys.executable, '-m', 'cone_feeder_sim.cli', 'run', str(scenario),
                 '--events', str(self.events), '--mcap', str(self.mcap)],
                stdout=log, stderr=subprocess.STDOUT, preexec_fn=default_sigint)

    def rows(self, count: int) -> list[list[str]]:
        """Wait until the CSV holds count rows, the header included; return them."""
        deadline = time.monotonic() + FIRST_ROW_TIMEOUT
        while len(seen := read_rows(self.events)) < count:
            assert self.proc.poll() is None, self.log()
            assert time.monotonic() < deadline, 'no rows in time:\n' + self.log()
            time.sleep(0.05)
        return seen

    def stop(self, signum: signal.Signals, timeout: float) -> tuple[int, float]:
        """Send the signal; return the exit status and the seconds it took to come."""
        sent = time.monotonic()
        self.proc.send_signal(signum)
        return self.proc.wait(timeout), time.monotonic() - sent

    def log(self) -> str:
        """Return what the run printed."""
        return self.log_path.read_text()

    def recording(self) -> tuple[list[str], dict[str, dict[str, str]]]:
        """Return the topics of the MCAP file's messages and its metadata; check it whole."""
        with self.mcap.open('rb') as stream:
            reader = mcap.reader.make_reader(stream)
            summary = reader.get_summary()
            assert summary is not None and summary.statistics is not None
            metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
            topics = [channel.topic for _, channel, _ in reader.iter_messages()]
        assert len(topics) == summary.statistics.message_count
        return topics, metadata

    def close(self) -> None:
        """Kill the process if it still runs."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


@pytest.mark.parametrize('signum', [signal.SIGTERM, signal.SIGINT])
def test_signal_after_the_first_exits_keeps_them(tmp_path: Path, signum: signal.Signals) -> None:
    run = Run(tmp_path, SCENARIO)
    try:
        seen = run.rows(3)  # the header and the two thrown pieces
        code, _ = run.stop(signum, END_TIMEOUT)
    finally:
        run.close()
    log = run.log()
    assert code == 128 + signum, log
    assert f'interrupted by {signum.name} at t = ' in log
    t_end = float(log.split('at t = ')[1].split()[0])
    assert t_end < 1.0e4
    # the CSV: the header and the rows seen before the signal, in exit-time order
    rows = read_rows(run.events)
    assert run.events.read_bytes().endswith(b'\r\n')  # no half-written row
    assert tuple(rows[0]) == EVENT_COLUMNS and rows[:len(seen)] == seen
    assert sorted(int(r[0]) for r in rows[1:]) == [0, 1]
    assert f': 2 exits written to {run.events}, run recorded to {run.mcap}' in log
    assert all(float(r[1]) <= t_end for r in rows[1:])
    # the MCAP: complete (summary, end metadata) and readable to the end
    topics, metadata = run.recording()
    assert topics.count('/exit_events') >= 1
    assert float(metadata[END_METADATA_NAME]['end_time']) == pytest.approx(t_end, abs=1e-3)
    assert int(metadata[END_METADATA_NAME]['exits']) == 2


def crowd_scenario() -> str:
    """Return a scenario of 70 pieces in two layers, one island, coupled exactly."""
    positions = crowd_in_layers(2, lift=0.0)
    pieces = ''.join(f'  - {{position: [{x:.17g}, {y:.17g}, {z:.17g}]}}\n'
                     for x, y, z in positions)
    return ('duration: 10.0\noutput_interval: 0.01\nrotation: [[0.0, -5.0]]\n'
            'interactions: {enabled: true, coupling: exact}\n'
            f'solver: {{h_max: 1.0e-8, max_steps: 1000000000000}}\nparticles:\n{pieces}')


#: Runs whose first output interval would compute for far longer than any test waits: no
#: step may exceed h_max = 1e-8 s, so the four pieces alone take 1e8 steps each in their one
#: 1-s interval (minutes each), and the island of 70 a million steps of its 700+ unknowns in
#: the first 0.01 s.
LONG_RUNS = {
    'alone': ('duration: 1.0\noutput_interval: 1.0\nrotation: [[0.0, -5.0]]\n'
              'solver: {h_max: 1.0e-8, max_steps: 1000000000000}\n'
              + SCENARIO.split('\n', 2)[2]),
    'crowd-exact': crowd_scenario(),
}
#: How long a stopped run may take to end: generous (closing the files included, on a
#: loaded machine); the interval it stops would take minutes to hours.
STOP_TIMEOUT = 30.0


@pytest.mark.parametrize('signum', [signal.SIGTERM, signal.SIGINT])
@pytest.mark.parametrize('case', sorted(LONG_RUNS))
def test_a_signal_stops_a_long_interval_within_a_step(
        tmp_path: Path, case: str, signum: signal.Signals) -> None:
    # the kernels read the stop flag between steps: the run ends without finishing the
    # interval, with its files complete (the events CSV: its header; the MCAP: readable)
    run = Run(tmp_path, LONG_RUNS[case])
    try:
        run.rows(1)  # the header: the files are open, the run starts
        time.sleep(0.5)  # into the interval (a signal before it stops the run as well)
        code, took = run.stop(signum, STOP_TIMEOUT)
    finally:
        run.close()
    log = run.log()
    assert code == 128 + signum, log
    assert f'interrupted by {signum.name} at t = 0.000 s: 0 exits written' in log, log
    assert took < STOP_TIMEOUT
    assert read_rows(run.events) == [list(EVENT_COLUMNS)]
    _, metadata = run.recording()
    assert float(metadata[END_METADATA_NAME]['end_time']) == 0.0
