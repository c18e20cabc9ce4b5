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
Physics sanity of the production simulator against known answers and symmetries.

Only the production simulator is used here, with its default solver settings. The
expected values are written out from statics and kinematics in this file:

* a piece resting on a stationary cone stays put (and creeps at the speed the
  regularised Coulomb law predicts);
* a slow spin-up makes a piece slip at the cone speed that the static friction balance
  predicts;
* a piece dropped on the tip or onto the cone lands, loses its energy and rests at the
  gap where the constraint force carries its weight;
* mirror and rotational symmetry of the whole model;
* pieces do not interact: several products at once give the per-piece results of each
  piece alone.
"""

import math

from cone_feeder_sim.physics.params import ModelParams, ProductParams, SolverParams
from cone_feeder_sim.physics.rotation import rotate_z, RotationProfile
from cone_feeder_sim.physics.simulation import ExitEvents, resting_height, SimParams, Simulator
import numpy as np
import pytest

import reference_model

CW = -10.47     # rad/s, the paper's clockwise rotation (about 100 rpm)
CCW = 10.47     # rad/s
TILT = math.radians(7.5)
G = 9.81
TABLE1_STARTS = reference_model.TABLE1_STARTS
REVERSING = [[0.0, 0.0], [0.4, CW], [1.0, CW], [1.4, CCW]]


def _simulator(table: list[list[float]], model: ModelParams | None = None) -> Simulator:
    """Return a simulator with default solver settings and the given rotation table."""
    return Simulator(SimParams(model=model or ModelParams(), solver=SolverParams()),
                     RotationProfile.from_table(table))


def _gap_at_rest(product: ProductParams, normal: float) -> float:
    """
    Return the gap s (m) at which the constraint force carries a normal load.

    The constraint force along e_Fc is R_a(s) F_c(0) = R_a(s) r_f / 2 with
    R_a(s) = (1 - tanh(r_t (s - r_c))) / 2; solving R_a r_f / 2 = normal gives
    s = r_c + artanh(1 - 4 normal / r_f) / r_t.

    :param product: The product (r_f, r_t, r_c).
    :param normal: The load R_a F_c must carry (N).
    :return: The gap (m).
    """
    return product.r_c + math.atanh(1.0 - 4.0 * normal / product.r_f) / product.r_t


def _slip_omega(mu: float, rho: float) -> float:
    """
    Return |omega| (rad/s) at which a piece at radius rho starts to slide outwards.

    Static balance on the slope (tilt a) of gravity, centrifugal force and friction
    mu * (true normal force): omega^2 = g (mu cos a - sin a) / (rho (cos a + mu sin a)).
    """
    cos_a, sin_a = math.cos(TILT), math.sin(TILT)
    return math.sqrt(G * (mu * cos_a - sin_a) / (rho * (cos_a + mu * sin_a)))


# ---------------------------------------------------------------------------------------
# A piece at rest on a stationary cone
# ---------------------------------------------------------------------------------------

@pytest.mark.parametrize('d', [30.0, 225.0, 750.0], ids=lambda d: f'd{d:g}')
def test_piece_at_rest_on_stationary_cone_stays_put(d: float) -> None:
    """A piece laid at its resting gap on a stationary cone moves less than 1 mm in 10 s."""
    model = ModelParams()
    product = ProductParams(d=d)
    start = np.array([0.11, 0.02, resting_height(model, product, 0.11, 0.02)])
    sim = _simulator([[0.0, 0.0]], model)
    sim.add(start, None, products=[product])
    worst = 0.0
    for k in range(1, 11):
        result = sim.advance_to(float(k))
        assert not result.failures and len(result.exits) == 0, (
            f'piece lost at t = {k} s: {result.failures} {result.exits}')
        q, _, _ = sim.world()
        worst = max(worst, float(np.linalg.norm(q[0] - start)))
    assert worst < 1.0e-3, f'piece moved {worst:.3e} m in 10 s (bar 1e-3 m)'


def test_resting_piece_creeps_at_regularised_coulomb_speed() -> None:
    """
    The regularised Coulomb law has no true sticking: on the slope a piece creeps.

    With F_C = mu_C N tanh(v / v_C) (eq. 8) the friction balances the downhill pull
    m g sin(a) only at a non-zero slip speed v* = v_C artanh(m g sin(a) / (mu_C N)),
    N = R_a F_c = m g cos(a)^2 at rest (the Stribeck and viscous terms nearly cancel at
    these speeds for d = 225 and are left out). The filter (eqs. 13-14) cannot freeze
    the piece either: a(v) > 0 for any v > 0. The Table II values give v* = 7.9 um/s,
    0.08 mm in 10 s, 1 mm in about 2 minutes. Checked: the speed over 5-10 s within 10 %
    of v*, and the direction (downhill: outwards and down).
    """
    model = ModelParams()
    product = ProductParams(d=225.0)
    x0, y0 = 0.11, 0.02
    sim = _simulator([[0.0, 0.0]], model)
    sim.add([x0, y0, resting_height(model, product, x0, y0)], None, products=[product])
    sim.advance_to(5.0)
    q5, _, _ = sim.world()
    sim.advance_to(10.0)
    q10, qdot, _ = sim.world()
    weight = product.m * model.g
    normal = weight * math.cos(TILT) ** 2
    v_star = product.v_C * math.atanh(weight * math.sin(TILT) / (product.mu_C * normal))
    step = q10[0] - q5[0]
    speed = float(np.linalg.norm(step)) / 5.0
    assert speed == pytest.approx(v_star, rel=0.1), (
        f'creep speed {speed:.4e} m/s, predicted {v_star:.4e} m/s')
    assert float(np.linalg.norm(qdot[0])) == pytest.approx(v_star, rel=0.1)
    radial = np.array([x0, y0]) / math.hypot(x0, y0)
    assert float(step[0:2] @ radial) > 0.99 * math.cos(TILT) * float(np.linalg.norm(step)), (
        f'creep step {step.tolist()} m is not radially outwards')
    assert step[2] < 0.0, f'creep step {step.tolist()} m is not downhill'


# ---------------------------------------------------------------------------------------
# Slip onset during a slow spin-up
# ---------------------------------------------------------------------------------------

SPIN_UP_RHO = 0.11
SPIN_UP_TIME = 40.0          # s, omega 0 -> -10 rad/s: 0.25 rad/s^2
SPIN_UP_SAMPLE = 0.02        # s, omega resolution 0.005 rad/s
SLIP_DISTANCE = 5.0e-3       # m, relative to the cone


@pytest.mark.parametrize('d', [30.0, 225.0, 750.0], ids=lambda d: f'd{d:g}')
def test_slow_spin_up_slips_between_static_predictions(d: float) -> None:
    """
    A piece resting at rho = 0.11 m slips when |omega| reaches the friction limit.

    Slip is defined as: the piece has moved 5 mm relative to the cone (its position in
    cone axes, rotate_z(q, -phi(t)), is 5 mm from where it was laid). The cone spins up
    clockwise from 0 to 10 rad/s in 40 s (0.25 rad/s^2, quasi-static: the Euler force
    is under 1 % of the friction demand), sampled every 20 ms.

    The static balance omega^2 = g (mu cos a - sin a) / (rho (cos a + mu sin a)) with the
    true normal force gives 7.59 rad/s for mu_C = 0.85 and 8.23 rad/s for mu_S = 0.99.
    The model's friction uses N = R_a F_c, the magnitude of the non-normalised
    e_Fc (|e_Fc| = 1/cos a), i.e. cos(a) times the true normal force: its own bracket
    is [omega(mu_C cos a), omega(mu_S cos a)] = [7.555, 8.193] rad/s, which is what is
    asserted. Observed: slip at 7.75-7.80 rad/s for d = 30, 225 and 750 (inside both
    brackets; 1 mm of motion comes up to 0.05 rad/s earlier). The slip must also be
    outwards (the radius grows by at least half the slip distance).
    """
    model = ModelParams()
    product = ProductParams(d=d)
    start = np.array([SPIN_UP_RHO, 0.0,
                      resting_height(model, product, SPIN_UP_RHO, 0.0)])
    profile = RotationProfile.from_table([[0.0, 0.0], [SPIN_UP_TIME, -10.0]])
    sim = Simulator(SimParams(model=model, solver=SolverParams()), profile)
    sim.add(start, None, products=[product])
    lower = _slip_omega(product.mu_C * math.cos(TILT), SPIN_UP_RHO)
    upper = _slip_omega(product.mu_S * math.cos(TILT), SPIN_UP_RHO)
    slip_omega = None
    steps = int(round(SPIN_UP_TIME / SPIN_UP_SAMPLE))
    for k in range(1, steps + 1):
        result = sim.advance_to(k * SPIN_UP_SAMPLE)
        assert not result.failures, f'integration failed: {result.failures}'
        assert len(result.exits) == 0, (
            f'piece left at t = {result.exits.t} s before it was seen to slip')
        q, _, _ = sim.world()
        in_cone = rotate_z(q[0], -profile.angle(sim.t))
        moved = float(np.linalg.norm(in_cone - start))
        if moved > SLIP_DISTANCE:
            slip_omega = abs(profile.omega(sim.t))
            outward = math.hypot(in_cone[0], in_cone[1]) - SPIN_UP_RHO
            assert outward > 0.5 * SLIP_DISTANCE, (
                f'slip of {moved:.4f} m but the radius grew only {outward:.4f} m')
            break
    assert slip_omega is not None, f'no slip up to |omega| = 10 rad/s (bracket {upper:.3f})'
    assert lower <= slip_omega <= upper, (
        f'slip at |omega| = {slip_omega:.3f} rad/s, outside [{lower:.3f}, {upper:.3f}] rad/s '
        f'(mu_C cos a, mu_S cos a)')


# ---------------------------------------------------------------------------------------
# Drops: on the tip, and onto the cone
# ---------------------------------------------------------------------------------------

DROP_SAMPLE = 0.005     # s


def _drop(model: ModelParams, product: ProductParams, start: list[float], omega: float,
          t_end: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Drop a piece from rest (world velocity 0) and sample it every DROP_SAMPLE seconds.

    :return: Times (K,), positions (K, 3), velocities (K, 3); the run must keep the piece.
    """
    sim = _simulator([[0.0, omega]], model)
    sim.add(start, np.zeros(3), products=[product])
    times, positions, velocities = [0.0], [np.array(start, dtype=float)], [np.zeros(3)]
    for k in range(1, int(round(t_end / DROP_SAMPLE)) + 1):
        result = sim.advance_to(k * DROP_SAMPLE)
        assert not result.failures, f'integration failed: {result.failures}'
        assert len(result.exits) == 0, f'piece left the cone at t = {result.exits.t} s'
        q, qdot, q_d = sim.world()
        assert np.all(np.isfinite(q)) and np.all(np.isfinite(qdot)) and np.all(
            np.isfinite(q_d)), f'non-finite state at t = {sim.t} s'
        times.append(sim.t)
        positions.append(q[0].copy())
        velocities.append(qdot[0].copy())
    return np.array(times), np.array(positions), np.array(velocities)


