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

"""Tests of ``residual: exits``: exits read, simulated, fitted; bad exits named."""

import csv
from pathlib import Path

from cone_feeder_sim.cli import main
from cone_feeder_sim.errors import ScenarioError
from cone_feeder_sim.fit.exits import Exits, read_exits_csv, simulate_exits, wrap_degrees
from cone_feeder_sim.fit.problem import FitProblem
from cone_feeder_sim.fit.solve import fit
from cone_feeder_sim.fit.spec import fit_from_mapping, load_fit
from cone_feeder_sim.formats.scenario_file import scenario_from_mapping, set_scenario_key
import numpy as np
import pytest
import yaml

#: Five pieces lying on the cone, clockwise: 1.5 s (three leave at -8 rad/s).
BASE = {'duration': 1.5, 'rotation': [[0.0, 0.0], [0.5, -8.0]],
        'particles': [{'position': p, 'on_surface': True} for p in (
            [0.11, -0.01, 0.0], [-0.10, -0.01, 0.0], [0.08, -0.13, 0.0], [-0.07, 0.04, 0.0],
            [0.14, 0.06, 0.0])]}
FREE = {'rotation.1.omega': [-10.0, -6.0]}


def test_the_events_of_a_run_are_exits_and_give_back_its_speed(tmp_path: Path) -> None:
    truth = set_scenario_key(BASE, 'rotation.1.1', -7.5)
    (tmp_path / 'truth.yaml').write_text(yaml.safe_dump(truth))
    assert main(['run', str(tmp_path / 'truth.yaml'), '--events', str(tmp_path / 'e.csv'),
                 '--quiet']) == 0
    exits = read_exits_csv(tmp_path / 'e.csv')
    angle, t = simulate_exits(scenario_from_mapping(truth))
    assert len(exits) >= 2
    # the runner stops every 0.01 s, simulate_exits every 0.1 s: the solver's tolerance
    np.testing.assert_allclose(exits.angle_deg, angle[exits.particle], atol=0.01)
    np.testing.assert_allclose(exits.t, t[exits.particle], atol=1e-4)
    spec = fit_from_mapping({'scenario': BASE, 'tracks': 'e.csv', 'residual': 'exits',
                             'free': FREE}, tmp_path)
    assert spec.start == (-8.0,) and len(spec.tracks) == 0
    result = fit(FitProblem(spec))
    assert result.estimate[0] == pytest.approx(-7.5, abs=1e-3)  # no noise: the truth
    assert set(result.piece_rms) == set(exits.particle.tolist())


