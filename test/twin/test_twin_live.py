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
"""The twin frame by frame: a frame waits for its cone speed; the camera stops and returns."""

from collections.abc import Iterator
from dataclasses import replace

from cone_feeder_sim.errors import Stopped
from cone_feeder_sim.physics.params import InteractionParams, ModelParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    add_particles, advance, resting_height, SimParams, SimState, world_from_cone)
from cone_feeder_sim.twin.camera import CameraSettings, observe
from cone_feeder_sim.twin.estimator import MASS_PRIOR, TwinSettings
from cone_feeder_sim.twin.frames import DetectionFrame
from cone_feeder_sim.twin.live import Follower, LiveSettings
import numpy as np
import pytest
from scipy.stats import chi2

MODEL = ModelParams()
PARAMS = SimParams(model=MODEL)
PROFILE = RotationProfile.from_table([[0.0, 0.0], [0.5, 4.0], [2.0, 4.0], [2.5, -4.0]])
PLACES = [[0.10, 0.02], [-0.08, 0.09], [0.03, -0.13], [-0.12, -0.05]]


def test_the_camera_stops_the_twin_goes_on_open_loop_and_recovers() -> None:
    rng = np.random.default_rng(0)
    q = np.array([[x, y, resting_height(MODEL, MODEL.product, x, y)] for x, y in PLACES])
    plant, _ = add_particles(SimState(), PARAMS, q)
    follower = Follower(PARAMS, LiveSettings(
        twin=TwinSettings(members=8, sigma=0.001, d_spread=0.05, mu_C_spread=0.01),
        forecast_period=0.25, open_loop_after=0.5))
    states: dict[float, str] = {}
    forecasts: list[float] = []
    for k in range(1, 124):  # 4.1 s; the camera is off from 1.0 s to 2.5 s
        t = k / 30.0
        plant = advance(plant, PARAMS, PROFILE, t).state
        seen, _, _ = world_from_cone(plant.y, plant.angle, PROFILE.omega(t))
        camera = not 1.0 < t <= 2.5
        if camera:  # the frame first: it waits for the encoder's reading of its instant
            found = DetectionFrame(t, seen[:, :2] + rng.normal(0.0, 0.001, (plant.count, 2)),
                                   None, None)
            assert follower.frame(found) == []
            assert follower.cone_speed(t, PROFILE.omega(t)) == [t]
        else:
            assert follower.cone_speed(t, PROFILE.omega(t)) == []
        states[t] = follower.state(t)
        if follower.outlook is not None and (not forecasts or follower.outlook.t > forecasts[-1]):
            forecasts.append(follower.outlook.t)
        if camera:
            assert follower.t == t
        elif states[t] == 'open loop':  # a copy moves on; the twin waits at its last frame
            assert follower.current.t == t and follower.t == 1.0
    assert states[30 / 30.0] == 'following'
    assert states[44 / 30.0] == 'following'  # within open_loop_after of the last frame
    assert all(state == 'open loop' for t, state in states.items() if 1.6 < t <= 2.5)
    assert any(1.6 < t <= 2.5 for t in forecasts)  # forecasts go on from the model alone
    assert all(state == 'following' for t, state in states.items() if t > 2.5)
    # every piece found again; a piece that the reversal in the dark put outside the gate is
    # born again, and its stale copy dies death_after (1 s) later (measured: one of four,
    # at 2.77 s)
    ids, mean, _ = follower.twin.pieces()
    assert len(ids) == plant.count, (ids, plant.ids)
    error = np.linalg.norm(mean[:, None, :] - seen[None, :, :2], axis=2).min(axis=1)
    assert error.max() < 0.005
    assert follower.last.associated == plant.count


def test_a_frame_without_encoder_goes_on_when_the_next_one_comes() -> None:
    follower = Follower(PARAMS, LiveSettings(twin=TwinSettings(members=4)))
    first = DetectionFrame(0.1, np.array([[0.1, 0.0]]), None, None)
    second = DetectionFrame(0.2, np.array([[0.1, 0.0]]), None, None)
    assert follower.frame(first) == []
    assert follower.frame(second) == [0.1]  # one frame late, on the last speed measured
    assert follower.state() == 'following'


def plant_frames(params: SimParams, profile: RotationProfile, places: list,
                 seconds: float) -> Iterator[tuple[float, float, SimState, np.ndarray]]:
    """Yield a plant's (t, cone speed, state, true world x, y (n, 2)) at 30 frames/s."""
    model = params.model
    q = np.array([[x, y, resting_height(model, model.product, x, y)] for x, y in places])
    plant, _ = add_particles(SimState(), params, q)
    for k in range(1, int(round(30 * seconds)) + 1):
        t = k / 30.0
        plant = advance(plant, params, profile, t).state
        seen, _, _ = world_from_cone(plant.y, plant.angle, profile.omega(t))
        yield t, profile.omega(t), plant, seen[:, :2]