@pytest.mark.parametrize('friction_direction', ['full', 'tangential'])
@pytest.mark.parametrize('omega', [0.0, CW], ids=['stationary', 'cw'])
def test_drop_exactly_on_tip(omega: float, friction_direction: str) -> None:
    """
    A piece dropped exactly on the tip (x = y = 0) lands, stays finite and on the axis.

    At rho = 0 the constraint divides by rho (eqs. 29, 36); the model regularises it with
    tip_epsilon. On the axis every horizontal term is a product with x or y (e_Fc =
    (0, 0, 1), omega x q = 0), so the piece cannot leave the axis, on a stationary or a
    turning cone: in exact arithmetic, and in floating point too, since those products
    of zeros are exactly zero and nothing else breaks the symmetry. A perturbation of
    roundoff size could not grow quickly either: friction holds a piece on the nearly
    flat regularised cap (test_drop_next_to_tip_stays_near_axis). The fair assertion is
    therefore a radius below 1 nm throughout (observed: exactly 0), rather than a loose
    "stays near the axis". Also asserted: free fall until contact (within 1 um), it
    lands (sinks below its resting height) without falling through the tip, rebounds
    less than 10 % of the drop, and moves slower than 1 mm/s after 2 s.

    The resting gap on the axis carries the full weight (|e_Fc| = 1 there), above the
    regularised tip h (1 - tip_epsilon / r). With tangential friction the piece settles
    there to 1 um. With the default full 3-D relative velocity, friction also opposes
    the normal motion: it sticks while the piece is still pressed in after the impact and
    holds it about 1.7 mm below the resting gap, releasing it only slowly (a property of
    that model reading, which the reference model shows too); the bar is then 3 mm below.
    """
    model = ModelParams(friction_direction=friction_direction)
    product = ProductParams()
    z_rest = (model.h * (1.0 - model.tip_epsilon / model.r)
              + _gap_at_rest(product, product.m * model.g))
    z0 = model.h + 0.05
    times, q, qdot = _drop(model, product, [0.0, 0.0, z0], omega, 2.0)
    rho = np.hypot(q[:, 0], q[:, 1])
    assert rho.max() <= 1.0e-9, f'piece left the axis: rho up to {rho.max():.3e} m'
    early = times <= 0.05       # gap still above 37 mm > s0: no contact force yet
    free_fall = z0 - 0.5 * model.g * times[early] ** 2
    fall_error = float(np.abs(q[early, 2] - free_fall).max())
    assert fall_error < 1.0e-6, f'free fall off by {fall_error:.3e} m'
    lowest = int(np.argmin(q[:, 2]))
    assert q[lowest, 2] < z_rest, (
        f'never landed: lowest z {q[lowest, 2]:.5f} m, resting height {z_rest:.5f} m')
    assert q[lowest, 2] > model.h * (1.0 - model.tip_epsilon / model.r), (
        f'fell through the tip: z = {q[lowest, 2]:.5f} m')
    rebound = float(q[lowest:, 2].max()) - z_rest
    assert rebound < 0.1 * (z0 - z_rest), (
        f'rebound {rebound:.4e} m above the resting height, drop {z0 - z_rest:.4e} m')
    speed = float(np.linalg.norm(qdot[-1]))
    assert speed < 1.0e-3, f'still moving at {speed:.3e} m/s after 2 s'
    sink = q[-1, 2] - z_rest
    if friction_direction == 'tangential':
        assert abs(sink) < 1.0e-6, (
            f'final z {q[-1, 2]:.6f} m, resting height {z_rest:.6f} m: {sink:.3e} m')
    else:
        assert -3.0e-3 < sink < 1.0e-6, (
            f'final z {q[-1, 2]:.6f} m, resting height {z_rest:.6f} m: {sink:.3e} m')


