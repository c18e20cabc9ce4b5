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
The twin's estimator following a plant that the test simulates (its truth never shown).

The plant is the physics core itself: five pieces on a cone that speeds up to 6 rad/s and
reverses, seen at 30 frames/s with 1 mm of noise. The twin starts from nothing and gets
the detections and the cone speed only.
"""

from dataclasses import replace
import math

from cone_feeder_sim.physics.params import ModelParams, P_D, P_M
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    add_particles, advance, remove_particles, resting_height, SimParams, SimState,
    world_from_cone)
from cone_feeder_sim.twin.estimator import (
    Exit, EXIT_LAG, Frame, MASS_PRIOR, MISSED_FRAME, parameter_note, STILL, Twin,
    TwinSettings, weighed_values, window_log_likelihood)
from cone_feeder_sim.twin.particles import resample_parameters
import numpy as np
import pytest
from scipy.stats import chi2

MODEL = ModelParams()
PARAMS = SimParams(model=MODEL)
PROFILE = RotationProfile.from_table([[0.0, 0.0], [0.5, 6.0], [1.5, 6.0], [2.0, -6.0]])
PLACES = [[0.10, 0.02], [-0.08, 0.09], [0.03, -0.13], [-0.12, -0.05], [0.20, 0.03]]
SIGMA = 0.001  # m


def follow(twin: Twin, frames: int) -> list[tuple[Frame, int, float]]:
    """Run the plant and the twin; return per frame (the twin's frame, pieces, worst error)."""
    rng = np.random.default_rng(0)
    q = np.array([[x, y, resting_height(MODEL, MODEL.product, x, y)] for x, y in PLACES])
    plant, _ = add_particles(SimState(), PARAMS, q)
    out = []
    for k in range(1, frames + 1):
        t = k / 30.0
        plant = advance(plant, PARAMS, PROFILE, t).state
        twin.cone_speed(t, PROFILE.omega(t))
        seen, _, _ = world_from_cone(plant.y, plant.angle, PROFILE.omega(t))
        frame = twin.update(t, seen[:, :2] + rng.normal(0.0, SIGMA, (plant.count, 2)))
        _, mean, _ = twin.pieces()
        error = np.linalg.norm(mean[:, None, :] - seen[None, :, :2], axis=2).min(axis=1)
        out.append((frame, plant.count, float(error.max()) if len(error) else np.inf))
    return out


@pytest.fixture(scope='module')
def followed() -> tuple[Twin, list[tuple[Frame, int, float]]]:
    twin = Twin(PARAMS, TwinSettings(members=32, sigma=SIGMA, d_spread=0.05,
                                     mu_C_spread=0.01, seed=1))
    return twin, follow(twin, 75)


def test_pieces_are_born_once_and_then_followed(followed: tuple) -> None:
    _, frames = followed
    assert frames[0][0].births == 5  # the first frame: every piece is new
    assert sum(frame.births for frame, _, _ in frames[1:]) == 0
    assert all(frame.associated == count for frame, count, _ in frames[1:])
    # shown once seen in `confirm` frames (2): tentative before
    confirm = TwinSettings().confirm
    assert all(error == np.inf for _, _, error in frames[:confirm - 1])
    assert max(error for _, _, error in frames[confirm - 1:]) < 5.0 * SIGMA


def test_the_innovations_are_consistent_with_the_reported_spread(followed: tuple) -> None:
    # the sum of the frames' NIS is chi-square with the observations' count: inside its
    # two-sided bounds at alpha = 1e-3
    _, frames = followed
    nis = sum(frame.nis for frame, _, _ in frames[1:])
    dof = sum(frame.observed for frame, _, _ in frames[1:])
    assert dof > 500
    assert chi2.ppf(5e-4, dof) < nis < chi2.ppf(1.0 - 5e-4, dof)


def test_a_piece_that_leaves_the_plant_leaves_the_twin(followed: tuple) -> None:
    twin, frames = followed
    left = frames[0][1] - frames[-1][1]
    assert left >= 1  # the cone at 6 rad/s throws the outermost piece off (at 0.77 s)
    assert sum(frame.exits + frame.deaths for frame, _, _ in frames) == left
    assert len(twin.pieces()[0]) == frames[-1][1]


def rim_twin(params: SimParams = PARAMS) -> Twin:
    """Return a twin of two resting pieces, one 15 mm from the rim at angle 0, seen at 0."""
    twin = Twin(params, TwinSettings(members=4, sigma=SIGMA, confirm=1, seed=4))
    twin.cone_speed(0.0, 0.0)
    twin.update(0.0, np.array([[0.21, 0.0], [0.05, 0.05]]))
    return twin


def test_a_measured_exit_takes_the_unseen_piece_at_the_rim_of_its_channel() -> None:
    channel = int(MODEL.channels.channel_of(0.0))  # the rim piece's
    opposite = int(MODEL.channels.channel_of(180.0))
    inner = np.array([[0.05, 0.05]])  # the camera sees the inner piece alone from now on
    # without a measured exit, or with one in the opposite channel, the unseen piece stays
    # (the pieces rest: only death_after, 1 s unseen, would take it)
    for measured in ((), ((0.1, opposite),)):
        twin = rim_twin()
        for when, c in measured:
            twin.measured_exit(when, c)
        frame = twin.update(0.1 + EXIT_LAG, inner)
        assert twin.pieces()[0].tolist() == [0, 1] and frame.left == ()
        assert frame.measured == len(measured) and frame.explained == 0
    # in its channel: it leaves at once, at the measured time
    twin = rim_twin()
    twin.measured_exit(0.1, channel)
    frame = twin.update(0.1 + EXIT_LAG, inner)
    assert twin.pieces()[0].tolist() == [1]
    assert frame.measured == frame.explained == frame.exits == 1
    assert frame.left == (Exit(piece=0, t=0.1, channel=channel, mass=MODEL.product.m),)
    # a piece the camera sees is never taken, however near the rim
    twin = rim_twin()
    twin.measured_exit(0.1, channel)
    frame = twin.update(0.1 + EXIT_LAG, np.array([[0.21, 0.0], [0.05, 0.05]]))
    assert frame.measured == 1 and frame.explained == 0 and len(twin.pieces()[0]) == 2


def test_one_channel_takes_the_rim_piece_wherever_it_is() -> None:
    one = SimParams(model=replace(MODEL, channels=replace(MODEL.channels, count=1)))
    twin = rim_twin(one)
    twin.measured_exit(0.1, 1)
    frame = twin.update(0.1 + EXIT_LAG, np.array([[0.05, 0.05]]))
    assert frame.exits == 1 and twin.pieces()[0].tolist() == [1]


def test_after_a_long_gap_the_twin_s_own_exit_still_explains_the_measured_one() -> None:
    # the twin let the piece leave at 0.5 s, in the channel the sensor measured; the next
    # frame comes 1.15 s later (a camera that stopped): the exit is the twin's own, and no
    # other piece near the rim is taken for it
    channel = int(MODEL.channels.channel_of(0.0))
    twin = rim_twin()
    twin._recent_exits.append((0.5, channel))
    twin.measured_exit(0.5, channel)
    frame = twin.update(1.65, np.array([[0.05, 0.05]]))
    assert frame.measured == frame.explained == 1
    assert frame.exits == 0 and frame.left == ()


def test_in_the_dark_a_measured_exit_takes_the_piece_at_the_rim_of_its_channel() -> None:
    # no frame says which pieces are still there: any is a candidate, the nearest the rim
    # of the channel goes
    twin = rim_twin()
    twin.measured_exit(0.1, int(MODEL.channels.channel_of(180.0)))  # no piece there
    twin.measured_exit(0.15, int(MODEL.channels.channel_of(0.0)))
    twin.predict(0.2)
    assert twin.open_loop_exits() == ()
    assert twin.pieces()[0].tolist() == [0, 1] and len(twin.pending_exits) == 1
    twin.predict(0.25)
    (left,) = twin.open_loop_exits()
    assert left.piece == 0 and left.t == 0.15 and twin.pieces()[0].tolist() == [1]


def test_a_frame_takes_the_exits_measured_up_to_exit_lag_before_it() -> None:
    twin = rim_twin()
    twin.measured_exit(0.2, int(MODEL.channels.channel_of(0.0)))
    inner = np.array([[0.05, 0.05]])
    assert twin.update(0.2 + 0.5 * EXIT_LAG, inner).measured == 0
    assert twin.pending_exits and len(twin.pieces()[0]) == 2
    assert twin.update(0.2 + EXIT_LAG, inner).measured == 1
    assert not twin.pending_exits and twin.pieces()[0].tolist() == [1]


def test_an_exit_the_twin_let_happen_explains_the_measured_one() -> None:
    # the plant's outermost piece leaves at 0.76 s: the twin lets it leave too (at 0.75 s),
    # and the plant's exit, measured, is that exit: it changes nothing
    q = np.array([[x, y, resting_height(MODEL, MODEL.product, x, y)] for x, y in PLACES])
    start, _ = add_particles(SimState(), PARAMS, q)
    runs = []
    for measure in (True, False):
        plant = start
        twin = Twin(PARAMS, TwinSettings(members=4, sigma=SIGMA, d_spread=0.05,
                                         mu_C_spread=0.01, seed=1))
        rng = np.random.default_rng(0)
        frames, measured = [], []
        for k in range(1, 34):
            t = k / 30.0
            result = advance(plant, PARAMS, PROFILE, t)
            plant = result.state
            measured += zip(result.exits.t.tolist(), result.exits.channel.tolist())
            if measure:
                for when, channel in measured[len(measured) - len(result.exits):]:
                    twin.measured_exit(when, channel)
            twin.cone_speed(t, PROFILE.omega(t))
            seen, _, _ = world_from_cone(plant.y, plant.angle, PROFILE.omega(t))
            noise = rng.normal(0.0, SIGMA, (plant.count, 2))
            frames.append(twin.update(t, seen[:, :2] + noise))
        runs.append((twin, frames, measured))
    (twin, frames, measured), (alone, frames_alone, _) = runs
    assert len(measured) == 1
    assert sum(f.measured for f in frames) == 1 and sum(f.explained for f in frames) == 1
    (left,) = [e for f in frames for e in f.left]
    assert left.channel == measured[0][1] and abs(left.t - measured[0][0]) < 0.02
    assert [replace(f, measured=0, explained=0) for f in frames] == frames_alone
    assert np.array_equal(twin.pieces()[1], alone.pieces()[1])


def test_weighed_exits_give_the_mass_of_the_pieces_without_a_camera_mass() -> None:
    # load cells: each weighed exit's mass joins the product's, worth MASS_PRIOR pieces; a
    # piece without a camera's mass has the mean, the pieces on the cone as well as those
    # born after; one with a camera's mass keeps it
    channel = int(MODEL.channels.channel_of(0.0))
    twin = rim_twin()
    assert twin.piece_mass == MODEL.product.m
    twin.measured_exit(0.1, channel, 0.2)  # the rim piece's
    twin.measured_exit(0.11, int(MODEL.channels.channel_of(180.0)))  # not weighed
    twin.measured_exit(0.12, int(MODEL.channels.channel_of(180.0)), 0.1)  # no piece there
    inner = np.array([[0.05, 0.05]])
    assert twin.masses[1] == MODEL.product.m
    frame = twin.update(0.1 + EXIT_LAG, inner)
    assert frame.measured == 1 and twin.pieces()[0].tolist() == [1]
    assert frame.left == (Exit(piece=0, t=0.1, channel=channel, mass=0.2),)  # as weighed
    assert set(twin.masses) == {1}  # the piece that left is forgotten
    mean = (MASS_PRIOR * MODEL.product.m + 0.2) / (MASS_PRIOR + 1)
    assert twin.piece_mass == pytest.approx(mean, rel=1e-15)
    assert twin.masses[1] == twin.piece_mass  # on the cone before the exit: the mean now
    assert twin.update(0.12 + EXIT_LAG, inner).measured == 2
    mean = (MASS_PRIOR * MODEL.product.m + 0.3) / (MASS_PRIOR + 2)
    assert twin.piece_mass == pytest.approx(mean, rel=1e-15)
    born = np.array([[0.05, 0.05], [-0.05, -0.05], [0.0, -0.1]])
    twin.update(0.25, born, np.array([np.nan, np.nan, 0.03]))
    assert twin.pieces()[0].tolist() == [1, 2, 3]
    assert twin.masses[1] == twin.masses[2] == twin.piece_mass and twin.masses[3] == 0.03
    # the members simulate each piece with the mass it was born with (the forecasts count
    # its mass now: test_forecast.py)
    born_with = [MODEL.product.m, twin.piece_mass, 0.03]
    assert all(s.products[:, P_M].tolist() == born_with for s in twin.states)
    # a weighed exit with the camera off (no piece near its channel: the mass alone counts)
    twin.measured_exit(0.3, channel, 0.4)
    twin.predict(0.3 + EXIT_LAG)
    assert twin.open_loop_exits() == () and twin.pieces()[0].tolist() == [1, 2, 3]
    mean = (MASS_PRIOR * MODEL.product.m + 0.7) / (MASS_PRIOR + 3)
    assert twin.piece_mass == pytest.approx(mean, rel=1e-15) and twin.piece_mass > 0.15
    assert twin.masses[1] == twin.masses[2] == twin.piece_mass and twin.masses[3] == 0.03
    twin.update(0.5, born)  # an analysis rebuilds the members' rows: the masses stay
    assert all(s.products[:, P_M].tolist() == born_with for s in twin.states)


def pushed(state: SimState, piece: int, speed: float) -> SimState:
    """Return the state with the piece moving outward along x at speed (m/s, cone axes)."""
    y = state.y.copy()
    y[list(state.ids).index(piece), 3:6] = [speed, 0.0, 0.0]
    return replace(state, y=y)


@pytest.mark.parametrize('late', [(2,), (2, 3)])
def test_a_piece_most_members_let_go_over_several_predictions_is_an_exit(late) -> None:
    # two of four members let the rim piece leave at once, the others 0.5 s later: once
    # most have, the twin drops it from all, an exit at the members' median time, one
    # member's (the mean, 0.18 s with one late member, or the midpoint of the middle two,
    # 0.26 s with two, would be a time none gave), and forgets it
    twin = rim_twin()
    assert set(twin.masses) == set(twin.last_seen) == set(twin.hits) == {0, 1}
    assert twin._mean_mass == {0, 1}
    twin.states = [pushed(s, 0, 1.0) if k < 2 else s for k, s in enumerate(twin.states)]
    twin.predict(0.5)
    assert [0 in s.ids for s in twin.states] == [False, False, True, True]
    assert set(twin.masses) == set(twin.last_seen) == {0, 1} and len(twin._leaving[0]) == 2
    twin.states = [pushed(s, 0, 3.0) if k in late else s for k, s in enumerate(twin.states)]
    twin.predict(0.6)
    assert all(s.ids.tolist() == [1] for s in twin.states)
    frame = twin.update(0.6, np.array([[0.05, 0.05]]))
    (left,) = frame.left
    assert left.piece == 0 and left.t < 0.05
    assert left.channel == int(MODEL.channels.channel_of(0.0))
    assert set(twin.masses) == set(twin.last_seen) == set(twin.hits) == {1}
    assert twin._mean_mass == {1} and twin._leaving == {}


def test_a_piece_some_members_hold_dies_unseen() -> None:
    # a piece one member lost (an exit, a failed integration) is in no output and no
    # association: it dies death_after (1 s) after it was last seen, in every member
    twin = rim_twin()
    twin.states = [remove_particles(twin.states[0], [0]), *twin.states[1:]]
    inner = np.array([[0.05, 0.05]])
    frame = twin.update(0.9, inner)
    assert frame.deaths == 0 and sum(0 in s.ids for s in twin.states) == 3
    frame = twin.update(1.05, inner)
    assert frame.deaths == 1 and frame.left == ()
    assert all(s.ids.tolist() == [1] for s in twin.states)
    assert set(twin.masses) == set(twin.last_seen) == set(twin.hits) == {1}


def test_a_bad_measured_exit_is_refused_with_its_reason() -> None:
    twin = rim_twin()
    for channel in (0, MODEL.channels.count + 1, 2.0, True):
        with pytest.raises(ValueError, match=f'channel {channel!r} is not one of 1..14'):
            twin.measured_exit(0.05, channel)
    # a piece heavier than 6.2 kg cannot rest on the cone (r_f 120 N, tilt 7.5 deg): one
    # load cell in grams (125 for 0.125 kg) would make every piece without a camera's mass so
    assert twin.heaviest == pytest.approx(60.0 / (MODEL.g * math.cos(math.radians(7.5)) ** 2))
    for mass in (0.0, -0.05, float('inf'), True, '0.05', 125.0, twin.heaviest):
        with pytest.raises(ValueError, match=f'mass {mass!r} is not a number of kg in '
                                             r'\(0, 6.222\)'):
            twin.measured_exit(0.05, 3, mass)
    assert twin.exit_mass(6.2) == 6.2  # heavy, but it rests
    # a camera's mass too, before the frame changes anything
    before = twin.snapshot()
    with pytest.raises(ValueError, match="a detection's mass of 125 kg is not below 6.222"):
        twin.update(0.6, np.array([[0.05, 0.05], [0.0, 0.1]]), np.array([np.nan, 125.0]))
    assert twin.t == before.t and twin.pending_exits == before.pending_exits
    twin.update(0.5, np.array([[0.05, 0.05]]))
    with pytest.raises(ValueError, match='older than the frames the twin took'):
        twin.measured_exit(0.5 - EXIT_LAG, 3)
    with pytest.raises(ValueError, match='not finite'):
        twin.measured_exit(float('nan'), 3)
    assert not twin.pending_exits


def test_a_small_ensemble_follows_many_pieces_consistently() -> None:
    # 8 members, 28 pieces: measured NIS 3,131 for 3,298 and 1,649 of 1,652 detections
    # associated; without localization each piece was moved by the others' innovations
    # (spurious covariances): NIS 5,454 for 3,208, 1,604 associated
    rng = np.random.default_rng(4)
    grid = np.array([[x, y] for x in np.linspace(-0.16, 0.16, 6)
                     for y in np.linspace(-0.16, 0.16, 6) if 0.05 < np.hypot(x, y) < 0.19])
    q = np.array([[x, y, resting_height(MODEL, MODEL.product, x, y)] for x, y in grid])
    plant, _ = add_particles(SimState(), PARAMS, q)
    profile = RotationProfile.from_table([[0.0, 0.0], [0.5, 3.0], [1.0, 3.0], [1.5, -3.0]])
    twin = Twin(PARAMS, TwinSettings(members=8, sigma=0.002, seed=3))
    nis, observed, associated, detected = 0.0, 0, 0, 0
    for k in range(1, 61):
        t = k / 30.0
        plant = advance(plant, PARAMS, profile, t).state
        twin.cone_speed(t, profile.omega(t))
        seen, _, _ = world_from_cone(plant.y, plant.angle, profile.omega(t))
        frame = twin.update(t, seen[:, :2] + rng.normal(0.0, 0.002, (plant.count, 2)))
        if k > 1:
            nis, observed = nis + frame.nis, observed + frame.observed
            associated, detected = associated + frame.associated, detected + plant.count
    assert plant.count == 28 and associated >= 0.995 * detected  # measured 1,649 of 1,652
    assert chi2.ppf(5e-4, observed) < nis < chi2.ppf(1.0 - 5e-4, observed)


def test_an_analysis_moves_a_piece_riding_with_the_cone_by_its_position_alone() -> None:
    # three pieces at rest on a cone at rest ride with it in every member; the first is
    # then made to slide in one member: it alone gets its velocity and filter force analysed
    twin = Twin(PARAMS, TwinSettings(members=8, sigma=SIGMA, seed=5))
    places = np.array(PLACES[:3])
    rng = np.random.default_rng(6)
    for k in range(1, 5):
        twin.cone_speed(k / 30.0, 0.0)
        twin.update(k / 30.0, places + rng.normal(0.0, SIGMA, places.shape))
    t = 5 / 30.0
    twin.cone_speed(t, 0.0)
    twin.predict(t)
    ids = twin.pieces()[0]
    assert len(ids) == 3 and all(np.all(np.linalg.norm(s.y[:, 3:6], axis=1) < STILL)
                                 for s in twin.states)
    sliding = twin.states[0].y.copy()
    sliding[0, 3] = 10.0 * STILL  # m/s, relative to the cone
    twin.states[0] = replace(twin.states[0], y=sliding)
    before = [s.y.copy() for s in twin.states]
    twin.update(t, places + 0.002)  # 2 mm off in x and y: every position moves
    for old, new in zip(before, twin.states):
        assert np.all(new.y[:, 0:2] != old[:, 0:2])
        np.testing.assert_array_equal(new.y[1:, 3:9], old[1:, 3:9])
    assert any(np.any(new.y[0, 3:9] != old[0, 3:9]) for old, new in zip(before, twin.states))


def test_a_false_detection_is_never_shown_and_dies_soon() -> None:
    twin = Twin(PARAMS, TwinSettings(members=4, sigma=SIGMA))
    piece, ghost = [0.1, 0.0], [-0.1, 0.05]
    shown = []
    for k in range(1, 9):
        twin.cone_speed(k / 30.0, 0.0)
        frame = twin.update(k / 30.0, np.array([piece, ghost] if k == 1 else [piece]))
        shown.append(len(twin.pieces()[0]))
        if k == 5:  # tentative_after (0.1 s) without a detection: dropped
            assert frame.deaths == 1 and len(twin.pieces(tentative=True)[0]) == 1
    assert shown == [0, 1, 1, 1, 1, 1, 1, 1]  # the piece confirmed at its second frame


def test_bad_input_is_refused_with_its_reason() -> None:
    twin = Twin(PARAMS, TwinSettings(members=4))
    twin.update(0.1, np.array([[0.1, 0.0]]))
    with pytest.raises(ValueError, match='not finite'):
        twin.update(0.2, np.array([[np.nan, 0.0]]))
    with pytest.raises(ValueError, match='older than the twin'):
        twin.update(0.05, np.array([[0.1, 0.0]]))
    with pytest.raises(ValueError, match='cone speed'):
        twin.cone_speed(-1.0, 1.0)
    with pytest.raises(ValueError, match='at least 2'):
        Twin(PARAMS, TwinSettings(members=1))
    with pytest.raises(ValueError, match='confirm must be at least 1'):
        Twin(PARAMS, TwinSettings(confirm=0))


def test_the_window_likelihood_is_the_gaussian_one_with_the_start_s_error_integrated_out(
        ) -> None:
    # brute force: the residuals' covariance written out (the noise on the diagonal, each
    # piece's columns moved together as the members' starts move them), inverted densely
    rng = np.random.default_rng(4)
    sigma, members = 0.002, 4
    ids = np.repeat(np.array([3, 7, 3, 9, 7, 3]), 2)  # frames hold different pieces
    residuals = rng.normal(0.0, 0.003, (5, len(ids)))
    anomalies = rng.normal(0.0, 0.001, (members, len(ids)))
    anomalies -= anomalies.mean(axis=0)
    same = ids[:, None] == ids[None, :]
    covariance = (sigma ** 2 * np.eye(len(ids))
                  + same * (anomalies.T @ anomalies) / (members - 1))
    expected = -0.5 * np.einsum('pi,ij,pj->p', residuals,
                                np.linalg.inv(covariance), residuals)
    found = window_log_likelihood(residuals, anomalies, ids, sigma)
    assert np.allclose(found, expected, rtol=1e-10, atol=0.0)
    # members that agree leave the plain Gaussian
    plain = -0.5 * np.sum(residuals ** 2, axis=1) / sigma ** 2
    assert np.array_equal(window_log_likelihood(residuals, 0.0 * anomalies, ids, sigma), plain)


def test_a_window_weighs_the_values_of_d_and_mu_c_by_the_fastest_sliding_pieces() -> None:
    settings = TwinSettings(members=4, particles=16, smoother_pieces=2, sigma=0.001, seed=3)
    twin = Twin(PARAMS, settings)
    assert len(twin.log_d) == len(twin.mu_c) == weighed_values(settings) == 16
    # three pieces at rest on a cone at rest, the youngest given a slide in every member
    twin.update(0.0, np.array([[0.10, 0.0], [0.0, 0.11], [-0.12, 0.0]]))
    twin.states = [replace(s, y=s.y.copy()) for s in twin.states]
    for state in twin.states:
        state.y[2, 3:5] = [0.05, 0.0]
    twin._start_window(0.0)
    # one state (no contact): of the slider and of the older of the others, 16 copies from
    # the members' mean (one per value), then 4 from each member's start (the values' mean)
    assert twin._smoother is not None and len(twin._smoother) == 1
    copies = twin._smoother[0]
    assert copies.ids.tolist() == [*range(20), *range(40, 60)]  # piece * 20 + copy
    starts = np.stack([s.y[[0, 2]] for s in twin.states])
    for k in range(16):  # each with its value of d
        assert np.all(copies.products[[k, 20 + k], P_D]
                      == pytest.approx(np.exp(twin._walk[0][k])))
        assert np.array_equal(copies.y[[k, 20 + k]], starts.mean(axis=0))
    for j in range(4):
        assert np.all(copies.products[[16 + j, 36 + j], P_D]
                      == pytest.approx(np.exp(np.mean(twin._walk[0]))))
        assert np.array_equal(copies.y[[16 + j, 36 + j]], starts[j])
    for t in (1 / 30, 2 / 30):
        twin.update(t, np.array([[0.10, 0.0], [0.0, 0.11], [-0.12, 0.0]]))
    assert [a.shape for a in twin._predicted] == [(16, 4)] * 2
    assert [a.shape for a in twin._anomalies] == [(4, 4)] * 2


def test_a_value_that_sends_a_seen_piece_off_the_cone_is_weighed_where_it_left() -> None:
    twin = Twin(PARAMS, TwinSettings(members=4, particles=8, smoother_pieces=1, sigma=0.001,
                                     seed=2))
    place = np.array([[0.20, 0.0]])  # at rest near the rim (0.225 m), the cone at rest
    twin.update(0.0, place)
    twin._start_window(0.0)
    assert twin._smoother is not None and len(twin._smoother) == 1
    copies = twin._smoother[0]
    assert copies.ids.tolist() == list(range(12))  # 8 values, then 4 members' starts
    # the copies of values 0 and 1 are sent outwards at 1 m/s: they leave within a frame
    twin._smoother = [replace(copies, y=copies.y.copy())]
    twin._smoother[0].y[:2, 3:5] = [1.0, 0.0]
    for t in (1 / 30, 2 / 30, 3 / 30):
        twin.update(t, place)  # the camera still sees the piece where it was
    assert twin._smoother[0].count == 10 and len(twin._departed) == 2
    # the piece still counts: the values whose copy left predict it where it left
    assert [a.shape for a in twin._predicted] == [(8, 2)] * 3
    left = np.array([twin._departed[(0, 0)], twin._departed[(0, 1)]])
    assert np.hypot(*left.T) == pytest.approx([MODEL.r] * 2, abs=1e-6)
    assert np.array_equal(twin._predicted[-1][:2], left)
    for predicted in twin._predicted:
        assert np.all(np.hypot(*predicted[:2].T) > 0.215)  # on the way or gone
        assert np.all(np.abs(predicted[2:] - place) < 0.002)  # where it is seen
    # and are weighed down by it
    log_likelihood = window_log_likelihood(
        np.concatenate(twin._predicted, axis=1) - np.concatenate(twin._observed),
        np.concatenate(twin._anomalies, axis=1), np.concatenate(twin._observed_ids), 0.001)
    assert np.max(log_likelihood[:2]) < np.min(log_likelihood[2:]) - 100.0


def one_piece_window(x: float) -> Twin:
    """Return a twin (4 members, 8 values) of one piece seen at (x, 0), its window started."""
    twin = Twin(PARAMS, TwinSettings(members=4, particles=8, smoother_pieces=1, sigma=0.001,
                                     confirm=1, seed=2))
    twin.update(0.0, np.array([[x, 0.0]]))
    twin._start_window(0.0)
    return twin


def test_a_value_that_keeps_a_piece_the_camera_no_longer_sees_is_weighed_down(
        monkeypatch: pytest.MonkeyPatch) -> None:
    twin = one_piece_window(0.20)  # at rest near the rim, the cone at rest
    copies = twin._smoother[0]
    twin._smoother = [replace(copies, y=copies.y.copy())]
    twin._smoother[0].y[:2, 3:5] = [1.0, 0.0]  # the copies of values 0 and 1 leave
    nothing = np.zeros((0, 2))
    for k in range(1, 5):  # and the camera sees the piece no more
        twin.update(k / 30, nothing)
    assert twin.pieces()[0].tolist() == [0] and len(twin._departed) == 2
    # every frame costs the values whose copy holds the piece; those whose copy left, less
    assert np.all(twin._missed[2:] == 4 * MISSED_FRAME)
    assert np.all(twin._missed[:2] >= 3 * MISSED_FRAME)
    later = twin.snapshot()  # a rewind's copy goes on apart
    later._missed += 1.0
    later._departed.clear()
    assert np.all(twin._missed[2:] == 4 * MISSED_FRAME) and len(twin._departed) == 2
    weighed = []

    def spy(parameters, log_likelihood, rng):  # noqa: ANN001, ANN202 - the function's own
        weighed.append(log_likelihood)
        return resample_parameters(parameters, log_likelihood, rng)

    monkeypatch.setattr('cone_feeder_sim.twin.estimator.resample_parameters', spy)
    twin._smooth()  # no detection in the window: the frames it missed weigh alone
    assert len(weighed) == 1 and np.array_equal(weighed[0], twin._missed)


def test_a_copy_whose_integration_fails_keeps_its_piece_counting_where_it_was() -> None:
    twin, place = one_piece_window(0.10), np.array([[0.10, 0.0]])
    copies = twin._smoother[0]
    twin._smoother = [replace(copies, y=copies.y.copy())]
    last, _, _ = world_from_cone(twin._smoother[0].y[[3]], copies.angle, 0.0)
    twin._smoother[0].y[3, 3] = np.nan  # value 3's copy cannot be integrated
    twin.update(1 / 30, place)
    assert twin._smoother[0].count == 11
    assert np.array_equal(twin._departed[(0, 3)], last[0, :2])  # where it last was
    # the piece still counts for every value, value 3's copy where it was
    assert [a.shape for a in twin._predicted] == [(8, 2)]
    assert np.array_equal(twin._predicted[0][3], last[0, :2])
    assert np.all(twin._missed == 0.0)


def test_a_piece_the_twin_dropped_while_the_camera_sees_it_costs_no_value() -> None:
    # the members send the piece off, the camera still sees it (born again under a new id):
    # the values whose copy kept it were right, and must not pay for the twin's mistake
    twin, place = one_piece_window(0.20), np.array([[0.20, 0.0]])
    twin.states = [replace(s, y=s.y.copy()) for s in twin.states]
    for state in twin.states:
        state.y[0, 3:5] = [1.0, 0.0]
    copies = twin._smoother[0]
    twin._smoother = [replace(copies, y=copies.y.copy())]
    twin._smoother[0].y[:2, 3:5] = [1.0, 0.0]  # and the copies of values 0 and 1
    for k in range(1, 5):
        twin.update(k / 30, place)
    assert 0 not in twin.pieces(tentative=True)[0].tolist()  # dropped, then born again
    assert len(twin.pieces(tentative=True)[0]) == 1
    assert len(twin._departed) == 2 and np.all(twin._missed == 0.0)


def test_the_note_names_too_few_values_of_d_and_mu_c() -> None:
    assert parameter_note(TwinSettings(members=4)) == ''  # 32 values, whatever the members
    assert '8 values of d and mu_C' in parameter_note(TwinSettings(members=4, particles=8))
    assert parameter_note(TwinSettings(members=40, particles=8)) == ''  # as many as members
    assert 'window 0' in parameter_note(TwinSettings(window=0.0))


def test_with_the_pair_law_on_the_smoother_weighs_pieces_apart_without_it() -> None:
    # copies of one piece in one state overlap: they run without the pair law, and only
    # the pieces that touch no other (within 3 s0) are weighed
    touching = replace(MODEL, interactions=replace(MODEL.interactions, enabled=True))
    twin = Twin(SimParams(model=touching), TwinSettings(members=4, particles=8, sigma=0.001,
                                                        smoother_pieces=3, drift=0.0, seed=5))
    gap = 2.5 * MODEL.product.s0
    frame = np.array([[0.10, 0.0], [0.10, gap], [-0.12, 0.0]])  # two close, one apart
    twin.update(0.0, frame)
    twin.log_d[:], twin.mu_c[:] = np.log(225.0), 0.85  # every value the same
    twin._start_window(0.0)
    assert twin._smoother is not None and len(twin._smoother) == 1
    assert twin._window_pieces.tolist() == [2]
    twin.states = [replace(s, y=s.y.copy()) for s in twin.states]
    slide = np.array([0.3, 0.0])  # the cone at rest: the piece and its copies slide
    copies = twin._smoother[0]
    twin._smoother = [replace(copies, y=copies.y.copy())]
    twin._smoother[0].y[:, 3:5] = slide
    for t in (1 / 30, 2 / 30):
        twin.update(t, frame)
    # 8 copies in one place, with one value: with the pair law they would push apart
    # (millimetres); without it they stay together to round-off (the copies are rows of one
    # compiled loop, which a CPU may run in vector lanes and a scalar remainder)
    assert [a.shape for a in twin._predicted] == [(8, 2)] * 2
    assert np.ptp(twin._predicted[-1], axis=0).max() < 1e-12
    assert np.hypot(*(twin._predicted[-1][0] - frame[2])) > 0.001  # and they slid


def test_a_window_without_a_piece_every_member_holds_weighs_nothing() -> None:
    twin = Twin(PARAMS, TwinSettings(members=2, particles=4, sigma=0.001, seed=1))
    twin.update(0.0, np.array([[0.10, 0.0], [-0.12, 0.0]]))
    twin.states = [remove_particles(s, [k]) for k, s in enumerate(twin.states)]  # one each
    twin._start_window(0.0)
    assert twin._smoother is None


def test_the_window_weighs_its_values_with_the_start_s_error_integrated_out(
        monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []

    def spy(residuals, anomalies, ids, sigma):  # noqa: ANN001, ANN202 - the function's own
        calls.append((residuals.shape, anomalies.shape, ids.shape, sigma))
        return window_log_likelihood(residuals, anomalies, ids, sigma)

    monkeypatch.setattr('cone_feeder_sim.twin.estimator.window_log_likelihood', spy)
    twin = Twin(PARAMS, TwinSettings(members=4, particles=8, sigma=0.001, window=0.1, seed=1))
    for k in range(7):  # a window from 0 to 0.1 s: frames at 1/30 .. 3/30 s, weighed at 0.1 s
        twin.update(k / 30.0, np.array([[0.10, 0.0], [-0.12, 0.0]]))
    (residuals, anomalies, ids, sigma), *_ = calls
    assert residuals[0] == 8 and anomalies[0] == 4 and residuals[1] == anomalies[1] == ids[0]
    assert sigma == 0.001


@pytest.mark.parametrize('settings, fragment', [
    ({'particles': 1}, 'particles must be at least 2'),
    ({'smoother_pieces': 0}, 'smoother_pieces at least 1'),
    ({'sigma': 0.0}, 'sigma must be positive'),
])
def test_settings_out_of_range_are_refused(settings: dict, fragment: str) -> None:
    with pytest.raises(ValueError, match=fragment):
        Twin(PARAMS, TwinSettings(**settings))
