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
The couplings of pieces that touch: island (the default) and multirate against exact.

The pair law itself is checked against closed forms in test_contact and test_collisions;
here crowds on the cone: the two couplings agree, momentum and histories are kept, results
do not depend on the thread count, mirrored crowds mirror and a pile settles.
"""

from pathlib import Path

from cone_feeder_sim.errors import ParameterError
from cone_feeder_sim.physics import (coupling, exact, integrator, island, model, neighbours,
                                     rosenbrock)
from cone_feeder_sim.physics.contact import cohesion, law, normal, tangential
from cone_feeder_sim.physics.exact import islands_of
from cone_feeder_sim.physics.params import InteractionParams, ModelParams, SolverParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    remove_particles, resting_height, SimParams, Simulator)
from cone_feeder_sim.weigher import combination
import numba
import numpy as np
import pytest
from workers import with_threads

STILL = [[0.0, 0.0], [100.0, 0.0]]
TURNING = [[0.0, 0.0], [0.4, -8.0], [5.0, -8.0]]
REVERSING = [[0.0, 0.0], [0.2, 6.0], [0.3, 6.0], [0.5, -6.0], [2.0, -6.0]]
#: nine touching pieces in a square near the rim, three more dropped onto them
CROWD_XY = [[0.10 + 0.046 * i, 0.046 * j] for i in range(3) for j in (-1, 0, 1)]


def contact(coupling: str = 'island', enabled: bool = True, **keys: float) -> ModelParams:
    return ModelParams(interactions=InteractionParams(enabled=enabled, coupling=coupling,
                                                      **keys))


def resting(m: ModelParams, xy: list) -> np.ndarray:
    return np.array([[a, b, resting_height(m, m.product, a, b)] for a, b in xy])


def crowd(m: ModelParams) -> np.ndarray:
    """Return the crowd's 12 positions (m): nine resting, three 4 cm above them."""
    return np.vstack([resting(m, CROWD_XY), resting(m, CROWD_XY[:3]) + [0.0, 0.023, 0.04]])


def run(m: ModelParams, table: list, positions: np.ndarray, t_end: float, dt: float = 0.02,
        solver: SolverParams | None = None) -> tuple[Simulator, list]:
    sim = Simulator(SimParams(model=m, solver=solver or SolverParams()),
                    RotationProfile.from_table(table))
    sim.add(positions)
    results = []
    for k in range(1, int(round(t_end / dt)) + 1):
        result = sim.advance_to(dt * k)
        assert not result.failures
        results.append(result)
    return sim, results


def test_every_kernel_a_tick_runs_releases_the_gil() -> None:
    modules = (cohesion, law, normal, tangential, coupling, exact, island, integrator, model,
               neighbours, rosenbrock, combination)
    kernels = [(m.__name__, name, f) for m in modules for name, f in vars(m).items()
               if isinstance(f, numba.core.registry.CPUDispatcher)]
    assert len(kernels) > 30
    holding = [f'{m}.{name}' for m, name, f in kernels if not f.targetoptions.get('nogil')]
    assert not holding


def test_the_coupling_is_validated_with_its_key_named() -> None:
    with pytest.raises(ParameterError, match='interactions.coupling'):
        InteractionParams(coupling='fast')
    with pytest.raises(ParameterError, match='interactions.coupling_tolerance'):
        InteractionParams(coupling_tolerance=0.0)


def test_islands_are_the_connected_pieces() -> None:
    pairs = np.array([[0, 3], [3, 5], [1, 2], [6, 8], [5, 7]])
    got = [(list(members), rows.tolist()) for members, _, rows in islands_of(9, pairs)]
    assert got == [([0, 3, 5, 7], [0, 1, 4]), ([1, 2], [2]), ([6, 8], [3])]
    assert islands_of(4, np.empty((0, 2), dtype=np.int64)) == []


@pytest.mark.parametrize('coupling', ['island', 'multirate', 'exact'])
def test_pieces_out_of_reach_move_exactly_as_without_interactions(coupling: str) -> None:
    m = contact(coupling)
    positions = resting(m, [[0.05, 0.0], [-0.1, 0.05], [0.0, -0.15]])
    a, _ = run(m, TURNING, positions, 0.6)
    b, _ = run(contact(enabled=False), TURNING, positions, 0.6)
    np.testing.assert_array_equal(a.state.y, b.state.y)