@pytest.mark.parametrize('omega', [0.0, CW], ids=['stationary', 'cw'])
def test_drop_next_to_tip_stays_near_axis(omega: float) -> None:
    """
    A piece dropped 1 um off the axis (a stand-in for broken symmetry) stays near it.

    Friction holds it on the regularised cap; it must stay within 0.1 mm of the axis.
    """
    model = ModelParams()
    _, q, _ = _drop(model, ProductParams(), [1.0e-6, 0.0, model.h + 0.05], omega, 2.0)
    rho = np.hypot(q[:, 0], q[:, 1])
    assert rho.max() < 1.0e-4, f'piece drifted to rho = {rho.max():.3e} m'


@pytest.mark.parametrize('friction_direction', ['full', 'tangential'])
def test_drop_onto_stationary_cone_comes_to_rest(friction_direction: str) -> None:
    """
    A piece dropped 3 cm onto a stationary cone lands, loses its energy and rests.

    Dropped from 30 mm above its resting height at rho = 0.112 m: it never goes through
    the surface, rebounds less than 10 % of the drop, ends with a kinetic energy below
    1e-6 of the drop's potential energy, and rests at the resting height: within 0.1 mm
    with tangential friction; with the default full friction within 3 mm below it (the
    friction holds the piece pressed in, see test_drop_exactly_on_tip).
    """
    model = ModelParams(friction_direction=friction_direction)
    product = ProductParams(d=225.0)
    x0, y0, drop = 0.1, 0.05, 0.03
    z_rest0 = resting_height(model, product, x0, y0)
    times, q, qdot = _drop(model, product, [x0, y0, z_rest0 + drop], 0.0, 1.5)
    surface = model.h * (1.0 - np.hypot(q[:, 0], q[:, 1]) / model.r)
    assert np.all(q[:, 2] > surface), 'piece went through the cone surface'
    lowest = int(np.argmin(q[:, 2]))
    assert q[lowest, 2] < z_rest0, f'never landed: lowest z {q[lowest, 2]:.5f} m'
    rebound = float(q[lowest:, 2].max()) - z_rest0
    assert rebound < 0.1 * drop, f'rebound {rebound:.4e} m after a drop of {drop} m'
    kinetic = 0.5 * product.m * float(qdot[-1] @ qdot[-1])
    potential = product.m * model.g * drop
    assert kinetic < 1.0e-6 * potential, (
        f'kinetic energy {kinetic:.3e} J after {times[-1]} s, drop energy {potential:.3e} J')
    z_rest = resting_height(model, product, q[-1, 0], q[-1, 1])
    sink = q[-1, 2] - z_rest
    if friction_direction == 'tangential':
        assert abs(sink) < 1.0e-4, f'final z {q[-1, 2]:.6f} m, resting {z_rest:.6f} m'
    else:
        assert -3.0e-3 < sink < 1.0e-4, f'final z {q[-1, 2]:.6f} m, resting {z_rest:.6f} m'


