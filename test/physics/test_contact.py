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

"""The pair law (physics/contact): against the tests' own reference and closed forms."""

from cone_feeder_sim.errors import ParameterError
from cone_feeder_sim.physics.contact import contact_force_py, history_update, interaction_row
from cone_feeder_sim.physics.contact.cohesion import largest_pull
from cone_feeder_sim.physics.params import (
    interaction_params_from_mapping, InteractionParams, ModelParams, product_row, ProductParams)
import numpy as np
import pytest
from reference_contacts import density_for, Law, pair_force, Piece

HEAVY = ProductParams(m=0.2, s0=0.03, young_modulus=3.0e4, poisson_ratio=0.4)


def law(**interactions: float) -> np.ndarray:
    return interaction_row(ModelParams(interactions=InteractionParams(enabled=True,
                                                                      **interactions)))


def random_state(rng: np.random.Generator, reach: float) -> tuple[np.ndarray, ...]:
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    d = n * (reach - rng.uniform(0.0005, 0.012))
    u = rng.normal(size=3) * 0.3
    xi = rng.normal(size=3) * rng.choice([1e-5, 1e-3])
    return d, u, xi - (xi @ n) * n


def test_the_law_is_the_soft_sphere_law_of_the_reference() -> None:
    rng = np.random.default_rng(3)
    products = ((ProductParams(), Piece()), (HEAVY, Piece(0.2, 0.03, 3.0e4, 0.4)))
    row = law(restitution=0.4, friction=0.6, pull_off=0.05)
    reference = Law(e=0.4, mu=0.6, k=density_for(0.05))
    slid = held = 0
    for trial in range(40):
        (pi, ri), (pj, rj) = products[trial % 2], products[(trial // 2) % 2]
        d, u, xi = random_state(rng, pi.s0 + pj.s0)
        got, what = contact_force_py(d, u, xi, product_row(pi), product_row(pj), row)
        want, f_n, s_t = pair_force(ri, rj, reference, d, u, xi)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
        assert what['F_n'] == pytest.approx(f_n, rel=1e-9)
        sliding = s_t * np.linalg.norm(xi) >= 0.6 * abs(f_n)
        slid, held = slid + sliding, held + (not sliding)
    assert slid > 5 and held > 5  # both branches of the tangential part were compared


def test_apart_there_is_no_force() -> None:
    p = product_row(ProductParams())
    force, what = contact_force_py([0.0, 0.0, 0.0501], [0.0, 0.0, -1.0], [1e-3, 0.0, 0.0], p, p,
                                   law())
    assert not force.any() and what['delta'] < 0.0


def test_equal_and_opposite_for_any_state() -> None:
    rng = np.random.default_rng(5)
    pi, pj = product_row(ProductParams()), product_row(HEAVY)
    row = law()
    for _ in range(20):
        d, u, xi = random_state(rng, 0.055)
        on_i, _ = contact_force_py(d, u, xi, pi, pj, row)
        on_j, _ = contact_force_py(-d, -u, -xi, pj, pi, row)
        np.testing.assert_allclose(on_i, -on_j, rtol=1e-14, atol=1e-16)


def test_frame_invariance_under_rotation_about_z() -> None:
    rng = np.random.default_rng(7)
    p = product_row(ProductParams())
    d, u, xi = random_state(rng, 0.05)
    a = 0.7
    turn = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0, 0, 1.0]])
    f, _ = contact_force_py(d, u, xi, p, p, law())
    g, _ = contact_force_py(turn @ d, turn @ u, turn @ xi, p, p, law())
    np.testing.assert_allclose(g, turn @ f, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize('pull_off', [0.01, 0.05, 0.5])
def test_the_largest_pull_is_the_pull_off_force(pull_off: float) -> None:
    p = product_row(ProductParams())
    row = law(pull_off=pull_off)
    overlaps = np.linspace(1e-7, 0.01, 20001)
    pulls = [-contact_force_py([0.0, 0.0, 0.05 - delta], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0],
                               p, p, row)[1]['F_n'] for delta in overlaps]
    assert max(pulls) == pytest.approx(pull_off, rel=0.01)
    # the reference's cohesion density gives the same largest pull
    assert largest_pull(density_for(pull_off), 1.0 / (2 * (1 - 0.45 ** 2) / 4.0e4), 0.025,
                        0.025) == pytest.approx(pull_off, rel=1e-6)