@pytest.fixture(scope='module')
def crowds() -> dict[str, np.ndarray]:
    """Return the crowd after 0.4 s on the reversing cone: each coupling, and off."""
    out = {}
    for name, m in (('island', contact()), ('multirate', contact('multirate')),
                    ('exact', contact('exact')), ('off', contact(enabled=False))):
        sim, results = run(m, REVERSING, crowd(m), 0.4)
        q = np.full((12, 3), np.nan)
        q[sim.state.ids] = sim.world()[0]
        out[name] = q
        out[f'{name} results'] = results
        out[f'{name} sim'] = sim
    return out


@pytest.mark.parametrize('coupling', ['island', 'multirate'])
def test_the_couplings_agree_with_the_exact_one(crowds: dict, coupling: str) -> None:
    # positions after 0.4 s differ by at most 1 % of the difference contact makes
    effect = np.nanmax(np.abs(crowds['exact'] - crowds['off']))
    error = np.nanmax(np.abs(crowds[coupling] - crowds['exact']))
    assert effect > 0.02  # m: the crowd pushes and drags its pieces
    assert error < 0.01 * effect


def test_multirate_pieces_take_their_own_steps_inside_the_intervals(crowds: dict) -> None:
    intervals = sum(r.stats.coupling_intervals for r in crowds['multirate results'])
    own = sum(r.stats.accepted for r in crowds['multirate results'])
    assert own > 2 * intervals  # the pieces took their own steps inside the intervals
    assert sum(r.stats.coupling_forced for r in crowds['multirate results']) == 0


def test_island_steps_are_counted_and_fast_pieces_refined(crowds: dict) -> None:
    results = crowds['island results']
    steps = sum(r.stats.coupling_intervals for r in results)
    assert steps > 20  # common steps of the islands
    assert sum(r.stats.coupling_rejected for r in results) < steps
    assert sum(r.stats.refined for r in results) > 0  # the dropped pieces hit the crowd
    assert all(r.stats.refined == 0 for r in crowds['exact results'])


@pytest.mark.parametrize('coupling', ['island', 'multirate'])
def test_every_pair_is_kept_and_histories_last_from_tick_to_tick(crowds: dict,
                                                                 coupling: str) -> None:
    sim = crowds[f'{coupling} sim']
    state = sim.state
    assert state.contact_ids.shape[0] >= 8 and state.contact_history.shape == (
        state.contact_ids.shape[0], 3)
    assert (state.contact_ids[:, 0] < state.contact_ids[:, 1]).all()
    assert np.abs(state.contact_history).max() > 1e-5  # m: the cone turned under them
    q, _, _ = sim.world()
    index = {int(i): k for k, i in enumerate(state.ids)}
    for a, b in state.contact_ids:  # every kept history belongs to a touching pair
        assert np.linalg.norm(q[index[int(a)]] - q[index[int(b)]]) < 0.05
    # a piece that leaves takes its contacts' histories with it
    gone = int(state.contact_ids[0, 0])
    left = remove_particles(state, [gone])
    assert not np.isin(left.contact_ids, [gone]).any()
    assert left.contact_ids.shape[0] < state.contact_ids.shape[0]


def test_momentum_of_a_crowd_in_free_flight_is_kept_to_round_off() -> None:
    # the crowd lifted 20 m above a still cone, thrown together: only the pairs act
    m = contact()
    positions = crowd(m) + [0.0, 0.0, 20.0]
    rng = np.random.default_rng(2)
    velocities = rng.normal(0.0, 0.3, positions.shape)
    sim = Simulator(SimParams(model=m), RotationProfile.from_table(STILL))
    sim.add(positions, velocities)
    _, qdot0, _ = sim.world()
    touching = 0
    for k in range(1, 11):
        result = sim.advance_to(0.01 * k)
        touching = max(touching, result.stats.contacts)
        _, qdot, _ = sim.world()
        np.testing.assert_allclose(qdot[:, :2].sum(axis=0), qdot0[:, :2].sum(axis=0),
                                   rtol=0.0, atol=1e-14)
    assert touching >= 5


