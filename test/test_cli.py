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

"""Tests of the command line and of the runner and the events CSV it writes."""

import contextlib
import csv
import io
import os
from pathlib import Path
import signal

from cone_feeder_sim.cli import main, ProgressBar, StopOnSignals
from cone_feeder_sim.feeder.runner import run_scenario
from cone_feeder_sim.formats import run_files
from cone_feeder_sim.formats.events_csv import EVENT_COLUMNS, EventsCsvWriter
from cone_feeder_sim.formats.mcap_writer import McapRecorder
from cone_feeder_sim.formats.scenario_file import scenario_from_mapping
from cone_feeder_sim.physics.simulation import ExitEvents
import mcap.reader
import numpy as np
import pytest

SCENARIO = """\
duration: 3.0
rotation: [[0.0, 0.0], [0.4, -10.47]]
particles:
  - {position: [0.11, -0.01, 0.03], d: 225.0}
  - {position: [0.14, 0.06, 0.03], d: 30.0}
  - {position: [0.02, 0.0, 0.0], on_surface: true}
"""


def test_run_writes_one_row_per_exit(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text(SCENARIO)
    events = tmp_path / 'events.csv'
    assert main(['run', str(scenario), '--events', str(events)]) == 0
    with events.open() as stream:
        rows = list(csv.DictReader(stream))
    assert tuple(rows[0].keys()) == EVENT_COLUMNS
    assert sorted(int(r['particle']) for r in rows) == [0, 1]  # the piece near the tip stays
    for row in rows:
        angle = float(row['angle_deg'])
        assert 0.0 <= angle < 360.0
        assert np.hypot(float(row['x']), float(row['y'])) == pytest.approx(0.225, abs=1e-6)
        assert np.degrees(np.arctan2(float(row['y']), float(row['x']))) % 360 == (
            pytest.approx(angle))
        assert 1 <= int(row['channel']) <= 14
    times = [float(r['t']) for r in rows]
    assert times == sorted(times)
    err = capsys.readouterr().err
    assert '2 of 3 pieces left the cone; 1 still on it' in err
    assert '100.0%' in err  # the progress bar reached the end


def test_run_with_a_feed_and_no_particles(tmp_path: Path,
                                          capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / 'fed.yaml'
    scenario.write_text('duration: 1.5\nrotation: [[0.0, -10.47]]\n'
                        'feed: {rate: 30.0, seed: 4}\n')
    events = tmp_path / 'events.csv'
    mcap_path = tmp_path / 'fed.mcap'
    assert main(['run', str(scenario), '--events', str(events), '--mcap', str(mcap_path),
                 '--quiet']) == 0
    with events.open() as stream:
        rows = list(csv.DictReader(stream))
    result = run_scenario(scenario_from_mapping(
        {'duration': 1.5, 'rotation': [[0.0, -10.47]], 'feed': {'rate': 30.0, 'seed': 4}}))
    assert len(rows) == result.exit_table()['ids'].size > 0
    err = capsys.readouterr().err
    assert f'{len(rows)} of {result.pieces} pieces left the cone' in err
    with mcap_path.open('rb') as stream:
        metadata = next(m for m in mcap.reader.make_reader(stream).iter_metadata()
                        if m.name == 'cone_feeder_sim').metadata
    assert (metadata['feed.rate'], metadata['feed.seed'], metadata['seed']) == ('30.0', '4', '4')


def test_packs_csv_of_a_scenario_with_a_weigher(tmp_path: Path,
                                                capsys: pytest.CaptureFixture) -> None:
    from cone_feeder_sim.formats.packs_csv import PACK_COLUMNS
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text(SCENARIO.replace('duration: 3.0', 'duration: 8.0') + (
        'weigher: {target: 0.1, transport_time: 1.0, load_cell_noise: 0.0}\n'))
    events, packs = tmp_path / 'events.csv', tmp_path / 'packs.csv'
    mcap = tmp_path / 'run.mcap'
    assert main(['run', str(scenario), '--events', str(events), '--packs', str(packs),
                 '--mcap', str(mcap)]) == 0
    with events.open() as stream:
        exits = list(csv.DictReader(stream))
    with packs.open() as stream:
        rows = list(csv.DictReader(stream))
    assert tuple(rows[0].keys()) == PACK_COLUMNS
    # the two pieces that left (0.125 kg each, target 0.1 kg) make two one-head packs,
    # each from the channel its piece fell into, after transport, gate and settling
    assert [int(r['pack']) for r in rows] == [1, 2]
    assert sorted(r['heads'] for r in rows) == sorted(e['channel'] for e in exits)
    for row in rows:
        assert float(row['mass']) == 0.125 == float(row['measured'])
        assert float(row['giveaway']) == pytest.approx(0.025)
        exit_t = min(float(e['t']) for e in exits if e['channel'] == row['heads'])
        assert float(row['t']) >= exit_t + 1.0 + 0.3 + 0.4  # transport, gate, settle
    assert '2 packs written' in capsys.readouterr().err
    # the recording carries the weigher, and the report draws it
    from cone_feeder_sim.report.draw import write_report
    run = write_report(mcap, tmp_path / 'report.png')
    assert run.packs is not None and len(run.packs.t) == 2
    np.testing.assert_array_equal(run.packs.mass, [float(r['mass']) for r in rows])
    assert run.hoppers.weight.shape[1] == 14 and run.hoppers.t[-1] == pytest.approx(8.0)
    assert run.metadata['weigher.enabled'] == 'true' and run.contact() == 'off'
    # without a weigher: section, --packs is refused before anything runs
    scenario.write_text(SCENARIO)
    assert main(['run', str(scenario), '--events', str(events), '--packs', str(packs)]) == 2
    assert 'weigher: section' in capsys.readouterr().err


def test_bad_scenario_fails_before_running(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text(SCENARIO.replace('d: 30.0', 'd: -30.0'))
    events = tmp_path / 'events.csv'
    assert main(['run', str(scenario), '--events', str(events), '--quiet']) == 2
    assert "parameter 'd' = -30 is out of range" in capsys.readouterr().err
    assert not events.exists()


def test_a_run_of_too_many_outputs_is_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text(SCENARIO + 'output_interval: 1.0e-12\n')
    events = tmp_path / 'events.csv'
    assert main(['run', str(scenario), '--events', str(events), '--quiet']) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'output_interval: 1e-12 s' in err and 'outputs' in err
    assert not events.exists()


def test_unwritable_events_file(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text(SCENARIO)
    code = main(['run', str(scenario), '--events', str(tmp_path / 'no' / 'e.csv')])
    err = capsys.readouterr().err
    assert code == 2 and 'cannot write events' in err
    assert '%' not in err  # refused before the run started


def test_runner_matches_the_simulator_and_stops_when_empty() -> None:
    sc = scenario_from_mapping({'duration': 10.0, 'rotation': [[0.0, 0.0], [0.4, -10.47]],
                                'particles': [{'position': [0.11, -0.01, 0.03]}]})
    seen = []
    result = run_scenario(sc, lambda t, sim, step: seen.append(t))
    table = result.exit_table()
    assert table['ids'].tolist() == [0]
    assert seen[-1] < 10.0  # stopped once the only piece had left
    assert result.accepted_steps > 0 and result.remaining_ids.size == 0


def test_runner_stops_between_intervals_when_asked() -> None:
    sc = scenario_from_mapping({'duration': 10.0, 'rotation': [[0.0, 0.0], [0.4, -10.47]],
                                'output_interval': 0.05,
                                'particles': [{'position': [0.11, -0.01, 0.03]}]})
    seen: list[float] = []
    result = run_scenario(sc, lambda t, sim, step: seen.append(t), stop=lambda: len(seen) == 3)
    assert result.stopped and len(seen) == 3
    assert result.end_time == pytest.approx(0.15) == seen[-1]
    assert result.remaining_ids.tolist() == [0]
    done = run_scenario(sc, stop=lambda: False)
    assert not done.stopped and done.end_time < 10.0 and done.remaining_ids.size == 0


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_signal_ends_the_run_after_the_interval(
        tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch,
        signum: signal.Signals) -> None:
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text(SCENARIO)
    events = tmp_path / 'events.csv'
    run_mcap = tmp_path / 'run.mcap'

    class SignalAfterFirstExit(EventsCsvWriter):

        def write(self, exits: ExitEvents) -> int:
            count = super().write(exits)
            if count:
                os.kill(os.getpid(), signum)  # handled at once, in this thread
            return count

    monkeypatch.setattr(run_files, 'EventsCsvWriter', SignalAfterFirstExit)
    ignored = signal.getsignal(signum) == signal.SIG_IGN
    if ignored:
        # a background job of a non-interactive shell ignores SIGINT, and the run rightly
        # keeps ignoring it there; this test is about a signal the process listens to
        signal.signal(signum, signal.default_int_handler)
    try:
        before = signal.getsignal(signum)
        code = main(['run', str(scenario), '--events', str(events), '--mcap', str(run_mcap),
                     '--quiet'])
        after = signal.getsignal(signum)
    finally:
        if ignored:
            signal.signal(signum, signal.SIG_IGN)
    assert code == 128 + signum
    assert after == before  # restored
    err = capsys.readouterr().err
    assert f'interrupted by {signum.name} at t = ' in err
    with events.open() as stream:
        rows = list(csv.DictReader(stream))
    assert len(rows) == 1 and int(rows[0]['particle']) == 1  # piece 0 leaves later
    assert f': 1 exits written to {events}, run recorded to {run_mcap}' in err
    t_end = float(err.split('at t = ')[1].split()[0])
    assert float(rows[0]['t']) <= t_end < 3.0
    with run_mcap.open('rb') as stream:
        reader = mcap.reader.make_reader(stream)
        summary = reader.get_summary()
        end = {m.name: dict(m.metadata) for m in reader.iter_metadata()}['cone_feeder_sim.end']
    assert summary is not None and summary.statistics.message_count > 0
    assert float(end['end_time']) == pytest.approx(t_end, abs=1e-3)


def test_stop_on_signals_leaves_an_ignored_signal_ignored() -> None:
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with StopOnSignals() as stop:
            assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN
            assert signal.getsignal(signal.SIGTERM) == stop._handle
        assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN
        assert not stop()
    finally:
        signal.signal(signal.SIGINT, previous)


class FakeStep:
    """What the progress bar reads of a step result."""

    exits = ()


class FakeSim:
    """What the progress bar reads of a simulator."""

    class state:  # noqa: N801 - mimics Simulator.state
        count = 3


def test_progress_bar_on_a_terminal_ends_its_line() -> None:
    class Terminal(io.StringIO):

        def isatty(self) -> bool:
            return True

    stream = Terminal()
    bar = ProgressBar(1.0, stream)

    bar(0.5, FakeSim(), FakeStep())  # type: ignore[arg-type]
    assert stream.getvalue().startswith('\r[') and not stream.getvalue().endswith('\n')
    bar.end()
    bar.end()
    assert stream.getvalue().endswith('\n') and stream.getvalue().count('\n') == 1  # once


def test_progress_bar_on_a_pipe_prints_every_tenth() -> None:
    stream = io.StringIO()
    bar = ProgressBar(1.0, stream)

    for k in range(1, 101):
        bar(k / 100.0, FakeSim(), FakeStep())  # type: ignore[arg-type]
    lines = stream.getvalue().splitlines()
    assert len(lines) == 11 and lines[-1].startswith('[' + '#' * 30 + ']')


def test_recover_makes_a_complete_file_of_an_unfinished_one(tmp_path: Path) -> None:
    source = tmp_path / 'run.mcap'
    with McapRecorder(source, chunk_size=200) as recorder:
        for i in range(500):
            recorder.write('/n', 'std_msgs/msg/Float64', {'data': float(i)}, i * 1000)
    raw = source.read_bytes()
    source.write_bytes(raw[:len(raw) // 2])  # cut off, as after a SIGKILL
    out = tmp_path / 'recovered.mcap'
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(['recover', str(source), str(out)]) == 0
    count = int(err.getvalue().split()[1])
    assert 0 < count < 500
    with out.open('rb') as stream:
        reader = mcap.reader.make_reader(stream)
        assert reader.get_summary().statistics.message_count == count
        assert [m.log_time for _, _, m in reader.iter_messages()] == [
            i * 1000 for i in range(count)]
    with contextlib.redirect_stderr(io.StringIO()):
        assert main(['recover', str(out), str(out)]) == 2
        assert main(['recover', str(tmp_path / 'missing.mcap'), str(out)]) == 2


def test_compile_loads_or_compiles_the_kernel() -> None:
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(['compile']) == 0
    # the tests' kernels live in the package's __pycache__ (or the user's cache directory,
    # where the line says so)
    line = err.getvalue()
    assert line.startswith('numba kernels ') and '(cache: ' in line, line
    assert ('/cone_feeder_sim/' in line) != ("outside the package's folder" in line), line