# ---------------------------------------------------------------------------------------
# Symmetries
# ---------------------------------------------------------------------------------------

def _run_sampled(table: list[list[float]], starts: np.ndarray,
                 products: list[ProductParams], times: np.ndarray
                 ) -> tuple[dict[int, tuple[float, float]], dict[tuple[int, int], np.ndarray]]:
    """
    Run pieces (moving with the cone at t = 0) and sample them.

    :return: exits {piece index: (t, angle_deg)} and states {(piece index, sample index):
        [q, qdot, Q_d] (9,)} of the pieces still on the cone at each sample time.
    """
    sim = _simulator(table)
    ids = sim.add(starts, None, products=products)
    index = {int(i): k for k, i in enumerate(ids)}
    exits: dict[int, tuple[float, float]] = {}
    states: dict[tuple[int, int], np.ndarray] = {}
    for j, t in enumerate(times):
        result = sim.advance_to(float(t))
        assert not result.failures, f'integration failed: {result.failures}'
        events: ExitEvents = result.exits
        for n in range(len(events)):
            exits[index[int(events.ids[n])]] = (float(events.t[n]), float(events.angle_deg[n]))
        q, qdot, q_d = sim.world()
        for n, i in enumerate(sim.state.ids):
            states[(index[int(i)], j)] = np.concatenate([q[n], qdot[n], q_d[n]])
        if sim.state.count == 0:
            break
    return exits, states