def turning_crowd() -> dict[str, np.ndarray]:
    """Return the state and contact histories of the crowd after 0.1 s on the turning cone."""
    m = contact()
    result, _ = run(m, TURNING, crowd(m), 0.1)
    return {'y': result.state.y, 'history': result.state.contact_history}


def test_the_result_is_the_same_on_any_number_of_threads(tmp_path: Path) -> None:
    # one thread here; three in a process of its own (whatever this one or the machine has)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = turning_crowd()
    finally:
        numba.set_num_threads(threads)
    three = with_threads(3, 'physics.test_coupling', 'turning_crowd', tmp_path / 'three.npz')
    assert one['history'].shape[0] > 0
    np.testing.assert_array_equal(three['y'], one['y'])
    np.testing.assert_array_equal(three['history'], one['history'])


def test_a_mirrored_crowd_under_mirrored_rotation_mirrors() -> None:
    m = contact()
    positions = crowd(m)
    a, _ = run(m, REVERSING, positions, 0.3)
    b, _ = run(m, [[t, -w] for t, w in REVERSING], positions * [1.0, -1.0, 1.0], 0.3)
    np.testing.assert_allclose(b.world()[0], a.world()[0] * [1.0, -1.0, 1.0], atol=1e-9)


def test_a_pile_of_40_settles() -> None:
    # 40 pieces in two layers 5.2 cm apart, dropped 1 cm onto a stationary cone
    m = contact()
    rng = np.random.default_rng(1)
    xy = [(-0.03 + 0.052 * i, -0.08 + 0.052 * j) for i in range(5) for j in range(4)]
    ground = resting(m, xy)
    positions = np.vstack([ground + [0.0, 0.0, 0.01], ground + [0.0, 0.0, 0.062]])
    positions += rng.normal(0.0, 0.002, positions.shape)
    sim = Simulator(SimParams(model=m), RotationProfile.from_table(STILL))
    sim.add(positions, np.zeros_like(positions))
    energy = []
    for k in range(1, 51):
        result = sim.advance_to(0.02 * k)
        assert not result.failures and not len(result.exits)
        _, qdot, _ = sim.world()
        energy.append(0.5 * 0.125 * float((qdot ** 2).sum()))
    q, _, _ = sim.world()
    assert q[:, 2].max() < positions[:, 2].max()  # nothing thrown up
    assert energy[-1] < 1e-2 * max(energy) and energy[-1] < energy[-10] < energy[-20]
    assert result.stats.contacts >= 20  # the upper layer rests on the lower one


def test_over_six_seconds_the_same_pieces_exit_into_the_same_channels() -> None:
    # 30 pieces strewn over the cone, reversing every second at 7 rad/s: the same pieces
    # exit into the same channels (measured: 16 pieces, angles within 0.12 deg of each
    # other, both couplings at the default tolerances)
    table = [[0.0, 0.0]] + [[0.5 + k, (-1) ** k * 7.0] for k in range(7)]
    rng = np.random.default_rng(4)
    xy: list = []
    while len(xy) < 30:
        radius, angle = rng.uniform(0.05, 0.19), rng.uniform(0.0, 2.0 * np.pi)
        p = np.array([radius * np.cos(angle), radius * np.sin(angle)])
        if all(np.linalg.norm(p - q) > 0.048 for q in xy):
            xy.append(p)
    exits = {}
    for name in ('island', 'exact'):
        m = contact(name)
        sim = Simulator(SimParams(model=m), RotationProfile.from_table(table))
        sim.add(resting(m, [list(p) for p in xy]))
        exits[name] = {}
        for k in range(1, 301):
            result = sim.advance_to(0.02 * k)
            assert not result.failures
            exits[name].update({int(i): float(a) for i, a in
                                zip(result.exits.ids, result.exits.angle_deg)})
    assert exits['island'].keys() == exits['exact'].keys() and len(exits['exact']) >= 10
    layout = contact().channels
    for i, angle in exits['exact'].items():
        assert abs((exits['island'][i] - angle + 180.0) % 360.0 - 180.0) < 0.2
        assert layout.channel_of(np.array([exits['island'][i]])) == layout.channel_of(
            np.array([angle]))