def stream(seconds: float) -> list[tuple[float, float, np.ndarray]]:
    """Return the plant's (t, cone speed, detections) at 30 frames/s."""
    rng = np.random.default_rng(5)
    return [(t, omega, seen + rng.normal(0.0, 0.001, seen.shape))
            for t, omega, _, seen in plant_frames(PARAMS, PROFILE, PLACES, seconds)]


def test_late_frames_give_what_the_frames_in_order_give() -> None:
    # every fourth frame arrives after the two frames after it (67 ms late), as a camera's
    # frame held up on the network does: the twin goes back to itself before that frame and
    # analyses again, and ends exactly where the frames in order take it
    settings = LiveSettings(twin=TwinSettings(members=8, sigma=0.001, seed=3),
                            forecast_period=0.5)
    frames = stream(1.5)
    in_order = Follower(PARAMS, settings)
    for t, omega, xy in frames:
        in_order.cone_speed(t, omega)
        in_order.frame(DetectionFrame(t, xy, None, None))
    late = Follower(PARAMS, settings)
    held: list[DetectionFrame] = []
    for k, (t, omega, xy) in enumerate(frames):
        late.cone_speed(t, omega)
        if k % 4 == 1:
            held.append(DetectionFrame(t, xy, None, None))
            continue
        late.frame(DetectionFrame(t, xy, None, None))
        if held and k % 4 == 3:
            late.frame(held.pop())
    for frame in held:
        late.frame(frame)
    ours, theirs = late.twin, in_order.twin
    assert ours.t == theirs.t
    assert np.array_equal(ours.pieces()[1], theirs.pieces()[1])
    assert ours.parameters() == theirs.parameters()
    assert np.array_equal(ours.states[3].y, theirs.states[3].y)


def test_a_late_measured_exit_gives_what_it_gives_in_order() -> None:
    # two resting pieces; from 0.3 s the camera no longer sees the one at the rim, and a
    # channel's sensor measured its exit at 0.3 s. Given in order, the frame of 0.4 s
    # (EXIT_LAG after it) takes it; given after the frame of 0.5 s, the twin goes back to
    # before the frame of 0.4 s and analyses again
    settings = LiveSettings(twin=TwinSettings(members=4, sigma=0.001, seed=3),
                            forecast_period=0.5)
    channel = int(MODEL.channels.channel_of(0.0))
    rng = np.random.default_rng(1)
    frames = []
    for k in range(1, 19):
        t = k / 30.0
        xy = np.array([[0.21, 0.0], [0.05, 0.05]] if t < 0.3 - 1e-9 else [[0.05, 0.05]])
        frames.append(DetectionFrame(t, xy + rng.normal(0.0, 0.001, xy.shape), None, None))
    twins = []
    for late in (False, True):
        follower = Follower(PARAMS, settings)
        again: list[float] = []
        for found in frames:
            follower.frame(found)
            follower.cone_speed(found.t, 0.0)
            if abs(found.t - (0.3 if not late else 0.5)) < 1e-9:
                again = follower.measured_exit(0.3, channel, 0.08)  # a load cell's step
        assert again == ([] if not late else [frames[k].t for k in (11, 12, 13, 14)])
        twins.append(follower.twin)
    ours, theirs = twins
    assert theirs.pieces()[0].tolist() == ours.pieces()[0].tolist() == [1]
    assert ours.t == theirs.t and ours.parameters() == theirs.parameters()
    weighed = (MASS_PRIOR * MODEL.product.m + 0.08) / (MASS_PRIOR + 1)
    assert ours.piece_mass == theirs.piece_mass == pytest.approx(weighed, rel=1e-15)
    assert np.array_equal(ours.states[3].y, theirs.states[3].y)
    with pytest.raises(ValueError, match='older than the twin can go back to'):
        follower.measured_exit(0.1, channel)
    with pytest.raises(ValueError, match='channel 15 is not one of'):
        follower.measured_exit(0.55, 15)


