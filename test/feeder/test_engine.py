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

"""Tests of cone_feeder_sim.feeder.engine: the drive, the feed, inputs per tick and determinism."""

import math

from cone_feeder_sim.errors import InputError, ParameterError, ScenarioError, Stopped
from cone_feeder_sim.feeder.engine import (
    drive_profile, DriveParams, EngineConfig, FeederEngine, FeedParams, MAX_PENDING_INPUTS,
    pattern_from_flat, PieceSpec, Reconfigure, ResetRequest, RotationCommand, SpawnRequest,
    tick_many, TickResult)
from cone_feeder_sim.physics.integrator import advance_batch, advance_batch_owned
from cone_feeder_sim.physics.params import (
    ChannelLayout, InteractionParams, ModelParams, SolverParams)
from cone_feeder_sim.physics.simulation import resting_height, warm_up
from crowds import crowd_in_layers
import numpy as np
import pytest

MODEL = ModelParams()
TABLE_I = (((0.11, -0.01, 0.03), 225.0), ((-0.10, -0.01, 0.03), 135.0),
           ((0.08, -0.13, 0.03), 750.0), ((-0.07, 0.04, 0.03), 750.0),
           ((0.14, 0.06, 0.03), 30.0))


def table_i_pieces() -> tuple[PieceSpec, ...]:
    return tuple(PieceSpec(p, product=MODEL.product.with_overrides({'d': d}))
                 for p, d in TABLE_I)


def resting(x: float, y: float) -> tuple[float, float, float]:
    return (x, y, resting_height(MODEL, MODEL.product, x, y))


def engine(**kwargs: object) -> FeederEngine:
    drive = kwargs.pop('drive', DriveParams(max_angular_velocity=10.0,
                                            max_angular_acceleration=20.0, cmd_timeout=0.0))
    return FeederEngine(EngineConfig(drive=drive, **kwargs))  # type: ignore[arg-type]


def test_starts_at_rest_and_time_is_index_times_dt() -> None:
    eng = engine(dt=0.01)
    assert (eng.t, eng.omega, eng.angle, eng.tick_index, eng.piece_count) == (0, 0, 0, 0, 0)
    for k in range(7):
        res = eng.tick()
        assert res.index == k
        assert res.t0 == k * 0.01 and res.t == (k + 1) * 0.01
    assert eng.t == 7 * 0.01 and eng.tick_index == 7


def test_command_followed_within_acceleration_limit_with_a_kink_mid_tick() -> None:
    eng = engine(dt=0.02)
    eng.command(1.0)
    omegas = []
    angles = [0.0]
    for _ in range(4):
        res = eng.tick()
        assert res.mode == 'command' and res.target_omega == 1.0
        omegas.append(res.omega)
        angles.append(res.angle)
    np.testing.assert_allclose(omegas, [0.4, 0.8, 1.0, 1.0])
    # third tick: ramp 0.8 -> 1.0 in 0.01 s at 20 rad/s^2, then 0.01 s at 1.0 rad/s
    assert angles[3] - angles[2] == pytest.approx(0.8 * 0.01 + 0.5 * 20 * 0.01 ** 2 + 0.01,
                                                  abs=1e-15)
    assert angles[1] == pytest.approx(0.5 * 20 * 0.02 ** 2, abs=1e-15)


def test_drive_profile_shapes() -> None:
    full = drive_profile(1.0, 1.02, 0.0, 5.0, 20.0)
    np.testing.assert_allclose(full.omegas, [0.0, 0.4])
    kink = drive_profile(1.0, 1.02, 0.0, 0.1, 20.0)
    np.testing.assert_allclose(kink.times, [1.0, 1.005, 1.02])
    np.testing.assert_allclose(kink.omegas, [0.0, 0.1, 0.1])
    hold = drive_profile(1.0, 1.02, -3.0, -3.0, 20.0)
    np.testing.assert_allclose(hold.omegas, [-3.0, -3.0])
    down = drive_profile(0.0, 0.5, 2.0, -2.0, 4.0)
    np.testing.assert_allclose(down.omegas, [2.0, 0.0])
    # a change below the resolution of t0 is taken at once instead of failing
    tiny = drive_profile(1.0e6, 1.0e6 + 0.02, 0.0, 1.0e-14, 20.0)
    assert tiny.omega(1.0e6 + 0.01) == 1.0e-14


