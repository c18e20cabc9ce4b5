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


"""Pieces that touch: the coupled integration against the reference the tests build."""

from cone_feeder_sim.physics.islands import islands_of
from cone_feeder_sim.physics.params import (
    InteractionParams, ModelParams, product_row, ProductParams, SolverParams)
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    contact_reach, resting_height, SimParams, Simulator)
import numpy as np
import pytest
from reference_contacts import (
    crowd_trajectory, four_touching_at, FOUR_TOUCHING_TABLE, FOUR_TOUCHING_XY, rim_crowd_exits)
from reference_model import table2_params

STILL = [[0.0, 0.0], [100.0, 0.0]]
TURNING = [[0.0, 0.0], [0.4, -8.0], [5.0, -8.0]]
HEAVY = ProductParams(m=0.2, s0=0.03)  # another product: heavier and larger


def model(pull_off: float = 0.05, enabled: bool = True, max_island: int = 1000) -> ModelParams:
    return ModelParams(interactions=InteractionParams(enabled=enabled, pull_off=pull_off,
                                                      max_island=max_island))


def simulate(m: ModelParams, table: list, positions: np.ndarray, velocities=None,
             products=None, t_end: float = 0.3, dt: float = 0.02,
             rtol: float | None = None) -> tuple[Simulator, dict[int, tuple[float, float]]]:
    solver = SolverParams() if rtol is None else SolverParams(
        rtol=rtol, atol_position=0.1 * rtol, atol_velocity=rtol, atol_force=10.0 * rtol)
    sim = Simulator(SimParams(model=m, solver=solver), RotationProfile.from_table(table))
    sim.add(positions, velocities, products)
    exits = {}
    for k in range(1, int(round(t_end / dt)) + 1):
        result = sim.advance_to(dt * k)
        assert not result.failures
        exits.update({int(i): (float(t), float(a)) for i, t, a in
                      zip(result.exits.ids, result.exits.t, result.exits.angle_deg)})
    return sim, exits


def resting(m: ModelParams, xy: list) -> np.ndarray:
    xy = np.asarray(xy, dtype=float)
    z = [resting_height(m, m.product, a, b) for a, b in xy]
    return np.column_stack([xy, z])


def test_islands_are_the_connected_pieces() -> None:
    pairs = np.array([[0, 3], [3, 5], [1, 2], [6, 7]])
    got = islands_of(9, pairs)
    assert [list(members) for members, _ in got] == [[0, 3, 5], [1, 2], [6, 7]]
    assert [local.tolist() for _, local in got] == [[[0, 1], [1, 2]], [[0, 1]], [[0, 1]]]
    assert islands_of(4, np.empty((0, 2), dtype=np.int64)) == []
    # against a plain search on random graphs
    rng = np.random.default_rng(2)
    for _ in range(20):
        count = 30
        pairs = np.unique(np.sort(rng.integers(0, count, (25, 2)), axis=1), axis=0)
        pairs = pairs[pairs[:, 0] != pairs[:, 1]]
        found = {tuple(members) for members, _ in islands_of(count, pairs)}
        expected = set()
        seen = set()
        for start in range(count):
            if start in seen:
                continue
            group, todo = {start}, [start]
            while todo:
                i = todo.pop()
                for a, b in pairs:
                    for u, v in ((a, b), (b, a)):
                        if u == i and v not in group:
                            group.add(v)
                            todo.append(v)
            seen |= group
            if len(group) > 1:
                expected.add(tuple(sorted(group)))
        assert found == expected


def test_contact_reach_covers_the_force() -> None:
    reach = contact_reach(np.array([product_row(ProductParams())]))[0]
    assert reach == pytest.approx(0.0375 / 2 + np.arctanh(1 - 2e-6) / (2 * np.arctanh(0.99))
                                  * 0.0125, rel=1e-12)