def test_a_frame_with_a_mass_no_piece_can_have_is_refused_before_it_waits() -> None:
    follower = Follower(PARAMS, LiveSettings(twin=TwinSettings(members=4, sigma=0.001, seed=3)))
    xy = np.array([[0.05, 0.05]])
    with pytest.raises(ValueError, match="a detection's mass of 125 kg is not below"):
        follower.frame(DetectionFrame(0.1, xy, np.array([125.0]), None))  # grams, as kg
    assert follower.frame(DetectionFrame(0.2, xy, np.array([0.125]), None)) == []
    assert follower.frame(DetectionFrame(0.3, xy, None, None)) == [0.2]  # 0.1 never waited


def test_in_open_loop_the_moving_copy_takes_the_measured_exits() -> None:
    follower = Follower(PARAMS, LiveSettings(twin=TwinSettings(members=4, sigma=0.001, seed=3),
                                             forecast_period=0.5, open_loop_after=0.2))
    channel = int(MODEL.channels.channel_of(0.0))
    for k in range(1, 4):  # two resting pieces, one at the rim, seen until 0.1 s
        follower.frame(DetectionFrame(k / 30.0, np.array([[0.21, 0.0], [0.05, 0.05]]), None,
                                      None))
        follower.cone_speed(k / 30.0, 0.0)
    for k in range(4, 16):  # the camera is off; the rim piece's exit is measured at 0.3 s
        t = k / 30.0
        follower.cone_speed(t, 0.0)
        if k == 10:
            assert follower.state(t) == 'open loop'
            follower.measured_exit(0.3, channel)
        if k == 11:  # less than EXIT_LAG (0.1 s) after it: still there
            assert follower.current.pieces()[0].tolist() == [0, 1]
    assert follower.current.t == 0.5 and follower.current.pieces()[0].tolist() == [1]
    # the twin waits at its last frame: the frame after the dark takes the exit
    assert follower.twin.t == 0.1 and [e[:2] for e in follower.twin.pending_exits] == [
        (0.3, channel)]
    # a report that comes after the copy moved EXIT_LAG past it: the copy takes it at once
    late = Follower(PARAMS, follower.settings)
    for k in range(1, 16):
        t = k / 30.0
        if k < 4:
            late.frame(DetectionFrame(t, np.array([[0.21, 0.0], [0.05, 0.05]]), None, None))
        late.cone_speed(t, 0.0)
    assert late.current.pieces()[0].tolist() == [0, 1]
    assert late.measured_exit(0.3, channel) == []
    assert late.current.pieces()[0].tolist() == [1]
    with pytest.raises(ValueError, match='not finite'):
        late.measured_exit(float('nan'), channel)


def camera(seconds: float, seed: int) -> list[tuple[float, float, DetectionFrame, np.ndarray]]:
    """
    Return a hard plant's (t, cone speed, frame, true x, y) at 30 frames/s.

    The plant: six pieces, two pairs of them in contact (the pair law on), a product other
    than the twin's prior (d 315, mu_C 0.78), the cone reversing twice. The camera: 1.5 mm
    of noise, 10 % of the pieces missed, a false detection in 30 % of the frames, track ids
    shuffled in every frame.
    """
    rng = np.random.default_rng(seed)
    model = replace(MODEL, product=replace(MODEL.product, d=315.0, mu_C=0.78),
                    interactions=InteractionParams(enabled=True))
    params = SimParams(model=model)
    profile = RotationProfile.from_table([[0.0, 0.0], [0.5, 5.0], [1.5, 5.0], [2.0, -5.0],
                                          [3.0, -5.0], [3.5, 5.0]])
    touch = 2.0 * 0.98 * model.product.s0  # 2 % of a diameter overlapping
    places = [[0.10, 0.02], [0.10, 0.02 + touch], [-0.08, 0.09], [0.03, -0.13],
              [0.03 + touch, -0.13], [-0.12, -0.05]]
    out = []
    lens = CameraSettings(sigma=0.0015, miss=0.1, false_rate=0.3, radius=0.25, swap=0.0)
    for t, omega, plant, seen in plant_frames(params, profile, places, seconds):
        xy, ids = observe(lens, rng, seen, plant.ids)
        out.append((t, omega, DetectionFrame(t, xy, None, ids), seen))
    return out