def test_target_is_clamped_to_the_maximum_angular_velocity() -> None:
    eng = engine(dt=0.05)
    eng.command(-50.0)
    peak = 0.0
    for _ in range(20):
        res = eng.tick()
        assert res.target_omega == -10.0
        peak = min(peak, res.omega)
        assert abs(res.omega) <= 10.0
    assert peak == -10.0


def test_runtime_reduction_of_the_limit_decelerates_within_the_acceleration_limit() -> None:
    eng = engine(dt=0.05)
    eng.command(10.0)
    for _ in range(12):
        eng.tick()
    assert eng.omega == pytest.approx(10.0)
    eng.reconfigure(drive=DriveParams(max_angular_velocity=5.0, max_angular_acceleration=20.0,
                                      cmd_timeout=0.0))
    assert eng.tick().omega == pytest.approx(9.0)
    assert eng.tick().omega == pytest.approx(8.0)


def test_cmd_timeout_ramps_to_rest_and_zero_holds() -> None:
    drive = DriveParams(max_angular_velocity=10.0, max_angular_acceleration=20.0,
                        cmd_timeout=0.1)
    eng = engine(dt=0.02, drive=drive)
    eng.command(2.0)
    modes = []
    omegas = []
    for _ in range(20):
        res = eng.tick()
        modes.append(res.mode)
        omegas.append(res.omega)
    # command applied at t = 0; ticks starting at t0 >= 0.1 s have timed out
    assert modes[:5] == ['command'] * 5 and modes[5:] == ['timeout'] * 15
    assert max(omegas) == pytest.approx(2.0)
    assert np.all(np.abs(np.diff(omegas)) <= 20.0 * 0.02 + 1e-12)
    assert omegas[-1] == 0.0
    # a new command revives the drive
    eng.command(1.0)
    assert eng.tick().mode == 'command'
    hold = engine(dt=0.02, drive=DriveParams(cmd_timeout=0.0))
    hold.command(2.0)
    for _ in range(100):
        res = hold.tick()
    assert res.mode == 'command' and res.omega == pytest.approx(2.0)


def test_open_loop_pattern_loops_until_the_first_command() -> None:
    drive = DriveParams(max_angular_velocity=10.0, max_angular_acceleration=1.0e4,
                        cmd_timeout=0.0, pattern=((0.1, 3.0), (0.05, -2.0)))
    assert drive.period == pytest.approx(0.15)
    eng = engine(dt=0.01, drive=drive)
    targets = [eng.tick().target_omega for _ in range(45)]
    expected = ([3.0] * 10 + [-2.0] * 5) * 3
    assert targets == expected
    assert eng.omega == -2.0
    eng.command(0.5)
    res = eng.tick()
    assert (res.mode, res.target_omega) == ('command', 0.5)
    # the pattern does not come back after the commands stop: the timeout stops the cone
    empty = engine(dt=0.01, drive=DriveParams(pattern=()))
    res = empty.tick()
    assert (res.mode, res.target_omega, res.omega) == ('pattern', 0.0, 0.0)


def test_pattern_from_flat() -> None:
    assert pattern_from_flat([1.0, -2.0, 3.0, 4.0]) == ((1.0, -2.0), (3.0, 4.0))
    assert pattern_from_flat([]) == ()
    with pytest.raises(ParameterError, match='pairs'):
        pattern_from_flat([1.0, 2.0, 3.0])


@pytest.mark.parametrize('kwargs, fragment', [
    ({'max_angular_velocity': 0.0}, 'max_angular_velocity'),
    ({'max_angular_acceleration': float('inf')}, 'must be finite'),
    ({'cmd_timeout': -1.0}, 'cmd_timeout'),
    ({'pattern': ((0.0, 1.0),)}, r'pattern\[0\] duration'),
    ({'pattern': ((1.0, 1.0, 2.0),)}, 'must be a pair'),
    ({'pattern': ((1.0, 1.0e3),)}, r'pattern\[0\] omega'),
])
def test_drive_validation_names_the_problem(kwargs: dict, fragment: str) -> None:
    with pytest.raises(ParameterError, match=fragment):
        DriveParams(**kwargs)


@pytest.mark.parametrize('kwargs, fragment', [
    ({'rate': -1.0}, 'feed.rate'),
    ({'rho_min': 0.1, 'rho_max': 0.05}, 'must not exceed'),
    ({'d_values': (1.0, -5.0)}, r'feed.d_values\[1\]'),
    ({'mass_rel_std': 2.0}, 'feed.mass_rel_std'),
    ({'max_pieces': 0}, 'feed.max_pieces'),
    ({'max_pieces': 2.5}, 'integer'),
])
def test_feed_validation_names_the_problem(kwargs: dict, fragment: str) -> None:
    with pytest.raises(ParameterError, match=fragment):
        FeedParams(**kwargs)