def test_angles_alone_with_their_sigma(tmp_path: Path) -> None:
    truth = set_scenario_key(BASE, 'rotation.1.1', -7.5)
    angle, _ = simulate_exits(scenario_from_mapping(truth))
    rng = np.random.default_rng(0)
    with (tmp_path / 'exits.csv').open('w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(['particle', 't', 'angle_deg'])
        writer.writerows((p, '', angle[p] + rng.normal(0.0, 2.0)) for p in (0, 2, 4))
    spec = fit_from_mapping({'scenario': BASE, 'tracks': 'exits.csv', 'residual': 'exits',
                             'exit_sigma': {'angle_deg': 2.0}, 'free': FREE}, tmp_path)
    assert np.isnan(spec.exits.t).all() and spec.exit_sigma == (2.0, 0.02)
    result = fit(FitProblem(spec))
    assert abs(result.estimate[0] + 7.5) < 3.0 * result.stderr[0]
    assert 0.0 < result.stderr[0] < 0.2


def test_exit_residuals_by_hand() -> None:
    # piece 0 left at 350 deg at 1.0 s; piece 1 left at 10 deg, time unknown; piece 2 stayed
    exits = Exits(np.array([0, 1, 2]), np.array([350.0, 10.0, np.nan]),
                  np.array([1.0, np.nan, np.nan]))
    angle = np.array([5.0, 20.0, 100.0])  # simulated: 0 at 5 deg, 1 at 20 deg
    t = np.array([1.5, 2.0, 2.5])  # and 2 left at 2.5 s of a 3-s run
    residuals, owner = exits.residuals(angle, t, 3.0, (2.0, 0.1))
    np.testing.assert_allclose(residuals, [15.0 / 2.0, 10.0 / 2.0, 0.5 / 0.1, 0.5 / 0.1])
    assert owner.tolist() == [0, 1, 0, 2]
    t[2] = 3.0  # it stayed too
    assert exits.residuals(angle, t, 3.0, (2.0, 0.1))[0][3] == 0.0


def test_a_piece_that_stayed_is_data(tmp_path: Path) -> None:
    truth = set_scenario_key(BASE, 'rotation.1.1', -7.5)
    angle, t = simulate_exits(scenario_from_mapping(truth))
    stayed = np.flatnonzero(t >= BASE['duration'])
    assert len(stayed) >= 1
    rows = [f'{p},{float(angle[p])!r}' if p not in stayed else f'{p},' for p in range(5)]
    (tmp_path / 'exits.csv').write_text('particle,angle_deg\n' + '\n'.join(rows) + '\n')
    spec = fit_from_mapping({'scenario': BASE, 'tracks': 'exits.csv', 'residual': 'exits',
                             'free': FREE}, tmp_path)
    assert np.isnan(spec.exits.angle_deg[stayed]).all()
    problem = FitProblem(spec)
    assert np.abs(problem.residuals(np.array([-7.5]))).max() < 0.01  # the truth fits
    # at -10 rad/s the pieces that stayed leave: their residuals say how early
    assert problem.residuals(np.array([-10.0]))[-len(stayed):].min() > 1.0


def test_angles_wrap() -> None:
    np.testing.assert_allclose(wrap_degrees([359.0 - 1.0, 1.0 - 359.0, 180.0, -180.0]),
                               [-2.0, 2.0, -180.0, -180.0])


@pytest.mark.parametrize('rows, change, fragment', [
    ('particle,t\n0,0.5\n', {}, 'the exits need the columns particle, angle_deg'),
    ('particle,angle_deg\n0,10\n0,20\n', {}, 'particle(s) 0 leave more than once'),
    ('particle,angle_deg\n9,10\n', {}, 'particle(s) 9 are not in the scenario'),
    ('particle,t,angle_deg\n0,7.0,10\n', {}, 'exit times must lie in [0, duration = 1.5 s]'),
    ('particle,angle_deg\n0,abc\n', {}, 'line 2'),
    ('particle,t,angle_deg\n0,0.5,\n', {}, 'a piece that stayed (no angle_deg) has no exit'),
    ('particle,angle_deg\n0,10\n', {'segments': 0.5}, 'segments (multiple shooting) needs'),
    ('particle,angle_deg\n0,10\n', {'exit_sigma': {'angle_deg': 0.0}},
     'exit_sigma.angle_deg must be a positive number'),
    ('particle,angle_deg\n0,10\n', {'exit_sigma': {'time': 1.0}},
     "unknown exit_sigma key(s) 'time'"),
])
def test_bad_exits_are_refused(tmp_path: Path, rows: str, change: dict, fragment: str) -> None:
    (tmp_path / 'exits.csv').write_text(rows)
    with pytest.raises(ScenarioError) as info:
        fit_from_mapping({'scenario': BASE, 'tracks': 'exits.csv', 'residual': 'exits',
                          'free': FREE, **change}, tmp_path)
    assert fragment in str(info.value)


def test_a_fit_file_given_by_a_relative_path_finds_the_parameter_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = tmp_path / 'config'
    folder.mkdir()
    (folder / 'table.yaml').write_text(yaml.safe_dump({'mu_C': 0.8}))
    (folder / 'base.yaml').write_text(yaml.safe_dump({**BASE, 'parameters': 'table.yaml'}))
    (folder / 'exits.csv').write_text('particle,angle_deg\n0,10\n')
    (folder / 'fit.yaml').write_text(yaml.safe_dump({
        'scenario': 'base.yaml', 'tracks': 'exits.csv', 'residual': 'exits', 'free': FREE}))
    monkeypatch.chdir(tmp_path)
    spec = load_fit('config/fit.yaml')
    assert FitProblem(spec).scenario(np.array(spec.start)).model.product.mu_C == 0.8
