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

"""`cone-feeder-sim run` as a real process: a signal after the first exits keeps them."""

import csv
from pathlib import Path
import signal
import subprocess
import sys
import time

from cone_feeder_sim.formats.events_csv import EVENT_COLUMNS
from cone_feeder_sim.formats.runlog import END_METADATA_NAME
import mcap.reader
import pytest

# Two pieces thrown over the rim leave in the first output interval; two rest on the still
# cone for ever, so the run (1e6 s at 0.01 s intervals) ends only by the signal.
SCENARIO = """\
duration: 1000000.0
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


@pytest.mark.parametrize('signum', [signal.SIGTERM, signal.SIGINT])
def test_signal_after_the_first_exits_keeps_them(tmp_path: Path, signum: signal.Signals) -> None:
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text(SCENARIO)
    events = tmp_path / 'events.csv'
    run_mcap = tmp_path / 'run.mcap'
    log_path = tmp_path / 'run.log'
    with log_path.open('wb') as log:
        proc = subprocess.Popen(
            [sys.executable, '-m', 'cone_feeder_sim.cli', 'run', str(scenario),
             '--events', str(events), '--mcap', str(run_mcap)],
            stdout=log, stderr=subprocess.STDOUT, preexec_fn=default_sigint)
    try:
        deadline = time.monotonic() + FIRST_ROW_TIMEOUT
        seen = read_rows(events)
        while len(seen) < 2:
            assert proc.poll() is None, log_path.read_text()
            assert time.monotonic() < deadline, 'no exit row in time:\n' + log_path.read_text()
            time.sleep(0.05)
            seen = read_rows(events)
        proc.send_signal(signum)
        code = proc.wait(END_TIMEOUT)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    log = log_path.read_text()
    assert code == 128 + signum, log
    assert f'interrupted by {signum.name} at t = ' in log
    t_end = float(log.split('at t = ')[1].split()[0])
    assert t_end < 1.0e6
    # the CSV: the header and the rows seen before the signal, in exit-time order
    rows = read_rows(events)
    assert events.read_bytes().endswith(b'\r\n')  # no half-written row
    assert tuple(rows[0]) == EVENT_COLUMNS and rows[:len(seen)] == seen
    assert sorted(int(r[0]) for r in rows[1:]) == [0, 1]
    assert f': 2 exits written to {events}, run recorded to {run_mcap}' in log
    assert all(float(r[1]) <= t_end for r in rows[1:])
    # the MCAP: complete (summary, end metadata) and readable to the end
    with run_mcap.open('rb') as stream:
        reader = mcap.reader.make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        topics = [channel.topic for _, channel, _ in reader.iter_messages()]
    assert len(topics) == summary.statistics.message_count
    assert topics.count('/exit_events') >= 1
    assert float(metadata[END_METADATA_NAME]['end_time']) == pytest.approx(t_end, abs=1e-3)
    assert int(metadata[END_METADATA_NAME]['exits']) == 2