@pytest.mark.parametrize('v', [0.2, 1.0])
def test_a_collision_in_free_flight_keeps_momentum_and_follows_the_reference(v: float) -> None:
    # well above the cone, at rest: a default piece hits a heavier, larger one
    positions = np.array([[-0.065, 0.0, 20.0], [0.0, 0.0, 20.0]])
    velocities = np.array([[v, 0.0, 0.0], [0.0, 0.0, 0.0]])
    sim = Simulator(SimParams(model=model(0.0)), RotationProfile.from_table(STILL))
    sim.add(positions, velocities, [ProductParams(), HEAVY])
    t_out = np.linspace(0.01, 0.3, 30)
    ref = crowd_trajectory([table2_params(1), table2_params(1, m=0.2, s0=0.03)],
                           np.hstack([positions, velocities, np.zeros((2, 3))]), STILL, 0.3,
                           t_eval=t_out)
    ref_y = ref.y.reshape(2, 9, -1)
    for k, t in enumerate(t_out):
        sim.advance_to(float(t))
        q, qdot, _ = sim.world()
        momentum = 0.125 * qdot[0, :2] + 0.2 * qdot[1, :2]
        assert np.abs(momentum - [0.125 * v, 0.0]).max() < 1e-15  # to round-off
        np.testing.assert_allclose(q, ref_y[:, 0:3, k], atol=2e-7)
        np.testing.assert_allclose(qdot, ref_y[:, 3:6, k], atol=2e-5)
    # the pieces touched and parted slower than they met (inelastic)
    assert 0.0 < (qdot[1, 0] - qdot[0, 0]) / v < 0.3


@pytest.mark.parametrize('v', [0.1, 1.0, 3.0])
def test_restitution_and_contact_duration_are_those_the_parameters_predict(v: float) -> None:
    # two default pieces head on, well above the cone, against the law's 1-D prediction
    from cone_feeder_sim.physics.contact import COLLISION_FORCE_FRACTION, head_on_collision
    m = model(0.05)
    piece = m.product
    gap = 0.08
    t_out = np.arange(1, int((gap - 2 * piece.s0) / v * 1e3) + 301) * 1e-3
    predicted = head_on_collision(piece.m, piece.s0, piece.s_c, piece.r_a, piece.r_d,
                                  piece.r_f, 0.05, v, t_max=float(t_out[-1]), start=gap,
                                  times=t_out)
    positions = np.array([[-0.5 * gap, 0.0, 20.0], [0.5 * gap, 0.0, 20.0]])
    velocities = np.array([[0.5 * v, 0.0, 0.0], [-0.5 * v, 0.0, 0.0]])
    sim = Simulator(SimParams(model=m), RotationProfile.from_table(STILL))
    sim.add(positions, velocities)
    from cone_feeder_sim.physics.contact import pair_force_py
    row = product_row(piece)
    distance, strong = [], []
    for t in t_out:
        sim.advance_to(float(t))
        q, qdot, _ = sim.world()
        assert abs(qdot[:, 0].sum()) < 1e-14 and abs(qdot[:, 1].sum()) < 1e-14  # momentum
        distance.append(q[1, 0] - q[0, 0])
        force = pair_force_py(q[1], qdot[1], row, q[0], qdot[0], row, 0.0)[0]
        strong.append(force > COLLISION_FORCE_FRACTION * piece.r_f)
    np.testing.assert_allclose(distance, predicted.distance, rtol=0.0, atol=5e-6)
    assert min(distance) == pytest.approx(predicted.closest, abs=1e-5)
    assert sum(strong) * 1e-3 == pytest.approx(predicted.duration, abs=2.1e-3)
    assert 0.0 < predicted.restitution < 0.1  # raw meat barely bounces


@pytest.fixture(scope='module')
def crowd_at_the_rim() -> tuple[np.ndarray, dict, dict]:
    """Six touching pieces near the rim, the cone spun up to -8 rad/s; both solutions."""
    m = model()
    positions = resting(m, [[0.15, 0.0], [0.19, 0.02], [0.16, 0.045], [0.12, 0.02],
                            [0.20, -0.025], [0.14, -0.04]])
    _, exits = simulate(m, TURNING, positions, t_end=1.1)
    reference = rim_crowd_exits(tuple(map(tuple, positions.tolist())))
    return positions, exits, reference


@pytest.mark.slow
def test_touching_pieces_exit_where_the_coupled_reference_says(crowd_at_the_rim) -> None:
    positions, exits, reference = crowd_at_the_rim
    # ids are given in order from 0; every piece leaves, as in the reference
    assert sorted(exits) == sorted(reference) == list(range(6))
    for i in range(6):
        assert abs(exits[i][0] - reference[i][0]) < 2e-3  # s
        assert abs((exits[i][1] - reference[i][1] + 180.0) % 360.0 - 180.0) < 0.1  # deg
    # the pieces do push each other: without interactions they leave elsewhere
    _, alone = simulate(model(enabled=False), TURNING, positions, t_end=1.1)
    assert max(abs(alone[i][1] - exits[i][1]) for i in range(6)) > 1.0