def test_config_validation() -> None:
    with pytest.raises(ParameterError, match='inside the cone'):
        EngineConfig(feed=FeedParams(rho_max=0.3))
    with pytest.raises(ParameterError, match="'dt'"):
        EngineConfig(dt=0.0)
    with pytest.raises(ParameterError, match='seed'):
        EngineConfig(seed=-1)
    with pytest.raises(ScenarioError, match='initial piece 1: .*outside the cone'):
        EngineConfig(initial_pieces=(PieceSpec((0.0, 0.0, 0.05)), PieceSpec((0.3, 0.0, 0.0))))


def test_spawn_and_command_refusals_keep_the_engine_running() -> None:
    eng = engine(dt=0.01)
    bad_spawns = [
        ([[0.3, 0.0, 0.01]], 'outside the cone'),
        ([[0.1, 0.0, 0.0]], 'below the cone surface'),
        ([[0.1, float('nan'), 0.05]], 'not finite'),
        ([[0.1, 0.0]], 'shape'),
        (np.zeros((0, 3)), 'at least one'),
    ]
    for positions, fragment in bad_spawns:
        with pytest.raises(ScenarioError, match=fragment):
            eng.spawn(positions)
    with pytest.raises(ScenarioError, match='velocity'):
        eng.spawn([[0.1, 0.0, 0.05]], velocities=[[0.0, 0.0]])
    for value in (float('nan'), float('inf'), '1.0', True):
        with pytest.raises(ParameterError, match='rotation command'):
            eng.command(value)  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match='inside the cone'):
        eng.reconfigure(feed=FeedParams(rho_max=1.0))
    assert eng.pending == ()
    eng.spawn([[0.1, 0.0, 0.05], [0.0, 0.1, 0.05]])
    res = eng.tick()
    assert res.count == 2 and list(res.spawned_ids) == [0, 1]
    assert res.positions.shape == (2, 3)


def test_inputs_are_applied_at_the_next_tick_in_arrival_order() -> None:
    eng = engine(dt=0.01)
    eng.command(1.0)
    eng.command(-1.0)
    eng.spawn([resting(0.1, 0.0)])
    eng.reset()
    eng.spawn([resting(0.0, 0.1)])
    assert [type(p) for p in eng.pending] == [RotationCommand, RotationCommand,
                                              SpawnRequest, ResetRequest, SpawnRequest]
    assert eng.piece_count == 0
    res = eng.tick()
    assert res.reset
    assert [type(p) for p in res.applied] == [RotationCommand, RotationCommand, SpawnRequest,
                                              ResetRequest, SpawnRequest]
    # the reset removed the first piece and forgot the commands; the second piece stays
    assert list(res.ids) == [1] and list(res.spawned_ids) == [0, 1]
    assert res.mode == 'pattern' and eng.pending == ()


def test_spawned_pieces_move_as_requested() -> None:
    eng = engine(dt=0.01)
    eng.command(5.0)
    for _ in range(10):
        eng.tick()
    eng.spawn([resting(0.1, 0.0)])
    eng.spawn([resting(0.1, 0.0)], velocities=[[0.0, 0.0, 0.0]])
    res = eng.tick()
    assert res.count == 2
    # the carried piece keeps up with the surface, the dropped one lags behind
    carried, dropped = res.velocities
    assert carried[1] == pytest.approx(res.omega * 0.1, rel=0.05)
    assert dropped[1] < carried[1] - 0.05


def run_with_inputs(config: EngineConfig, schedule: dict[int, list]) -> list:
    eng = FeederEngine(config)
    results = []
    for k in range(70):
        for item in schedule.get(k, []):
            eng.submit(item)
        results.append(eng.tick())
    return results


def busy_config(seed: int = 7) -> EngineConfig:
    return EngineConfig(
        dt=0.02, seed=seed, initial_pieces=table_i_pieces(),
        drive=DriveParams(max_angular_velocity=10.47, max_angular_acceleration=40.0,
                          cmd_timeout=1.0, pattern=((1.0, -10.47), (1.0, 10.47))),
        feed=FeedParams(rate=40.0, mass_rel_std=0.3, d_values=(30.0, 750.0)))