def _angle_difference(a_deg: float, b_deg: float) -> float:
    """Return a - b wrapped into [-180, 180) degrees."""
    return (a_deg - b_deg + 180.0) % 360.0 - 180.0


MIRROR = np.array([1.0, -1.0, 1.0] * 3)   # y -> -y for q, qdot and Q_d


@pytest.mark.parametrize('sample', [1, 4, 5], ids=lambda s: f's{s}')
@pytest.mark.parametrize('table', [[[0.0, CW]], REVERSING], ids=['cw', 'reversing'])
def test_mirror_symmetry(table: list[list[float]], sample: int) -> None:
    """
    A run mirrored in y equals the opposite-turning run of the mirrored start.

    Mirroring y -> -y maps a clockwise cone onto a counter-clockwise one, so the run of
    the start (x, -y, z) under -omega(t) must be the mirror image of the run of (x, y, z)
    under omega(t): exit angle a -> 360 - a, the same exit time, states mirrored at every
    10 ms sample. The rotating-frame integrator treats x and y alike, so this holds to
    roundoff: the bars (1e-8 deg, 1e-9 s, 1e-9 m, 1e-8 m/s, 1e-7 N) are far below the
    solver tolerances (atol 1e-6 m) and catch any sign slip in the handling of omega.
    """
    start = np.array([TABLE1_STARTS[sample]])
    mirrored_table = [[t, -w] for t, w in table]
    times = np.arange(1, 201) * 0.01
    exits_a, states_a = _run_sampled(table, start, [ProductParams()], times)
    exits_b, states_b = _run_sampled(mirrored_table, start * MIRROR[0:3], [ProductParams()],
                                     times)
    assert 0 in exits_a and 0 in exits_b, f'no exit within 2 s: {exits_a} {exits_b}'
    (t_a, angle_a), (t_b, angle_b) = exits_a[0], exits_b[0]
    assert abs(t_a - t_b) < 1.0e-9, f'exit times {t_a:.12f} s vs {t_b:.12f} s'
    d_angle = _angle_difference(angle_a, 360.0 - angle_b)
    assert abs(d_angle) < 1.0e-8, (
        f'exit angle {angle_a:.10f} deg vs 360 - {angle_b:.10f} deg: {d_angle:.3e} deg')
    assert set(states_a) == set(states_b), 'the runs have different samples'
    assert len(states_a) > 10
    for key, y_a in states_a.items():
        np.testing.assert_allclose(states_b[key][0:3], MIRROR[0:3] * y_a[0:3], rtol=0.0,
                                   atol=1.0e-9, err_msg=f'position at sample {key}')
        np.testing.assert_allclose(states_b[key][3:6], MIRROR[3:6] * y_a[3:6], rtol=0.0,
                                   atol=1.0e-8, err_msg=f'velocity at sample {key}')
        np.testing.assert_allclose(states_b[key][6:9], MIRROR[6:9] * y_a[6:9], rtol=0.0,
                                   atol=1.0e-7, err_msg=f'filter force at sample {key}')


