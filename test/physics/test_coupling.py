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

"""The multirate coupling of pieces that touch, against the coupled reference."""

from cone_feeder_sim.errors import ParameterError
from cone_feeder_sim.physics import (band, contact, coupling, integrator, islands, model,
                                     neighbours, rosenbrock)
from cone_feeder_sim.physics.params import InteractionParams, ModelParams, ProductParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import resting_height, SimParams, Simulator
from cone_feeder_sim.weigher import combination
import numba
import numpy as np
import pytest
from reference_contacts import (
    crowd_trajectory, four_touching_at, FOUR_TOUCHING_TABLE, FOUR_TOUCHING_XY, rim_crowd_exits)
from reference_model import table2_params

STILL = [[0.0, 0.0], [100.0, 0.0]]
TURNING = [[0.0, 0.0], [0.4, -8.0], [5.0, -8.0]]
HEAVY = ProductParams(m=0.2, s0=0.03)  # another product: heavier and larger


def multirate(tolerance: float = 1e-6, enabled: bool = True,
              max_island: int = 48) -> ModelParams:
    return ModelParams(interactions=InteractionParams(
        enabled=enabled, coupling='multirate', coupling_tolerance=tolerance,
        max_island=max_island))


def resting(m: ModelParams, xy: list) -> np.ndarray:
    xy = np.asarray(xy, dtype=float)
    z = [resting_height(m, m.product, a, b) for a, b in xy]
    return np.column_stack([xy, z])


def run(m: ModelParams, table: list, positions: np.ndarray, t_end: float, velocities=None,
        products=None, dt: float = 0.02) -> tuple[Simulator, dict, list]:
    sim = Simulator(SimParams(model=m), RotationProfile.from_table(table))
    sim.add(positions, velocities, products)
    exits, results = {}, []
    for k in range(1, int(round(t_end / dt)) + 1):
        result = sim.advance_to(dt * k)
        assert not result.failures
        results.append(result)
        exits.update({int(i): (float(t), float(a)) for i, t, a in
                      zip(result.exits.ids, result.exits.t, result.exits.angle_deg)})
    return sim, exits, results


def test_every_kernel_a_tick_runs_releases_the_gil() -> None:
    modules = (band, contact, coupling, integrator, islands, model, neighbours, rosenbrock,
               combination)
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


def test_a_free_flight_collision_keeps_momentum_and_follows_the_reference() -> None:
    # well above the cone: a default piece hits a heavier, larger one; the two pieces take
    # different steps inside each coupling interval
    v = 1.0
    positions = np.array([[-0.065, 0.0, 20.0], [0.0, 0.0, 20.0]])
    velocities = np.array([[v, 0.0, 0.0], [0.0, 0.0, 0.0]])
    t_out = np.linspace(0.01, 0.3, 30)
    ref = crowd_trajectory([table2_params(1), table2_params(1, m=0.2, s0=0.03)],
                           np.hstack([positions, velocities, np.zeros((2, 3))]), STILL, 0.3,
                           t_eval=t_out)
    ref_y = ref.y.reshape(2, 9, -1)
    m = ModelParams(interactions=InteractionParams(enabled=True, pull_off=0.0,
                                                   coupling='multirate',
                                                   coupling_tolerance=1e-9))
    sim = Simulator(SimParams(model=m), RotationProfile.from_table(STILL))
    sim.add(positions, velocities, [ProductParams(), HEAVY])
    worst, intervals, own_steps = 0.0, 0, 0
    for t in t_out:
        result = sim.advance_to(float(t))
        intervals += result.stats.coupling_intervals
        own_steps += result.stats.accepted
        q, qdot, _ = sim.world()
        momentum = 0.125 * qdot[0, :2] + 0.2 * qdot[1, :2]
        assert np.abs(momentum - [0.125 * v, 0.0]).max() < 1e-15  # to round-off
        worst = max(worst, float(np.abs(q - ref_y[:, 0:3, len([s for s in t_out if s < t])])
                                 .max()))
    assert intervals > 10 and own_steps > 2 * intervals  # the pieces stepped on their own
    # measured 1.13e-5 m (the exact coupling: 2e-7); first order: the error halves with
    # each tenfold tighter tolerance (doc/model.md, "Multirate coupling")
    assert worst < 2e-5  # m
    assert 0.0 < (qdot[1, 0] - qdot[0, 0]) / v < 0.3  # inelastic