def test_run_is_reproducible_from_config_and_tick_indexed_inputs() -> None:
    schedule = {
        5: [SpawnRequest(np.array([resting(0.05, 0.05)]))],
        20: [Reconfigure(feed=FeedParams(rate=10.0, rho_min=0.1, rho_max=0.12))],
        40: [RotationCommand(10.0)],
        50: [ResetRequest(), RotationCommand(-6.0)],
        61: [RotationCommand(2.0), SpawnRequest(np.array([resting(-0.1, 0.0)]),
                                                np.zeros((1, 3)))],
    }
    first = run_with_inputs(busy_config(), schedule)
    assert sum(len(r.exits) for r in first) > 0
    assert sum(len(r.feed_ids) for r in first) > 0
    # replay from the log of applied inputs
    log = {r.index: list(r.applied) for r in first if r.applied}
    assert sorted(log) == sorted(schedule)
    second = run_with_inputs(busy_config(), log)
    for a, b in zip(first, second):
        assert a.t == b.t and a.angle == b.angle and a.omega == b.omega
        np.testing.assert_array_equal(a.ids, b.ids)
        np.testing.assert_array_equal(a.positions, b.positions)
        np.testing.assert_array_equal(a.velocities, b.velocities)
        np.testing.assert_array_equal(a.masses, b.masses)
        np.testing.assert_array_equal(a.exits.ids, b.exits.ids)
        np.testing.assert_array_equal(a.exits.t, b.exits.t)
        np.testing.assert_array_equal(a.channel_mass, b.channel_mass)
    # another seed gives another feed
    third = run_with_inputs(busy_config(seed=8), schedule)
    assert not all(np.array_equal(a.masses, b.masses) for a, b in zip(first, third))


def test_feed_is_seeded_and_follows_its_parameters() -> None:
    feed = FeedParams(rate=5000.0, rho_min=0.05, rho_max=0.12, drop_height=0.04,
                      mass_rel_std=0.25, d_values=(30.0, 750.0), max_pieces=100_000)
    config = EngineConfig(dt=0.02, seed=3, feed=feed)
    eng = FeederEngine(config)
    res = [eng.tick() for _ in range(3)]
    ids = np.concatenate([r.feed_ids for r in res])
    counts = [len(r.feed_ids) for r in res]
    # Poisson(100) per tick: 3 draws far inside 100 +- 40
    assert all(60 <= c <= 140 for c in counts)
    again = FeederEngine(config)
    assert [len(again.tick().feed_ids) for _ in range(3)] == counts
    products = eng.state.products
    first_tick = res[0].feed_ids
    assert len(ids) == sum(counts)
    masses = products[:, 0]
    d = products[:, 1]
    assert set(np.unique(d)) == {30.0, 750.0}
    assert np.mean(masses) == pytest.approx(MODEL.product.m, rel=0.05)
    assert np.std(masses) / MODEL.product.m == pytest.approx(0.25, rel=0.2)
    # drop positions of the first tick, at the start of the tick (inputs of tick 0)
    fresh = FeederEngine(config)
    state_before = fresh.state
    assert state_before.count == 0
    fresh._feed_pieces()  # the generator's first draws, as in tick 0
    q = fresh.state.y[:, 0:3]  # cone axes = world axes at angle 0
    rho = np.hypot(q[:, 0], q[:, 1])
    assert len(q) == len(first_tick)
    assert np.all((rho >= 0.05) & (rho <= 0.12))
    np.testing.assert_allclose(q[:, 2], MODEL.h * (1 - rho / MODEL.r) + 0.04)
    np.testing.assert_allclose(fresh.state.y[:, 3:6], 0.0)  # dropped: at rest in the world


def test_feed_pauses_at_max_pieces() -> None:
    eng = FeederEngine(EngineConfig(dt=0.02, feed=FeedParams(rate=2000.0, max_pieces=10)))
    counts = [eng.tick().count for _ in range(3)]
    assert max(counts) <= 10 and counts[0] == 10


