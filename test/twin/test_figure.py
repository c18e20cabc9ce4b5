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
"""The headless twin's report: its scores against a run directory written by hand."""

import csv
from pathlib import Path

from cone_feeder_sim.twin.figure import read_scores, write_report
from cone_feeder_sim.twin.run import FILES
import numpy as np
import pytest


def write(out: Path, rows: dict[str, list[list]]) -> None:
    for name, columns in FILES.items():
        with (out / name).open('w', newline='') as stream:
            writer = csv.writer(stream)
            writer.writerow(columns)
            writer.writerows(rows.get(name, []))


@pytest.fixture()
def run(tmp_path: Path) -> Path:
    # two pieces leave: piece 1 into channel 3 at 1.2 s (0.1 kg), piece 2 into channel 5
    # at 2.9 s (0.2 kg); frames up to 3.0 s
    write(tmp_path, {
        'exits.csv': [[1.2, 1, 3, 0.1], [2.9, 2, 5, 0.2]],
        'pieces.csv': [
            [1.0, 1, 0.1, 0.0, 3, 0.9, 1.21],   # lead 0.2: right
            [0.8, 1, 0.1, 0.0, 4, 0.6, 1.25],   # lead 0.4: wrong
            [0.5, 1, 0.1, 0.0, 3, 0.5, 1.3],    # lead 0.7: right
            [2.0, 2, 0.1, 0.0, 5, 0.7, 2.8],    # lead 0.9: right
            [0.5, 2, 0.1, 0.0, 0, 1.0, ''],     # lead 2.4: past the last bin, not scored
            [1.0, 7, 0.1, 0.0, 2, 1.0, 1.1],    # a piece never seen to leave: not scored
        ],
        'channel_forecast.csv': [
            # at 1.0 s over 0.5 s: 0.08 kg in channel 3 (0.1 came): error 0.02 + 0.01
            [1.0, 0.5, 3, 0.08, 0.01], [1.0, 0.5, 4, 0.01, 0.01],
            # at 1.0 s over 2 s: both exits within; forecast 0.1 in 3, nothing in 5
            [1.0, 2.0, 3, 0.1, 0.0], [1.0, 2.0, 5, 0.0, 0.0],
            # at 2.0 s over 0.5 s: nothing came, 0.05 forecast: error 0.05
            [2.0, 0.5, 5, 0.05, 0.0],
            # at 2.0 s over 2 s: ends past the stream (3.0 s): not scored
            [2.0, 2.0, 5, 0.2, 0.0],
        ],
        'frames.csv': [[t, 2, 2, 0, 0, 0, 4.0, 4] for t in np.arange(0.0, 3.01, 0.5)],
        'parameters.csv': [[t, key, value, 0.1] for t in (1.0, 2.0)
                           for key, value in (('d', 225.0), ('mu_C', 0.85))],
    })
    return tmp_path


def test_the_scores_are_the_hand_computed_ones(run: Path) -> None:
    scores = read_scores(run)
    assert scores.cases.tolist() == [1, 1, 2, 0]
    assert scores.right.tolist() == [1, 0, 2, 0]
    assert scores.horizons.tolist() == [0.5, 2.0]
    assert scores.forecasts.tolist() == [2, 1]
    assert scores.mae == pytest.approx([(0.03 + 0.05) / 2, 0.2])
    assert scores.empty == pytest.approx([(0.1 + 0.0) / 2, 0.3])


def test_the_report_is_one_png_page(run: Path) -> None:
    path = write_report(run)
    assert path == run / 'report.png'
    assert path.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and path.stat().st_size > 20000