#: The overlap (m) at which Hertz's push on two default pieces is 1 N, and the spring's
#: stiffness S_t (N/m) there: 4/3 Y* sqrt(R*) delta^1.5 = 1 N, S_t = 8 G* sqrt(R* delta).
Y_STAR = 1.0 / (2.0 * (1.0 - 0.45 ** 2) / 4.0e4)
G_STAR = 1.0 / (2.0 * 2.0 * (2.0 - 0.45) * (1.0 + 0.45) / 4.0e4)
ONE_NEWTON = (1.0 / (4.0 / 3.0 * Y_STAR * np.sqrt(0.0125))) ** (2.0 / 3.0)
S_T = 8.0 * G_STAR * np.sqrt(0.0125 * ONE_NEWTON)


def loaded_piece(load: float, t_end: float, ramp: float = 0.1,
                 dt: float = 2e-5) -> tuple[float, float, float, float]:
    """
    Press a piece on a fixed one, push it sideways; return its motion and the forces.

    The piece is pressed with 1 N along the normal and pushed along the tangent with a
    load that rises to ``load`` N over ``ramp`` s. Returns its tangential
    displacement (m) and speed (m/s) at t_end (s), and the contact's last tangential
    force (N, along the tangent) and normal force F_n (N).

    The loads follow the contact's normal and tangent, so the case is the 1-D law. The
    law's force and history update are integrated by semi-implicit Euler at a step far
    below the periods of the contact (0.14 s along the tangent, for a default piece), from
    the overlap where F_n = 1 N.
    """
    piece = ProductParams()
    p, row = product_row(piece), law(restitution=0.3, friction=0.5, pull_off=0.0)
    x = np.array([0.0, 0.0, 0.05 - ONE_NEWTON])  # the fixed piece at the origin
    v = np.zeros(3)
    xi = np.zeros(3)
    shift = 0.0
    for k in range(int(round(t_end / dt))):
        n = x / np.linalg.norm(x)
        tangent = np.array([1.0, 0.0, 0.0]) - n[0] * n
        tangent /= np.linalg.norm(tangent)
        applied = -n + load * min(1.0, k * dt / ramp) * tangent
        force, what = contact_force_py(x, v, xi, p, p, row)
        v = v + dt * (force + applied) / piece.m
        step = dt * v
        x = x + step
        shift += float(step @ tangent)
        xi = np.array(history_update(*xi, *step, *x, *v, p, p, row))
    return shift, float(v @ tangent), float(force @ tangent), what['F_n']


def test_below_the_coulomb_load_a_piece_sticks_with_the_spring_give() -> None:
    # 1 N along the normal: the cap is mu F_n = 0.5 N; 0.4 N along the tangent holds, and
    # the piece gives by the spring's stretch 0.4 N / S_t
    shift, speed, _, _ = loaded_piece(0.4, t_end=1.0, ramp=0.3)
    assert shift == pytest.approx(0.4 / S_T, rel=0.02)
    assert abs(speed) < 0.01 * 0.4 / S_T / 0.14  # at rest: 1 % of the give per period


def test_above_the_coulomb_load_a_piece_slides() -> None:
    # 0.6 N against a cap of 0.5 N: once the load passes the cap, the piece slides, held
    # back by mu F_n exactly (F_n falls below 1 N as the piece circles the other)
    before, early, _, _ = loaded_piece(0.6, t_end=0.3, ramp=0.2)
    shift, late, friction, normal = loaded_piece(0.6, t_end=0.4, ramp=0.2)
    assert friction == pytest.approx(-0.5 * normal, rel=1e-9)
    assert 0.8 < normal < 1.0
    assert late > early > 0.05 and shift > before > 3.0 * 0.6 / S_T


def test_misspelt_and_out_of_range_keys_are_named() -> None:
    with pytest.raises(ParameterError, match="unknown interactions key.*'restitusion'"):
        interaction_params_from_mapping({'restitusion': 0.5})
    for key, value in (('restitution', 0.0), ('restitution', 1.5), ('friction', -0.1),
                       ('pull_off', -1.0)):
        with pytest.raises(ParameterError, match=f'interactions.{key}'):
            InteractionParams(**{key: value})
    for key, value in (('young_modulus', 0.0), ('poisson_ratio', 0.6)):
        with pytest.raises(ParameterError, match=key):
            ProductParams(**{key: value})