def test_reset_restores_the_start_and_keeps_time_and_ids_running() -> None:
    config = busy_config()
    eng = FeederEngine(config)
    start = [eng.tick() for _ in range(25)]
    assert sum(len(r.exits) for r in start) > 0
    assert start[-1].channel_mass.sum() > 0
    eng.reset()
    after = [eng.tick() for _ in range(25)]
    assert after[0].reset and after[0].t0 == pytest.approx(25 * 0.02)
    assert eng.t == pytest.approx(50 * 0.02)
    assert after[0].ids.min() > start[-1].ids.max() if start[-1].count else True
    # the run after the reset repeats the first one (time shifted, ids offset)
    for a, b in zip(start, after):
        assert a.count == b.count
        assert a.omega == pytest.approx(b.omega, abs=1e-9)
        assert a.angle == pytest.approx(b.angle, abs=1e-9)
        np.testing.assert_allclose(a.positions, b.positions, atol=1e-7)
        np.testing.assert_allclose(a.channel_mass, b.channel_mass, atol=1e-12)
        np.testing.assert_allclose(a.masses, b.masses)


def test_channel_mass_is_the_sum_of_the_exit_events() -> None:
    eng = FeederEngine(busy_config())
    total = np.zeros(MODEL.channels.count)
    exits = 0
    for _ in range(50):
        res = eng.tick()
        for channel, mass in zip(res.exits.channel, res.exits.mass):
            total[channel - 1] += mass
            exits += 1
        np.testing.assert_allclose(res.channel_mass, total, rtol=0, atol=1e-12)
        assert np.all(res.exits.t > res.t0) and np.all(res.exits.t <= res.t)
        assert np.all(np.hypot(res.exits.position[:, 0], res.exits.position[:, 1])
                      == pytest.approx(MODEL.r, abs=1e-6))
    assert exits >= 5


def test_world_states_match_the_cone_surface_at_rest() -> None:
    eng = FeederEngine(EngineConfig(dt=0.02, initial_pieces=(
        PieceSpec(resting(0.1, 0.02)), PieceSpec(resting(-0.05, -0.1)))))
    for _ in range(10):
        res = eng.tick()
    assert res.count == 2 and list(res.ids) == [0, 1]
    np.testing.assert_allclose(res.positions, [resting(0.1, 0.02), resting(-0.05, -0.1)],
                               atol=2e-4)
    np.testing.assert_allclose(res.velocities, 0.0, atol=1e-3)
    assert math.isclose(res.masses[0], MODEL.product.m)


# --------------------------------------------------------------------------- bounds


def test_a_spawn_beyond_max_pieces_is_refused_for_the_excess() -> None:
    eng = engine(feed=FeedParams(max_pieces=5), initial_pieces=table_i_pieces()[:3])
    eng.spawn([resting(0.05 * math.cos(a), 0.05 * math.sin(a)) for a in np.arange(4.0)])
    res = eng.tick()
    assert res.count == 5 and res.spawned_ids.shape == (2,)
    assert [(r.kind, r.count) for r in res.refusals] == [('spawn', 2)]
    assert 'feed.max_pieces = 5' in res.refusals[0].reason
    eng.spawn([resting(0.05, 0.0)])
    res = eng.tick()
    assert res.count == 5 and [r.count for r in res.refusals] == [1]
    assert eng.tick().refusals == ()


def test_the_feed_and_the_initial_pieces_respect_max_pieces() -> None:
    eng = engine(feed=FeedParams(rate=500.0, max_pieces=7))
    counts = [eng.tick().count for _ in range(20)]
    assert max(counts) == 7
    with pytest.raises(ScenarioError, match='exceed feed.max_pieces = 2'):
        EngineConfig(feed=FeedParams(max_pieces=2), initial_pieces=table_i_pieces())


def test_the_input_queue_is_bounded() -> None:
    eng = engine()
    for k in range(MAX_PENDING_INPUTS):
        eng.command(float(k % 5))
    with pytest.raises(InputError, match=f'{MAX_PENDING_INPUTS} inputs are already waiting'):
        eng.command(1.0)
    with pytest.raises(InputError):
        eng.spawn([resting(0.05, 0.0)])
    assert len(eng.tick().applied) == MAX_PENDING_INPUTS
    eng.command(1.0)  # the queue is empty again after the tick


def test_a_full_queue_refuses_a_reconfiguration_before_it_is_submitted() -> None:
    eng = engine()
    eng.check_reconfigure(feed=FeedParams(rate=3.0))  # room, and a feed that fits
    with pytest.raises(ParameterError, match='inside the cone'):
        eng.check_reconfigure(feed=FeedParams(rho_max=1.0))
    for k in range(MAX_PENDING_INPUTS):
        eng.command(float(k % 5))
    with pytest.raises(InputError, match='already waiting'):
        eng.check_reconfigure()
    assert len(eng.pending) == MAX_PENDING_INPUTS  # the check queued nothing