def test_the_case_is_robust(crowd_at_the_rim) -> None:
    positions, exits, _ = crowd_at_the_rim
    moved = positions.copy()
    moved[2, 0] += 1e-6
    _, again = simulate(model(), TURNING, moved, t_end=1.1)
    assert max(abs(again[i][1] - exits[i][1]) for i in range(6)) < 0.2


def test_pieces_out_of_reach_move_exactly_as_without_interactions() -> None:
    positions = resting(model(), [[0.05, 0.0], [-0.1, 0.05], [0.0, -0.15]])
    a, _ = simulate(model(), TURNING, positions, t_end=0.6)
    b, _ = simulate(model(enabled=False), TURNING, positions, t_end=0.6)
    np.testing.assert_array_equal(a.state.y, b.state.y)


def test_a_mirrored_crowd_under_mirrored_rotation_mirrors() -> None:
    m = model()
    positions = resting(m, [[0.06, 0.01], [0.105, 0.015], [0.08, 0.05], [0.12, -0.02]])
    mirrored = positions * [1.0, -1.0, 1.0]
    a, ea = simulate(m, TURNING, positions, t_end=0.8)
    b, eb = simulate(m, [[t, -w] for t, w in TURNING], mirrored, t_end=0.8)
    qa, _, _ = a.world()
    qb, _, _ = b.world()
    np.testing.assert_allclose(qb, qa * [1.0, -1.0, 1.0], atol=1e-9)
    assert ea.keys() == eb.keys()


def test_the_error_shrinks_with_the_tolerance() -> None:
    m = model()
    positions = resting(m, FOUR_TOUCHING_XY)
    table = [list(r) for r in FOUR_TOUCHING_TABLE]
    ref = four_touching_at(tuple(map(tuple, positions.tolist())))
    errors = []
    for rtol in (1e-3, 1e-5, 1e-7):
        sim, _ = simulate(m, table, positions, t_end=0.4, rtol=rtol)
        errors.append(np.abs(sim.world()[0] - ref).max())
    # measured: 9.1e-7, 3.6e-8 and 5.0e-10 m
    assert errors[0] > 5.0 * errors[1] > 25.0 * errors[2]
    assert errors[2] < 1e-8  # m


def test_a_pile_settles() -> None:
    # 40 pieces in two layers 5.2 cm apart, dropped 1 cm onto a stationary cone
    m = model()
    rng = np.random.default_rng(1)
    xy = [(-0.03 + 0.052 * i, -0.08 + 0.052 * j) for i in range(5) for j in range(4)]
    ground = resting(m, xy)
    positions = np.vstack([ground + [0.0, 0.0, 0.01], ground + [0.0, 0.0, 0.062]])
    positions += rng.normal(0.0, 0.002, positions.shape)
    sim = Simulator(SimParams(model=m), RotationProfile.from_table(STILL))
    sim.add(positions, np.zeros_like(positions))
    energy = []
    for k in range(1, 61):
        result = sim.advance_to(0.02 * k)
        assert not result.failures and not len(result.exits)
        _, qdot, _ = sim.world()
        energy.append(0.5 * 0.125 * float((qdot ** 2).sum()))
    q, _, _ = sim.world()
    dist = np.linalg.norm(q[:, None] - q[None], axis=2) + np.eye(40)
    assert dist.min() > 2.0 * m.product.s_c  # never closer than the compression radii
    assert q[:, 2].max() < positions[:, 2].max()  # nothing thrown up
    assert energy[-1] < 1e-3 * max(energy) and energy[-1] < energy[-10] < energy[-20]


def crowd_ring(m: ModelParams, count: int, spacing: float) -> np.ndarray:
    """Return count pieces resting in touching rows on the cone's ring, (count, 3) m."""
    xy = []
    radius = 0.04
    while len(xy) < count:
        assert radius < 0.2
        slots = int(2.0 * np.pi * radius / spacing)
        for k in range(min(slots, count - len(xy))):
            angle = 2.0 * np.pi * k / slots + 0.3 * radius
            xy.append((radius * np.cos(angle), radius * np.sin(angle)))
        radius += 0.9 * spacing
    return resting(m, xy)