def test_the_error_shrinks_with_the_coupling_tolerance() -> None:
    # four touching pieces on a cone spun up to -6 rad/s, 0.4 s, against Radau at 1e-10
    m = multirate()
    positions = resting(m, FOUR_TOUCHING_XY)
    table = [list(r) for r in FOUR_TOUCHING_TABLE]
    ref = four_touching_at(tuple(map(tuple, positions.tolist())))
    errors = []
    for tolerance in (1e-5, 1e-7, 1e-9):
        sim, _, _ = run(multirate(tolerance), table, positions, 0.4)
        errors.append(float(np.abs(sim.world()[0] - ref).max()))
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 2e-5  # m


def test_pieces_out_of_reach_move_exactly_as_without_interactions() -> None:
    m = multirate()
    positions = resting(m, [[0.05, 0.0], [-0.1, 0.05], [0.0, -0.15]])
    a, _, _ = run(m, TURNING, positions, 0.6)
    b, _, _ = run(multirate(enabled=False), TURNING, positions, 0.6)
    np.testing.assert_array_equal(a.state.y, b.state.y)


def crowd(m: ModelParams, count: int) -> np.ndarray:
    """Return count pieces resting in touching rows (spacing 48 mm) on a still cone."""
    xy = [(-0.1 + 0.048 * i, -0.1 + 0.048 * j) for i in range(5) for j in range(5)]
    return resting(m, xy[:count])


def test_no_pair_is_left_out_of_a_crowd_larger_than_max_island() -> None:
    m = multirate(max_island=8)
    sim, _, results = run(m, STILL, crowd(m, 25), 0.2)
    assert max(r.stats.largest_island for r in results) == 25
    assert sum(r.stats.pairs_left_out for r in results) == 0
    q, _, _ = sim.world()
    dist = np.linalg.norm(q[:, None] - q[None], axis=2) + np.eye(25)
    assert dist.min() > 2.0 * m.product.s_c


def test_the_result_is_the_same_on_any_number_of_threads() -> None:
    m = multirate()
    positions = crowd(m, 12) + [0.0, 0.0, 0.004]  # dropped 4 mm onto each other's reach
    available = numba.config.NUMBA_NUM_THREADS
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        a, _, _ = run(m, TURNING, positions, 0.1)
        numba.set_num_threads(min(2, available))
        b, _, _ = run(m, TURNING, positions, 0.1)
    finally:
        numba.set_num_threads(threads)
    np.testing.assert_array_equal(a.state.y, b.state.y)


@pytest.mark.xfail(strict=True, reason='multirate misses the 0.1 deg bar: measured 0.55 deg at '
                   'coupling_tolerance 1e-8 (first-order split, doc/model.md)')
def test_touching_pieces_exit_where_the_coupled_reference_says() -> None:
    # six touching pieces near the rim, the cone spun up to -8 rad/s (test_islands' case)
    m = multirate(1e-8)
    positions = resting(m, [[0.15, 0.0], [0.19, 0.02], [0.16, 0.045], [0.12, 0.02],
                            [0.20, -0.025], [0.14, -0.04]])
    _, exits, _ = run(m, TURNING, positions, 1.1)
    reference = rim_crowd_exits(tuple(map(tuple, positions.tolist())))
    assert sorted(exits) == sorted(reference) == list(range(6))
    for i in range(6):
        assert abs(exits[i][0] - reference[i][0]) < 2e-3  # s
        assert abs((exits[i][1] - reference[i][1] + 180.0) % 360.0 - 180.0) < 0.1  # deg