def test_a_command_says_the_target_it_gets_under_the_speed_limit() -> None:
    eng = engine()  # max_angular_velocity 10 rad/s
    assert eng.command(4.0) == 4.0
    assert eng.command(25.0) == 10.0 and eng.command(-25.0) == -10.0
    eng.tick()
    assert eng.tick().target_omega == -10.0  # the tick applies the same clamp


def test_an_offered_spawn_takes_the_valid_poses_and_refuses_the_rest() -> None:
    eng = engine(feed=FeedParams(rate=0.0, max_pieces=3), spawn_max_height=0.5)
    good = [resting(0.05 * math.cos(a), 0.05 * math.sin(a)) for a in np.linspace(0, 6, 5)]
    positions = np.array([good[0], (0.3, 0.0, 0.01), good[1], (0.1, np.nan, 0.05), good[2],
                          (0.05, 0.0, 0.6), good[3], good[4]])
    offer = eng.offer_spawn(positions, np.zeros_like(positions))
    assert offer.total == 8
    assert offer.invalid.count == 3
    for fragment in ('position[1]', 'outside the cone', 'position[3]', 'not finite',
                     'position[5]', 'above the highest start 0.5 m'):
        assert fragment in offer.invalid.reason
    assert offer.excess.count == 2 and 'feed.max_pieces = 3' in offer.excess.reason
    assert offer.queue is None and offer.refusals == (offer.invalid, offer.excess)
    request, = eng.pending
    np.testing.assert_array_equal(request.positions, np.array(good[:3]))
    assert eng.tick().count == 3
    # nothing valid: nothing queued, all refused
    offer = eng.offer_spawn([[0.3, 0.0, 0.01]])
    assert offer.invalid.count == 1 and offer.excess is None and eng.pending == ()


def test_spawns_above_the_highest_start_are_refused() -> None:
    eng = engine(spawn_max_height=0.5)
    with pytest.raises(ScenarioError, match='above the highest start 0.5 m'):
        eng.spawn([(0.05, 0.0, 0.6)])
    with pytest.raises(ScenarioError, match='above the highest start'):
        eng.spawn([(0.05, 0.0, 1e300)])
    eng.spawn([(0.05, 0.0, 0.5)])
    assert eng.tick().count == 1


def test_failed_pieces_are_reported_with_their_mass_and_the_mass_balances() -> None:
    # max_steps = 1 per tick: every piece that needs more than one step fails
    eng = engine(solver=SolverParams(max_steps=1), initial_pieces=table_i_pieces(),
                 feed=FeedParams(rate=50.0))
    failures = []
    for _ in range(10):
        res = eng.tick()
        failures += res.failures
        on_cone = float(res.masses.sum())
        assert res.mass_in == pytest.approx(
            on_cone + float(res.channel_mass.sum()) + res.failed_mass, rel=1e-12, abs=1e-15)
    assert failures and res.failed_mass == pytest.approx(sum(f.mass for f in failures))
    first = failures[0]
    assert 'max_steps' in first.reason and first.mass > 0.0
    assert np.all(np.isfinite(first.position)) and np.all(np.isfinite(first.velocity))


def test_mass_balance_with_exits_spawns_and_a_reset() -> None:
    eng = engine(feed=FeedParams(rate=20.0), initial_pieces=table_i_pieces())
    eng.command(8.0)
    exited = 0
    for k in range(150):
        if k == 100:
            eng.reset()
        if k % 10 == 5:
            eng.spawn([resting(0.2, 0.0)], velocities=[(1.0, 0.0, 0.0)])
        res = eng.tick()
        exited += len(res.exits)
        assert res.mass_in == pytest.approx(
            float(res.masses.sum()) + float(res.channel_mass.sum()) + res.failed_mass,
            rel=1e-12)
    assert exited > 0


def test_no_kernel_is_compiled_inside_a_tick() -> None:
    eng = engine(model=ModelParams(g=5.0, cone_tilt=9.0), solver=SolverParams(rtol=1e-4),
                 feed=FeedParams(rate=100.0))
    loaded = list(advance_batch.signatures)  # the engine loaded the kernel when built
    assert loaded
    eng.spawn([resting(0.2, 0.0)], velocities=[(2.0, 0.0, 0.0)])
    eng.command(8.0)
    for _ in range(30):
        eng.tick()
    assert list(advance_batch.signatures) == loaded