@pytest.mark.parametrize('beta', [0.3, 2.5, -2.0], ids=lambda b: f'beta{b:g}')
@pytest.mark.parametrize('omega', [CW, CCW], ids=['cw', 'ccw'])
@pytest.mark.parametrize('sample', [1, 3, 5], ids=lambda s: f's{s}')
def test_rotational_symmetry(sample: int, omega: float, beta: float) -> None:
    """
    Rotating the start by beta about z rotates the exit angle by beta, at constant omega.

    The cone is axisymmetric and turns at a constant speed, so the rotated start must
    leave at the same time, beta further round. Unlike the mirror image this is not
    exact in floating point: the step-size control weighs the x and y errors separately,
    so rotated runs take different steps and agree only to the integration error
    (observed up to 1e-4 deg and 2e-7 s). Bars: 0.005 deg (1/20 of the accuracy bar)
    and 10 us.
    """
    start = np.array(TABLE1_STARTS[sample])
    runs = []
    for q0 in (start, rotate_z(start, beta)):
        sim = _simulator([[0.0, omega]])
        sim.add(q0, None, products=[ProductParams()])
        result = sim.advance_to(3.0)
        assert len(result.exits) == 1 and not result.failures, (
            f'expected one exit within 3 s, got {len(result.exits)} and {result.failures}')
        runs.append((float(result.exits.t[0]), float(result.exits.angle_deg[0])))
    (t_a, angle_a), (t_b, angle_b) = runs
    assert abs(t_a - t_b) < 1.0e-5, f'exit times {t_a:.9f} s vs {t_b:.9f} s'
    d_angle = _angle_difference(angle_b, angle_a + math.degrees(beta))
    assert abs(d_angle) < 5.0e-3, (
        f'exit angle {angle_b:.6f} deg, expected {angle_a:.6f} + {math.degrees(beta):.6f} '
        f'deg: off by {d_angle:.3e} deg')


# ---------------------------------------------------------------------------------------
# Independence of particles
# ---------------------------------------------------------------------------------------

def test_pieces_are_independent() -> None:
    """
    Several products at once give each piece exactly the result it gets alone.

    Six pieces with different d, m and mu_S (one of them near the tip, still on the cone
    at the end) on the reversing pattern, sampled every 0.1 s for 2 s; each piece is
    then run alone. Exits (time, angle) and sampled states must agree to 1e-9 (s, deg,
    m, m/s, N): the pieces do not interact, and the per-piece step control must not
    couple them either.
    """
    starts = np.array([*TABLE1_STARTS.values(), (0.02, 0.03, 0.06)])
    products = [ProductParams(d=225.0), ProductParams(d=135.0, m=0.05),
                ProductParams(d=750.0, m=0.3), ProductParams(d=750.0, mu_S=1.1),
                ProductParams(d=30.0, m=0.2), ProductParams(d=225.0, m=0.08)]
    times = np.arange(1, 21) * 0.1
    exits_all, states_all = _run_sampled(REVERSING, starts, products, times)
    assert len(exits_all) == 5, f'expected 5 exits, got {sorted(exits_all)}'
    for k in range(len(products)):
        exits_one, states_one = _run_sampled(REVERSING, starts[k:k + 1], [products[k]], times)
        assert (0 in exits_one) == (k in exits_all), f'piece {k}: exit differs'
        if k in exits_all:
            t_all, angle_all = exits_all[k]
            t_one, angle_one = exits_one[0]
            assert abs(t_all - t_one) < 1.0e-9, f'piece {k}: exit {t_all} s vs {t_one} s'
            assert abs(_angle_difference(angle_all, angle_one)) < 1.0e-9, (
                f'piece {k}: exit angle {angle_all} deg vs {angle_one} deg')
        mine = {j: y for (i, j), y in states_all.items() if i == k}
        alone = {j: y for (_, j), y in states_one.items()}
        assert set(mine) == set(alone), f'piece {k}: sampled at different times'
        for j, y in mine.items():
            np.testing.assert_allclose(alone[j], y, rtol=0.0, atol=1.0e-9,
                                       err_msg=f'piece {k} at t = {times[j]:.1f} s')
