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

"""Tests of the events CSV: written interval by interval, the same bytes as a whole run."""

from collections.abc import Mapping
import csv
import io
from pathlib import Path

from cone_feeder_sim.errors import ConeFeederError
from cone_feeder_sim.feeder.runner import run_scenario
from cone_feeder_sim.formats.events_csv import EVENT_COLUMNS, EventsCsvWriter
from cone_feeder_sim.formats.scenario_file import load_scenario
from cone_feeder_sim.physics.simulation import ExitEvents, Simulator, StepResult
import numpy as np
import pytest

CONFIG = Path(__file__).resolve().parents[2] / 'config'


def whole_run_csv(table: Mapping[str, np.ndarray]) -> bytes:
    """Return the documented CSV of a whole run's exit table, as it was written at the end."""
    stream = io.StringIO(newline='')
    writer = csv.writer(stream)
    writer.writerow(EVENT_COLUMNS)
    for i in np.argsort(table['t'], kind='stable'):
        writer.writerow([int(table['ids'][i]), repr(float(table['t'][i])),
                         repr(float(table['angle_deg'][i])), int(table['channel'][i]),
                         *(repr(float(v)) for v in table['position'][i]),
                         *(repr(float(v)) for v in table['velocity'][i]),
                         repr(float(table['mass'][i]))])
    return stream.getvalue().encode('utf-8')


def exits(ids: list[int], times: list[float]) -> ExitEvents:
    """Return exit events of the given ids and times, the other columns derived from them."""
    n = len(ids)
    t = np.array(times)
    return ExitEvents(ids=np.array(ids, dtype=np.int64), t=t, angle_deg=90.0 * t,
                      channel=np.arange(1, n + 1), position=np.outer(t, [1.0, 2.0, 3.0]),
                      velocity=np.outer(t, [-1.0, 0.5, 0.0]), mass=np.full(n, 0.125))


def test_incremental_csv_is_the_whole_run_csv(tmp_path: Path) -> None:
    path = tmp_path / 'events.csv'
    scenario = load_scenario(CONFIG / 'paper_table1.yaml')
    intervals_with_exits = []
    with EventsCsvWriter(path) as events:
        def progress(t: float, sim: Simulator, step: StepResult) -> None:
            if events.write(step.exits):
                intervals_with_exits.append(t)

        result = run_scenario(scenario, progress)
    assert events.closed and events.rows == 5
    assert len(intervals_with_exits) >= 2  # the rows really came in several appends
    assert path.read_bytes() == whole_run_csv(result.exit_table())
    with path.open() as stream:
        rows = list(csv.DictReader(stream))
    assert sorted(int(r['particle']) for r in rows) == [0, 1, 2, 3, 4]  # scenario indices


def test_rows_are_in_the_file_after_each_write(tmp_path: Path) -> None:
    path = tmp_path / 'events.csv'
    with EventsCsvWriter(path) as events:
        assert path.read_bytes() == ','.join(EVENT_COLUMNS).encode() + b'\r\n'  # at open
        assert events.write(exits([4, 2], [0.75, 0.5])) == 2
        lines = path.read_text().splitlines()  # flushed: readable before close
        assert [line.split(',')[:2] for line in lines[1:]] == [['2', '0.5'], ['4', '0.75']]
        assert events.write(exits([], [])) == 0
        assert events.write(exits([7], [1.0])) == 1
        assert events.rows == 3
    events.close()  # idempotent
    text = path.read_bytes()
    assert text == whole_run_csv({
        'ids': np.array([4, 2, 7]), 't': np.array([0.75, 0.5, 1.0]),
        'angle_deg': np.array([67.5, 45.0, 90.0]), 'channel': np.array([1, 2, 1]),
        'position': np.outer([0.75, 0.5, 1.0], [1.0, 2.0, 3.0]),
        'velocity': np.outer([0.75, 0.5, 1.0], [-1.0, 0.5, 0.0]),
        'mass': np.full(3, 0.125)})
    assert text.splitlines()[1] == b'2,0.5,45.0,2,0.5,1.0,1.5,-0.5,0.25,0.0,0.125'


def test_unwritable_path_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(ConeFeederError, match='cannot write events to'):
        EventsCsvWriter(tmp_path / 'missing' / 'events.csv')