def test_no_contact_kernel_is_compiled_inside_a_tick() -> None:
    from cone_feeder_sim.physics.coupling import advance_coupled
    from cone_feeder_sim.physics.exact import advance_island
    from cone_feeder_sim.physics.island import advance_islands
    from cone_feeder_sim.physics.neighbours import _contact_pairs
    # each engine loads the kernels of its own coupling when it is built
    for coupling, kernels in (('island', (advance_islands, _contact_pairs)),
                              ('multirate', (advance_coupled, _contact_pairs)),
                              ('exact', (advance_island, _contact_pairs))):
        eng = engine(model=ModelParams(interactions=InteractionParams(enabled=True,
                                                                      coupling=coupling)),
                     feed=FeedParams(rate=0.0))
        loaded = [list(k.signatures) for k in kernels]
        assert all(loaded)  # the engine loaded them when built
        # a row of five touching pieces: one island
        eng.spawn([resting(0.02 + 0.046 * k, 0.0) for k in range(5)])
        for _ in range(30):
            eng.tick()
        assert [list(k.signatures) for k in kernels] == loaded


def test_pieces_that_touch_are_not_spawned_inside_each_other() -> None:
    # a thousand pieces at one place: one is placed, the others refused with the reason
    # (pressed 50 mm into another); pieces pressed in by less than 10 mm are placed
    eng = engine(model=ModelParams(interactions=InteractionParams(enabled=True)),
                 feed=FeedParams(rate=0.0, max_pieces=2000))
    eng.spawn(np.tile(resting(0.1, 0.0), (1000, 1)))
    result = eng.tick()
    assert eng.piece_count == 1 and result.refusals[0].count == 999
    assert 'position[1] ' in result.refusals[0].reason
    assert 'is pressed 50.0 mm into position[0] (at most 10.0 mm' in result.refusals[0].reason
    eng.spawn([resting(0.1, 0.045), resting(0.1, -0.03)])  # 5 mm in; 20 mm into piece 0
    result = eng.tick()
    assert eng.piece_count == 2 and result.refusals[0].count == 1
    reason = result.refusals[0].reason
    assert 'position[1]' in reason and 'into piece 0' in reason
    alone = engine(feed=FeedParams(rate=0.0))  # the paper's model: pieces pass through
    alone.spawn(np.tile(resting(0.1, 0.0), (3, 1)))
    alone.tick()
    assert alone.piece_count == 3


def test_the_weigher_below_the_cone_takes_every_exit() -> None:
    from cone_feeder_sim.weigher.machine import WeigherParams
    weigher = WeigherParams(target=0.2, transport_time=0.5, load_cell_noise=0.0)
    engine = FeederEngine(EngineConfig(drive=DriveParams(pattern=((2.0, -8.0), (2.0, 8.0))),
                                       feed=FeedParams(rate=5.0), weigher=weigher))
    packs, exits = [], 0.0
    for _ in range(1000):  # 20 s
        result = engine.tick()
        packs += result.packs
        exits += float(result.exits.mass.sum())
        assert result.hoppers.shape == (14,)
    balance = engine.weigher.balance()
    assert balance['in'] == pytest.approx(exits, rel=1e-12)
    held = sum(v for k, v in balance.items() if k != 'in')
    assert held == pytest.approx(balance['in'], rel=1e-12)
    assert len(packs) > 5 and all(pack.mass >= 0.2 for pack in packs)
    assert [pack.index for pack in packs] == list(range(1, len(packs) + 1))
    assert engine.weigher.heads == 14  # one head per channel of the cone
    # a machine whose combinations cannot be enumerated each cycle is refused up front
    with pytest.raises(ParameterError, match='weigher.max_heads'):
        EngineConfig(model=ModelParams(channels=ChannelLayout(count=40)),
                     weigher=WeigherParams(max_heads=14))


def test_channel_feed_sets_the_troughs_and_is_checked() -> None:
    from cone_feeder_sim.feeder.engine import ChannelFeed
    from cone_feeder_sim.weigher.machine import WeigherParams
    engine = FeederEngine(EngineConfig(drive=DriveParams(pattern=((2.0, -8.0), (2.0, 8.0))),
                                       feed=FeedParams(rate=10.0), weigher=WeigherParams()))
    engine.submit(ChannelFeed((0.0,) * 14))  # every trough stopped
    for _ in range(500):
        assert not engine.tick().packs
    balance = engine.weigher.balance()
    assert balance['in'] > 0.0 and balance['troughs'] == balance['in']
    engine.submit(ChannelFeed((1.0,) * 14))
    packs = sum((list(engine.tick().packs) for _ in range(300)), [])
    assert packs and engine.weigher.amplitude.tolist() == [1.0] * 14
    for bad, match in [((1.0,) * 13, '14 amplitudes'), ((2.5,) + (1.0,) * 13, r'\[0, 2\]'),
                       ((math.nan,) * 14, r'\[0, 2\]'), (('x',) * 14, 'numbers')]:
        with pytest.raises(ParameterError, match=match):
            engine.submit(ChannelFeed(bad))
    with pytest.raises(InputError, match='no weigher'):
        FeederEngine(EngineConfig()).submit(ChannelFeed((1.0,) * 14))


