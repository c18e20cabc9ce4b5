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

"""Tests of multiple shooting: windows, start guesses, the Jacobian assembled window by window."""

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from cone_feeder_sim.fit.jacobian import forward_jacobian, forward_steps
from cone_feeder_sim.fit.problem import FitProblem, predict
from cone_feeder_sim.fit.shooting import initial_starts, Shooting, split, STEPS, UNKNOWNS
from cone_feeder_sim.fit.solve import fit
from cone_feeder_sim.fit.spec import fit_from_mapping, FitSpec
from cone_feeder_sim.fit.tracks import Tracks
from cone_feeder_sim.formats.scenario_file import scenario_from_mapping, set_scenario_key
import numpy as np
import pytest
from test_fit import BASE as FIVE_PIECES, FREE, write_tracks

#: Three pieces on a cone that speeds up: 0.6 s.
BASE = {'duration': 0.6, 'rotation': [[0.0, 0.0], [0.4, -6.0]],
        'particles': [{'position': p, 'on_surface': True} for p in (
            [0.11, -0.01, 0.0], [-0.10, -0.01, 0.0], [0.08, -0.13, 0.0])]}


def tracks_of(mapping: dict, rate: float = 30.0) -> Tracks:
    """Return noise-free x, y tracks of the scenario's pieces at ``rate`` frames/s."""
    times = np.arange(0.0, mapping['duration'], 1.0 / rate)
    count = len(mapping['particles'])
    particle = np.tile(np.arange(count), len(times))
    t = np.repeat(times, count)
    xyz = predict(scenario_from_mapping(mapping), Tracks(particle, t, np.zeros((len(t), 3))))
    xyz[:, 2] = np.nan
    return Tracks(particle, t, xyz)


def test_windows_carry_the_pieces_whose_tracks_span_their_start() -> None:
    # piece 0 tracked throughout, piece 1 lost at 0.35 s, piece 2 seen from 0.45 s on
    t = np.array([0.0, 0.1, 0.2, 0.3, 0.35, 0.45, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95])
    particle = np.array([0, 0, 1, 0, 1, 2, 0, 2, 0, 2, 0, 0])
    tracks = Tracks(particle, t, np.zeros((len(t), 3)))
    windows = split(tracks, 4, 0.3)
    np.testing.assert_allclose(windows.edges, [0.0, 0.3, 0.6, 0.95])  # 0.9-0.95 joins
    assert [w.tolist() for w in windows.pieces] == [[0, 1, 2, 3], [0, 1], [0, 2]]
    assert [r.tolist() for r in windows.rows] == [[0, 1, 2], [3, 4, 6], [7, 8, 9, 10, 11]]
    # row 5 (piece 2 at 0.45 s) has no window: its track starts inside one
    assert [g.tolist() for g in windows.gaps] == [[0, 1], [0]]


def test_a_start_is_read_off_a_parabola() -> None:
    t = np.arange(0.0, 1.0, 1.0 / 30.0)
    x, y = 0.1 + 0.2 * t - 0.15 * t * t, -0.05 + 0.3 * t + 0.1 * t * t
    tracks = Tracks(np.zeros(len(t), dtype=np.int64), t, np.column_stack([x, y, 0.0 * t]))
    windows = split(tracks, 1, 0.5)
    scenario = scenario_from_mapping({**BASE, 'particles': BASE['particles'][:1]})
    start = initial_starts(tracks, windows, scenario)[1][0]
    np.testing.assert_allclose(start[:4], [0.1 + 0.1 - 0.0375, -0.05 + 0.15 + 0.025,
                                           0.2 - 0.15, 0.3 + 0.1], atol=1e-9)
    # the filter force holds the piece on its path: tangential, its size m |a| or so
    assert 0.0 < np.hypot(*start[4:]) < 2.0


@pytest.mark.parametrize('contact', [False, True])
def test_the_jacobian_window_by_window_equals_column_by_column(contact: bool) -> None:
    mapping = {**BASE, 'model': {'interactions': {'enabled': contact}}}
    tracks = tracks_of(mapping)
    spec = FitSpec(mapping=mapping, base_dir=None, tracks=tracks, keys=('model.d',),
                   bounds=((10.0, 1000.0),), start=(225.0,))
    windows = split(tracks, 3, 0.2)
    scenario = scenario_from_mapping(mapping)
    with ThreadPoolExecutor(2) as pool:
        shooting = Shooting(spec, windows, lambda v: scenario_from_mapping(
            spec.scenario_mapping(v)), np.exp, scenario, pool.map)
        starts = initial_starts(tracks, windows, scenario)
        z = np.concatenate([[np.log(250.0)], *(b.reshape(-1) for b in starts)])
        theta_steps = forward_steps(z[:1], 1e-3, np.log([10.0]), np.log([1000.0]))
        jac = shooting.jacobian(z, theta_steps)
        steps = np.concatenate([theta_steps, np.tile(STEPS, (len(z) - 1) // UNKNOWNS)])
        brute = forward_jacobian(shooting.residuals, z, shooting.residuals(z), steps)
    assert jac.shape == (shooting.size, len(z)) == brute.shape
    np.testing.assert_allclose(jac, brute, rtol=1e-6, atol=1e-6 * np.abs(brute).max())
    assert np.count_nonzero(jac[:, 1:]) < 0.5 * jac[:, 1:].size  # the windows' blocks


@pytest.mark.slow
def test_multiple_shooting_converges_where_single_shooting_does_not(tmp_path: Path) -> None:
    # five pieces over 3 s, tracked until they leave; the start: d 3x too high, mu_C half
    truth = set_scenario_key(set_scenario_key(FIVE_PIECES, 'model.d', 315.0), 'model.mu_C', 0.7225)
    write_tracks(tmp_path / 'tracks.csv', truth, 30.0, 0.001, 5, lose_exits=True)
    far = set_scenario_key(set_scenario_key(FIVE_PIECES, 'model.d', 1000.0), 'model.mu_C', 0.35)
    content = {'scenario': far, 'tracks': 'tracks.csv', 'free': FREE, 'starts': 1,
               'processes': 1}
    single = fit(FitProblem(fit_from_mapping(content, tmp_path)))
    assert abs(single.estimate[0] - 315.0) > 10.0 * single.stderr[0]  # another valley
    # ... and the test of fit says so, naming pieces that do not fit
    assert not single.success and single.fit_test is not None and single.fit_test.failing
    assert single.warnings[0].startswith('the fit fails its test'), single.warnings
    problem = FitProblem(fit_from_mapping({**content, 'segments': 0.25, 'profiles': False},
                                          tmp_path))
    shooting = fit(problem)
    assert shooting.interval.startswith('Jacobian, 95 %')
    assert problem.window_simulations > 0
    for value, estimate, stderr in zip((315.0, 0.7225), shooting.estimate, shooting.stderr):
        assert abs(estimate - value) < 2.0 * stderr