def test_a_large_island_is_coupled_as_one() -> None:
    # 50 touching pieces in rows around the tip: one island, in the band order
    m = model()
    positions = crowd_ring(m, 50, 0.047)
    sim = Simulator(SimParams(model=m), RotationProfile.from_table(TURNING))
    sim.add(positions, np.zeros_like(positions))
    largest = 0
    for k in range(1, 11):
        result = sim.advance_to(0.02 * k)
        assert not result.failures
        largest = max(largest, result.stats.largest_island)
        q, _, _ = sim.world()
        dist = np.linalg.norm(q[:, None] - q[None], axis=2) + np.eye(q.shape[0])
        assert dist.min() > 2.0 * m.product.s_c
    assert largest == 50
    # without contact the same crowd overlaps: the check above can fail
    alone = Simulator(SimParams(model=model(enabled=False)), RotationProfile.from_table(TURNING))
    alone.add(positions, np.zeros_like(positions))
    alone.advance_to(0.2)
    assert not np.array_equal(alone.state.y, sim.state.y)


def test_an_island_larger_than_max_island_is_cut_and_the_cut_pairs_counted() -> None:
    from cone_feeder_sim.physics.simulation import cut_island
    m = model()
    positions = crowd_ring(m, 50, 0.047)
    pairs = contact_pairs_of(positions)
    [(members, local)] = islands_of(50, pairs)
    parts, dropped = cut_island(members, local, 20)
    assert [len(p) for p, _ in parts] == [20, 20, 10]
    assert sorted(np.concatenate([p for p, _ in parts]).tolist()) == list(range(50))
    kept = {tuple(sorted((int(p[a]), int(p[b])))) for p, own in parts for a, b in own}
    assert kept <= {tuple(pair) for pair in pairs.tolist()}
    assert len(kept) + dropped == len(pairs) and 0 < dropped < len(pairs) // 2
    # the simulation cuts, counts and keeps going; with a limit above the island, nothing
    results = {}
    for limit in (20, 50):
        sim = Simulator(SimParams(model=model(max_island=limit)),
                        RotationProfile.from_table(TURNING))
        sim.add(positions, np.zeros_like(positions))
        result = sim.advance_to(0.02)
        assert not result.failures and result.stats.largest_island == 50
        results[limit] = result.stats.pairs_left_out
    assert results[50] == 0 and results[20] > 0


def contact_pairs_of(positions: np.ndarray) -> np.ndarray:
    from cone_feeder_sim.physics.neighbours import contact_pairs
    count = positions.shape[0]
    return contact_pairs(positions, contact_reach(np.tile(product_row(ProductParams()),
                                                          (count, 1))))


def test_the_band_order_solves_what_the_given_order_solves() -> None:
    # one island advanced with the reverse Cuthill-McKee band and with the full matrix
    from cone_feeder_sim.physics.band import band_order
    from cone_feeder_sim.physics.integrator import STAT_WIDTH
    from cone_feeder_sim.physics.islands import advance_island
    from cone_feeder_sim.physics.neighbours import contact_pairs
    m = model()
    params = SimParams(model=m)
    positions = crowd_ring(m, 30, 0.047)
    pairs = contact_pairs(positions, contact_reach(np.tile(product_row(m.product), (30, 1))))
    [(members, local)] = islands_of(30, pairs)
    assert members.size == 30
    pos, width = band_order(30, local)
    assert width < 12  # a ring of touching pieces is narrow in that order
    y0 = np.zeros((30, 9))
    y0[:, 0:3] = positions
    products = np.tile(product_row(m.product), (30, 1))
    seg_t, seg_omega, seg_domega = RotationProfile.from_table(TURNING).segments(0.0, 0.05)
    solver = params.solver
    out = []
    for order, kl in [(pos, 3 * width + 2), (np.arange(30), 89)]:
        y = y0.copy()
        stats = np.zeros(STAT_WIDTH, dtype=np.int64)
        code, t, _, _ = advance_island(
            y, products, local, order, kl, params.global_row, seg_t, seg_omega, seg_domega,
            m.r, 1e-4, solver.rtol, params.atol, solver.h_min, solver.h_max, solver.h_init,
            solver.max_steps, m.interactions.pull_off, stats)
        assert t == pytest.approx(0.05) and stats[0] > 5
        out.append(y)
    np.testing.assert_allclose(out[0][:, 0:3], out[1][:, 0:3], rtol=0.0, atol=1e-9)