@pytest.mark.parametrize('coupling', ['alone', 'island', 'multirate', 'exact'])
def test_a_long_tick_leaves_the_gil_to_other_threads(coupling: str) -> None:
    # a tick that would compute for minutes (no step longer than 2e-8 s: a million steps a
    # piece) runs on a thread; this thread keeps running Python meanwhile and then stops
    # the tick. A kernel that held the GIL would let this thread run only once the tick had
    # ended by itself, and the tick would not have been stopped.
    import threading
    import time
    model = ModelParams(interactions=InteractionParams(
        enabled=coupling != 'alone', coupling='island' if coupling == 'alone' else coupling))
    sim = FeederEngine(EngineConfig(model=model, solver=SolverParams(h_max=2.0e-8),
                                    drive=DriveParams(cmd_timeout=0.0),
                                    feed=FeedParams(rate=0.0)))
    sim.spawn(crowd_in_layers(1)[:3], velocities=np.zeros((3, 3)))  # three pieces, one island
    entered = threading.Event()
    outcome: list[str] = []

    def run() -> None:
        entered.set()
        try:
            sim.tick()
            outcome.append('ended by itself')
        except Stopped:
            outcome.append('stopped')

    worker = threading.Thread(target=run)
    worker.start()
    assert entered.wait(60.0)
    cpu, rounds = time.process_time(), 0
    while rounds < 100 or time.process_time() < cpu + 0.2:  # the worker computes meanwhile
        time.sleep(0.001)
        rounds += 1
    alive = worker.is_alive()
    sim.request_stop()
    worker.join(120.0)
    assert alive and outcome == ['stopped'], (alive, outcome)


def test_tick_many_equals_each_engines_own_ticks() -> None:
    # three feeders under their own drives and feeds, pieces integrated in one call
    def engines() -> list[FeederEngine]:
        made = []
        for k, omega in enumerate((-6.0, 0.0, 8.0)):
            eng = FeederEngine(EngineConfig(feed=FeedParams(rate=60.0, mass_rel_std=0.2,
                                                            rho_min=0.17, rho_max=0.21),
                                            seed=k, drive=DriveParams(cmd_timeout=0.0)))
            eng.command(omega)
            made.append(eng)
        made[2].spawn(np.array([[0.1, 0.0, 0.05]]), velocities=np.zeros((1, 3)))
        return made

    together, alone = engines(), engines()
    # tick_many's callers load its kernel first (the RL vector environment, when built)
    warm_up(ModelParams(), batched=True)
    loaded = list(advance_batch_owned.signatures)  # none compiles in a tick
    assert loaded
    exits = 0
    for _ in range(30):
        for mine, theirs in zip(tick_many(together), [eng.tick() for eng in alone]):
            np.testing.assert_array_equal(mine.positions, theirs.positions)
            np.testing.assert_array_equal(mine.velocities, theirs.velocities)
            np.testing.assert_array_equal(mine.channel_mass, theirs.channel_mass)
            assert mine.omega == theirs.omega and mine.stats == theirs.stats
            exits += len(mine.exits)
    assert exits > 0 and all(eng.piece_count > 5 for eng in together)
    assert list(advance_batch_owned.signatures) == loaded


def test_observers_see_every_tick_until_let_go() -> None:
    engine = FeederEngine(EngineConfig(feed=FeedParams(rate=20.0)))
    seen: list[tuple[int, float]] = []

    def observer(source: FeederEngine, result: TickResult) -> None:
        assert source is engine
        seen.append((result.index, source.t))

    engine.observe(observer)
    results = [engine.tick() for _ in range(3)]
    assert seen == [(r.index, r.t) for r in results]
    engine.unobserve(observer)
    engine.unobserve(observer)  # not observing: no error
    engine.tick()
    assert len(seen) == 3