def test_a_hard_plant_is_followed_with_consistent_innovations() -> None:
    # misses, false detections, swapped ids, pieces in contact and every fifth frame two
    # frames late: after half a second, the twin holds the plant's pieces and no others,
    # within 5 mm, and its innovations are chi-square with their degrees of freedom
    # (measured: NIS 910 for 908 from 0.5 s; the twin without the pair law)
    follower = Follower(PARAMS, LiveSettings(
        twin=TwinSettings(members=16, sigma=0.0015, seed=2), forecast_period=0.5))
    held: list[DetectionFrame] = []
    nis, observed, counts = 0.0, 0, []
    for k, (t, omega, found, truth) in enumerate(camera(4.0, 11), start=1):
        follower.cone_speed(t, omega)
        if k % 5 == 2:
            held.append(found)
            continue
        if follower.frame(found) == [t] and t > 0.5:  # in order: one analysis each
            nis += follower.last.nis
            observed += follower.last.observed
        if held and k % 5 == 4:
            late = held.pop()
            assert follower.frame(late) == [late.t]  # and the two frames after it again
        if t > 0.5:
            ids, mean, _ = follower.twin.pieces()
            error = np.linalg.norm(mean[:, None, :] - truth[None, :, :], axis=2)
            counts.append(len(ids) == len(truth))
            assert error.min(axis=0).max() < 0.005 and error.min(axis=1).max() < 0.005
    assert np.mean(counts) > 0.95
    assert observed > 600
    assert chi2.ppf(5e-4, observed) < nis < chi2.ppf(1.0 - 5e-4, observed)


def test_swapped_or_absent_track_ids_give_the_same_twin() -> None:
    # the association is by position alone: a camera's ids that swap cannot mislead it;
    # each piece carries the track id of the detection last associated with it
    twins = []
    frames = camera(1.0, 4)
    for ids in (True, False):
        follower = Follower(PARAMS, LiveSettings(twin=TwinSettings(members=4, seed=1)))
        for t, omega, found, _ in frames:
            follower.cone_speed(t, omega)
            follower.frame(found if ids else replace(found, track_ids=None))
        twins.append(follower.twin)
    truth = frames[-1][3]
    assert np.array_equal(twins[0].pieces()[1], twins[1].pieces()[1])
    assert twins[0].parameters() == twins[1].parameters()
    pieces, mean, _ = twins[0].pieces()
    nearest = np.argmin(np.linalg.norm(mean[:, None] - truth[None], axis=2), axis=1)
    assert len(pieces) == len(truth)  # the plant's ids are 0..5, in the order of truth
    assert [twins[0].tracks[int(i)] for i in pieces] == nearest.tolist()
    assert twins[1].tracks == {}


def test_forecasts_on_their_own_thread_leave_the_twin_as_forecasts_in_turn() -> None:
    # the forecasts read a snapshot: the twin is the one the frames make either way, and
    # the newest finished forecast is one the synchronous follower also made
    made = []
    for background in (False, True):
        follower = Follower(PARAMS, LiveSettings(twin=TwinSettings(members=4, seed=2),
                                                 forecast_period=0.2, background=background))
        outlooks = {}
        for t, omega, xy in stream(1.0):
            follower.cone_speed(t, omega)
            follower.frame(DetectionFrame(t, xy, None, None))
            if follower.outlook is not None:
                outlooks[follower.outlook.t] = follower.outlook
        follower.close()
        figures = follower.figures()
        made.append((follower.twin, outlooks, figures))
    (ours, in_turn, _), (theirs, threaded, figures) = made
    assert np.array_equal(ours.pieces()[1], theirs.pieces()[1])
    assert ours.parameters() == theirs.parameters()
    assert threaded and figures['forecasts'] >= 1
    for t, outlook in threaded.items():
        np.testing.assert_array_equal(outlook.mass, in_turn[t].mass)


def test_a_frame_older_than_the_history_is_refused() -> None:
    follower = Follower(PARAMS, LiveSettings(twin=TwinSettings(members=4), max_delay=0.2))
    for t in (0.1, 0.2, 0.3, 0.4, 0.5):
        follower.cone_speed(t, 0.0)
        follower.frame(DetectionFrame(t, np.array([[0.1, 0.0]]), None, None))
    follower.frame(DetectionFrame(0.45, np.array([[0.1, 0.0]]), None, None))  # in time
    with pytest.raises(ValueError, match='max_delay'):
        follower.frame(DetectionFrame(0.05, np.array([[0.1, 0.0]]), None, None))
    assert follower.t == 0.5


def test_a_stop_request_ends_the_computation_under_way() -> None:
    # twin_node's watcher sets the flag when a signal shuts its context down: the kernels
    # read it between steps, and the frame's analysis ends with Stopped instead of finishing
    frames = stream(0.2)
    follower = Follower(PARAMS, LiveSettings(twin=TwinSettings(members=4)))
    for t, omega, xy in frames[:3]:
        follower.cone_speed(t, omega)
        follower.frame(DetectionFrame(t, xy, None, None))
    follower.stop.request()
    t, omega, xy = frames[3]
    follower.frame(DetectionFrame(t, xy, None, None))
    with pytest.raises(Stopped):
        follower.cone_speed(t, omega)
