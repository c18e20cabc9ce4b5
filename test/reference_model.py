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
Plain world-frame reference implementation of the cone feeder particle model.

This module is a test helper. It is written independently of the production
integrator, straight from the formulas of Hartmann et al. (eqs. 1-38, Table II),
read with the conventions of the project's model notes. It favours clarity over
speed: one particle, world frame, numpy vectors and scipy's Radau solver.

Conventions
-----------
* World frame, z up, origin at the centre of the cone base. The cone turns about +z
  with angular velocity ``omega`` (rad/s); ``omega > 0`` is counter-clockwise seen
  from above. The paper's clockwise rotation is ``omega < 0``.
* State ``y`` (9,) = [q (3, m), q_dot (3, m/s), Q_d (3, N)].
* The tip is regularised by rho = sqrt(q1**2 + q2**2 + tip_epsilon**2) wherever rho
  appears in the constraint (s_perp, v_perp and e_Fc). The exit test uses the true
  radius sqrt(q1**2 + q2**2).

Only numpy, scipy and numba are used; nothing is imported from the production package.
The functions on numpy arrays (constraint_terms, static_friction, reference_rhs) are the
readable definition; the solvers call ``compiled_rhs``, the same equations written out
scalar by scalar for numba (a call costs microseconds instead of numpy's tens), which
test_reference_model checks against them in every reading of the model.
"""

import dataclasses
import itertools
import math
from typing import Any

import numba
import numpy as np
from numpy.typing import ArrayLike
from scipy.integrate import OdeSolution, solve_ivp
SAMPLE_DAMPING: dict[int, float] = {1: 225.0, 2: 135.0, 3: 750.0, 4: 750.0, 5: 30.0}

# Start positions (m) of Table I, samples 1..5.
TABLE1_STARTS: dict[int, tuple[float, float, float]] = {
    1: (0.11, -0.01, 0.03),
    2: (-0.10, -0.01, 0.03),
    3: (0.08, -0.13, 0.03),
    4: (-0.07, 0.04, 0.03),
    5: (0.14, 0.06, 0.03),
}

# Default absolute tolerances of the reference solver, per state component.
# Positions are of order 0.1 m and velocities of order 0.1-1 m/s, so with rtol = 1e-10
# the relative part dominates; the absolute floors matter only for components that
# pass through zero (q_dot3 at rest, q1/q2 near an axis). 1e-12 m and 1e-12 m/s are
# far below every physical scale of the model (s0 = 2.5e-2 m, v_C = 5e-5 m/s,
# q_dot_F = 1e-4 m/s). Friction forces are of order m*g = 1.2 N (at most about
# mu_S*r_f = 119 N), so 1e-10 N is a relative 1e-10 of the weight and corresponds to
# an acceleration error below 1e-9 m/s^2 for m = 0.125 kg.
DEFAULT_ATOL: np.ndarray = np.array([1e-12] * 3 + [1e-12] * 3 + [1e-10] * 3)

_PARAM_KEYS: tuple[str, ...] = (
    'epsilon', 'd', 'mu_C', 'mu_S', 'v_C', 'v_S', 'm', 'T_F', 'qdot_F', 'g', 's0',
    's_c_ratio', 'r_a', 'r_d', 'r_f', 'cone_diameter', 'cone_tilt', 'tip_epsilon',
    'normal_force', 'friction_direction',
)


def table2_params(sample: int = 1, **overrides: Any) -> dict[str, Any]:
    """
    Return the Table II parameter dict (SI units, tilt in degrees).

    :param sample: Table I/II sample number 1..5; selects the damping d.
    :param overrides: Replacement values for any of the keys; unknown keys raise.
    :return: A fresh parameter dict.
    """
    if sample not in SAMPLE_DAMPING:
        raise ValueError(f'sample must be one of {sorted(SAMPLE_DAMPING)}, got {sample}')
    p: dict[str, Any] = {
        'epsilon': 1e-7,
        'd': SAMPLE_DAMPING[sample],
        'mu_C': 0.85,
        'mu_S': 0.99,
        'v_C': 0.00005,
        'v_S': 0.1,
        'm': 0.125,
        'T_F': 0.0003,
        'qdot_F': 0.0001,
        'g': 9.81,
        's0': 0.025,
        's_c_ratio': 0.5,
        'r_a': 0.99,
        'r_d': 120.0,
        'r_f': 120.0,
        'cone_diameter': 0.45,
        'cone_tilt': 7.5,
        'tip_epsilon': 1e-4,
        'normal_force': 'newton',
        'friction_direction': 'full',
    }
    for key, value in overrides.items():
        if key not in _PARAM_KEYS:
            raise KeyError(f'unknown parameter {key!r}')
        p[key] = value
    return p


def cone_geometry(p: dict[str, Any]) -> tuple[float, float]:
    """
    Return the cone radius r and height h (m).

    :param p: Parameter dict.
    :return: (r, h) with r = diameter / 2 and h = r * tan(tilt).
    """
    r = p['cone_diameter'] / 2.0
    h = r * math.tan(math.radians(p['cone_tilt']))
    return r, h


def activation_constants(p: dict[str, Any]) -> tuple[Any, Any]:
    """
    Return the transition coefficient r_t (1/m) and offset r_c (m), eqs. 32-33.

    :param p: Parameter dict (values scalars, or arrays that broadcast: one per piece).
    :return: (r_t, r_c).
    """
    s0 = p['s0']
    s_c = p['s_c_ratio'] * s0
    r_t = 2.0 * _call('arctanh', p['r_a']) / (s0 - s_c)
    r_c = (s0 + s_c) / 2.0
    return r_t, r_c


def constraint_terms(q: np.ndarray, qdot: np.ndarray, p: dict[str, Any]) -> dict[str, Any]:
    """
    Evaluate the cone constraint quantities of eqs. 27-36.

    Written on arrays: the vector components run along the first axis, any further axes
    are independent states (pieces, or the columns scipy's solvers ask for at once).

    :param q: Position (3, ...), m.
    :param qdot: Velocity (3, ...), m/s.
    :param p: Parameter dict (values scalars, or arrays broadcasting with q[0]).
    :return: Dict with s_perp, v_perp, e_Fc (3, ...), R_a, F_c (N) and rho (regularised).
    """
    r, h = cone_geometry(p)
    r_t, r_c = activation_constants(p)
    q1, q2, q3 = q[0], q[1], q[2]
    qd1, qd2, qd3 = qdot[0], qdot[1], qdot[2]
    eps_tip = p.get('tip_epsilon', 1e-4)
    rho = np.sqrt(q1 * q1 + q2 * q2 + eps_tip * eps_tip)
    # Eqs. 27-28: distance above the surface point straight below the particle.
    s_perp = q3 - h * (1.0 - rho / r)
    # Eq. 29: its time derivative.
    v_perp = qd3 + (h / r) * (q1 * qd1 + q2 * qd2) / rho
    # Eq. 36: d v_perp / d q_dot (not normalised).
    e_fc = np.stack(np.broadcast_arrays((h / r) * q1 / rho, (h / r) * q2 / rho, 1.0))
    # Eq. 31: activation function.
    r_act = (1.0 - _call('tanh', r_t * (s_perp - r_c))) / 2.0
    # Eq. 35: constraint force magnitude F_c(v_perp).
    f_c = p['r_f'] * (1.0 - _call('tanh', p['r_d'] * v_perp)) / 2.0
    return {'s_perp': s_perp, 'v_perp': v_perp, 'e_Fc': e_fc, 'R_a': r_act, 'F_c': f_c,
            'rho': rho}


def static_friction(v_dif: np.ndarray, r_act: Any, normal: Any,
                    p: dict[str, Any]) -> np.ndarray:
    """
    Return the constraint-specific static friction force Q_s^c (N), eqs. 4-10.

    :param v_dif: Relative velocity used for friction (3, ...), m/s.
    :param r_act: Activation R_a (scales the viscous terms), shape (...).
    :param normal: Normal force magnitude N used in the Coulomb/Stribeck terms, (...).
    :param p: Parameter dict (values scalars, or arrays broadcasting with r_act).
    :return: Q_s^c (3, ...).
    """
    v = np.sqrt(np.sum(v_dif * v_dif, axis=0))               # eq. 5
    e_v = -v_dif / (v + p['epsilon'])                        # eq. 4
    d, v_c, v_s = p['d'], p['v_C'], p['v_S']
    mu_c, mu_s = p['mu_C'], p['mu_S']
    f_visc = r_act * d * v                                   # eq. 7, times R_a
    f_coul = mu_c * normal * _call('tanh', v / v_c)          # eq. 8
    f_s_delta = (mu_s - mu_c * _call('tanh', v_s / v_c)) * normal - r_act * d * v_s  # eq. 10
    f_strib = f_s_delta * (v / v_s) * _call('exp', 0.5 - 0.5 * (v / v_s) ** 2)  # eq. 9
    return (f_visc + f_coul + f_strib) * e_v


def reference_rhs(t: float, y: np.ndarray, p: dict[str, Any], omega: float,
                  domega: float = 0.0) -> np.ndarray:
    """
    Right-hand side of the combined model, eq. 38 with eq. 37.

    :param t: Time (s); unused, the model is autonomous given omega.
    :param y: State (9, ...) = [q, q_dot, Q_d] in the world frame: one particle, or one
        per further index (columns of a vectorised solver call, pieces of a crowd).
    :param p: Parameter dict (values scalars, or arrays broadcasting with y[0]).
    :param omega: Cone angular velocity about +z at time t (rad/s).
    :param domega: Angular acceleration (rad/s^2); unused in the world frame.
    :return: dy/dt, the shape of y.
    """
    del t, domega
    return rhs_terms(y, p, omega)['rhs']


def rhs_terms(y: np.ndarray, p: dict[str, Any], omega: float) -> dict[str, np.ndarray]:
    """
    Return reference_rhs (key ``rhs``) with the terms its last two blocks add up.

    ``q_s`` (Q_s^c), ``a`` (eq. 14's factor), ``f_g`` and ``f_perp`` (3, ...), in N or
    dimensionless: what :func:`rounding_bound` needs to size the round-off of the sums.
    """
    literal, tangential = readings(p)
    y = np.asarray(y, dtype=float)
    q = y[0:3]
    qdot = y[3:6]
    q_d = y[6:9]

    # Eqs. 2-3: full 3-D relative velocity to the cone surface,
    # v_p = omega e_z x q = (-omega q2, omega q1, 0).
    v_p = np.stack([-omega * q[1], omega * q[0], np.zeros_like(q[0])])
    v_dif = qdot - v_p
    v_dif_abs = np.sqrt(np.sum(v_dif * v_dif, axis=0))

    c = constraint_terms(q, qdot, p)
    r_act, f_c, e_fc = c['R_a'], c['F_c'], c['e_Fc']

    # Normal force magnitude inside the friction terms.
    normal = r_act * f_c
    if literal:
        normal = normal / p['r_f']

    # Velocity used by the friction law.
    if tangential:
        n = e_fc / np.sqrt(np.sum(e_fc * e_fc, axis=0))
        v_fric = v_dif - np.sum(v_dif * n, axis=0) * n
    else:
        v_fric = v_dif

    q_s = static_friction(v_fric, r_act, normal, p)

    # Eq. 14 with the full |v_dif| in every mode; eq. 37.
    a = 1.0 - _call('exp', -(v_dif_abs / p['qdot_F']) ** 2)
    dq_d = a / p['T_F'] * (q_s - q_d)

    # Eq. 38: Q_d + F_g + F_perp, F_perp = R_a F_c e_Fc (in newtons in every mode).
    weight = np.broadcast_to(-p['m'] * p['g'], r_act.shape)
    f_g = np.stack([np.zeros_like(weight), np.zeros_like(weight), weight])
    f_perp = r_act * f_c * e_fc
    qddot = (q_d + f_g + f_perp) / p['m']

    return {'rhs': np.concatenate([qdot, qddot, dq_d]), 'q_s': q_s, 'a': a, 'f_g': f_g,
            'f_perp': f_perp}


# The transcendental functions the numpy definition calls. Two correct implementations of
# one (numpy's SIMD loops, the C library numba calls) may differ by a few ulps; the
# definition calls them through _call so that rounding_bound can perturb each call.
_TRANSCENDENTALS: dict[str, Any] = {'exp': np.exp, 'tanh': np.tanh, 'arctanh': np.arctanh}
_perturbation: dict[str, Any] = {}


def _call(name: str, x: Any) -> Any:
    """Return the transcendental ``name`` of x, perturbed where rounding_bound says."""
    if not _perturbation:
        return _TRANSCENDENTALS[name](x)
    index = _perturbation['count']
    _perturbation['count'] += 1
    if index != _perturbation['call']:
        return _TRANSCENDENTALS[name](x)
    rel = _perturbation['rel']
    if _perturbation['where'] == 'argument':
        return _TRANSCENDENTALS[name](x * (1.0 + rel))
    return _TRANSCENDENTALS[name](x) * (1.0 + rel)


#: The ulps by which one transcendental result (or its argument, computed in another
#: order) may differ between two correct implementations: numpy's AVX-512 exp and AVX2
#: tanh differ from glibc's by up to 1 and 2 ulps (measured on 100,000 arguments), each
#: within its documented bound of 4 ulps of the true value.
ULPS = 4.0


def rounding_bound(y: np.ndarray, p: dict[str, Any], omega: float,
                   ulps: float = ULPS) -> np.ndarray:
    """
    Bound |f1 - f2| for two correct implementations of reference_rhs at states y (9, ...).

    What the arithmetic guarantees, to first order: each transcendental call's result and
    argument may be off by ``ulps`` ulps, times the right-hand side's sensitivity to that
    call (its condition, measured by perturbing one call at a time, central differences);
    and each sum of eq. 38 and eq. 37 may be off by ``ulps`` ulps of its terms' magnitudes
    (the same operations in another order). Returns the bound (9, ...), in y's units / s.
    """
    eps = ulps * np.finfo(float).eps
    terms = rhs_terms(y, p, omega)
    a, q_s, q_d = np.abs(terms['a']), np.abs(terms['q_s']), np.abs(np.asarray(y)[6:9])
    bound = np.zeros_like(terms['rhs'])
    bound[3:6] = eps * (q_d + np.abs(terms['f_g']) + np.abs(terms['f_perp'])) / p['m']
    bound[6:9] = eps * a / p['T_F'] * (q_s + q_d)
    _perturbation.update(count=0, call=-1, rel=0.0, where='result')
    try:
        rhs_terms(y, p, omega)
        calls = _perturbation['count']
        rel = 1e-7
        for call, where in itertools.product(range(calls), ('result', 'argument')):
            change = []
            for sign in (1.0, -1.0):
                _perturbation.update(count=0, call=call, rel=sign * rel, where=where)
                change.append(rhs_terms(y, p, omega)['rhs'])
            bound += eps * np.abs(change[0] - change[1]) / (2.0 * rel)
    finally:
        _perturbation.clear()
    return bound


#: The parameters of one piece, in the order of the rows compiled_rhs takes.
PIECE_KEYS: tuple[str, ...] = ('epsilon', 'd', 'mu_C', 'mu_S', 'v_C', 'v_S', 'm', 'T_F',
                               'qdot_F', 'g', 's0', 's_c_ratio', 'r_a', 'r_d', 'r_f')


def piece_row(p: dict[str, Any]) -> np.ndarray:
    """Return the PIECE_KEYS values of p as one float row (15,)."""
    return np.array([p[key] for key in PIECE_KEYS], dtype=float)


def cone_row(p: dict[str, Any]) -> np.ndarray:
    """Return [r, h, tip_epsilon] of p (m)."""
    r, h = cone_geometry(p)
    return np.array([r, h, p.get('tip_epsilon', 1e-4)])


@numba.njit(cache=True)
def friction_of(vx: float, vy: float, vz: float, r_act: float, normal: float,
                p: np.ndarray) -> tuple[float, float, float]:
    """static_friction for one velocity (3 floats); p a PIECE_KEYS row (its first six)."""
    eps, d, mu_c, mu_s, v_c, v_s = p[0], p[1], p[2], p[3], p[4], p[5]
    v = math.sqrt(vx * vx + vy * vy + vz * vz)
    f_visc = r_act * d * v
    f_coul = mu_c * normal * math.tanh(v / v_c)
    f_s_delta = (mu_s - mu_c * math.tanh(v_s / v_c)) * normal - r_act * d * v_s
    f_strib = f_s_delta * (v / v_s) * math.exp(0.5 - 0.5 * (v / v_s) ** 2)
    scale = -(f_visc + f_coul + f_strib) / (v + eps)
    return scale * vx, scale * vy, scale * vz


@numba.njit(cache=True)
def piece_rhs_into(out: np.ndarray, y: np.ndarray, b: int, c: int, p: np.ndarray,
                   cone: np.ndarray, omega: float, literal: bool, tangential: bool) -> None:
    """
    Write reference_rhs of the piece in rows b..b+8 of column c of y into out (the same rows).

    p: its PIECE_KEYS row; cone: cone_row; literal, tangential: the readings of the model.
    """
    r, h, tip_eps = cone[0], cone[1], cone[2]
    m, t_f, qdot_f, g = p[6], p[7], p[8], p[9]
    s0, s_c_ratio, r_a, r_d, r_f = p[10], p[11], p[12], p[13], p[14]
    q0, q1, q2 = y[b, c], y[b + 1, c], y[b + 2, c]
    qd0, qd1, qd2 = y[b + 3, c], y[b + 4, c], y[b + 5, c]
    vx, vy, vz = qd0 + omega * q1, qd1 - omega * q0, qd2
    rho = math.sqrt(q0 * q0 + q1 * q1 + tip_eps * tip_eps)
    s_perp = q2 - h * (1.0 - rho / r)
    v_perp = qd2 + (h / r) * (q0 * qd0 + q1 * qd1) / rho
    s_c = s_c_ratio * s0
    r_t = 2.0 * math.atanh(r_a) / (s0 - s_c)
    r_act = (1.0 - math.tanh(r_t * (s_perp - 0.5 * (s0 + s_c)))) / 2.0
    f_c = r_f * (1.0 - math.tanh(r_d * v_perp)) / 2.0
    ex, ey = (h / r) * q0 / rho, (h / r) * q1 / rho
    normal = r_act * f_c / r_f if literal else r_act * f_c
    fx, fy, fz = vx, vy, vz
    if tangential:
        norm = math.sqrt(ex * ex + ey * ey + 1.0)
        nx, ny, nz = ex / norm, ey / norm, 1.0 / norm
        along = vx * nx + vy * ny + vz * nz
        fx, fy, fz = vx - along * nx, vy - along * ny, vz - along * nz
    qs = friction_of(fx, fy, fz, r_act, normal, p)
    a = 1.0 - math.exp(-(math.sqrt(vx * vx + vy * vy + vz * vz) / qdot_f) ** 2)
    e = (ex, ey, 1.0)
    for k in range(3):
        out[b + k, c] = y[b + 3 + k, c]
        out[b + 6 + k, c] = a / t_f * (qs[k] - y[b + 6 + k, c])
        out[b + 3 + k, c] = (y[b + 6 + k, c] + r_act * f_c * e[k]) / m
    out[b + 5, c] -= g


@numba.njit(cache=True)
def _pieces_rhs(y: np.ndarray, p: np.ndarray, cone: np.ndarray, omega: float, literal: bool,
                tangential: bool) -> np.ndarray:
    """Return dy/dt (9, k) of one piece for y (9, k)."""
    out = np.empty_like(y)
    for c in range(y.shape[1]):
        piece_rhs_into(out, y, 0, c, p, cone, omega, literal, tangential)
    return out


def readings(p: dict[str, Any]) -> tuple[bool, bool]:
    """Return (literal normal force, tangential friction) of p, checked."""
    normal_mode = p.get('normal_force', 'newton')
    direction_mode = p.get('friction_direction', 'full')
    if normal_mode not in ('newton', 'literal'):
        raise ValueError(f'normal_force must be newton or literal, got {normal_mode!r}')
    if direction_mode not in ('full', 'tangential'):
        raise ValueError(
            f'friction_direction must be full or tangential, got {direction_mode!r}')
    return normal_mode == 'literal', direction_mode == 'tangential'


def compiled_rhs(p: dict[str, Any]) -> Any:
    """
    Return fun(y, omega) = reference_rhs(t, y, p, omega), compiled.

    y (9,) or (9, k): one state, or k at once (scipy's vectorised calls).
    """
    literal, tangential = readings(p)
    row, cone = piece_row(p), cone_row(p)

    def fun(y: np.ndarray, omega: float) -> np.ndarray:
        columns = np.asarray(y, dtype=float).reshape(9, -1)
        return _pieces_rhs(columns, row, cone, float(omega), literal,
                           tangential).reshape(np.shape(y))
    return fun


def _check_table(table: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """
    Validate a rotation table and return its times and speeds.

    :param table: List of [t_i, omega_i] with strictly increasing t_i.
    :return: (times, omegas) arrays.
    """
    arr = np.asarray(table, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 1:
        raise ValueError('rotation table must be a non-empty list of [t, omega] pairs')
    times, omegas = arr[:, 0], arr[:, 1]
    if np.any(np.diff(times) <= 0.0):
        raise ValueError('rotation table times must be strictly increasing')
    return times, omegas


def omega_of_t(table: ArrayLike, t: float) -> float:
    """
    Piecewise-linear cone speed (rad/s) at time t.

    Linear between the points of the table, held constant before the first and after
    the last point.

    :param table: List of [t_i, omega_i] with strictly increasing t_i.
    :param t: Time (s).
    :return: omega(t).
    """
    times, omegas = _check_table(table)
    return float(np.interp(t, times, omegas))


def domega_of_t(table: ArrayLike, t: float) -> float:
    """
    Slope of the rotation table (rad/s^2) on the segment that starts at or before t.

    :param table: List of [t_i, omega_i] with strictly increasing t_i.
    :param t: Time (s).
    :return: d omega / dt (right derivative at breakpoints).
    """
    times, omegas = _check_table(table)
    if t < times[0] or t >= times[-1]:
        return 0.0
    i = int(np.searchsorted(times, t, side='right')) - 1
    return float((omegas[i + 1] - omegas[i]) / (times[i + 1] - times[i]))


def initial_state_on_feeder(q0: ArrayLike, omega0: float) -> np.ndarray:
    """
    Return the initial state of a piece lying on the feeder: it moves with the cone.

    :param q0: Start position (3,), m.
    :param omega0: Cone speed at the start time (rad/s).
    :return: y0 (9,) = [q0, omega0 e_z x q0, 0].
    """
    q = np.asarray(q0, dtype=float)
    qdot = np.array([-omega0 * q[1], omega0 * q[0], 0.0])   # omega0 e_z x q0
    return np.concatenate([q, qdot, np.zeros(3)])


def exit_angle_deg(q: ArrayLike) -> float:
    """
    Return atan2(y, x) in degrees, in [0, 360).

    :param q: Position (at least 2 components).
    :return: Angle in degrees.
    """
    angle = math.degrees(math.atan2(q[1], q[0])) % 360.0
    return 0.0 if angle >= 360.0 else angle


def channel_of_angle(angle_deg: float, count: int = 14, boundary_deg: float = 108.0,
                     numbering: str = 'clockwise') -> int:
    """
    Dosing channel (1..count) receiving a piece leaving at the given angle.

    Clockwise numbering: channel 1 covers [boundary - w, boundary), channel 2 the next
    sector clockwise, ...; counter-clockwise numbering: channel 1 covers
    [boundary, boundary + w). Here w = 360 / count.

    :param angle_deg: Exit angle in degrees (any real value).
    :param count: Number of channels.
    :param boundary_deg: Angle of the start boundary of channel 1 (see above).
    :param numbering: 'clockwise' or 'counterclockwise'.
    :return: Channel number.
    """
    if count < 1:
        raise ValueError('count must be positive')
    width = 360.0 / count
    offset = (angle_deg - boundary_deg) % 360.0   # in [0, 360), ccw from the boundary
    k = min(math.floor(offset / width), count - 1)   # sector index ccw, 0-based
    if numbering == 'counterclockwise':
        return k + 1
    if numbering == 'clockwise':
        return count - k
    raise ValueError(f'numbering must be clockwise or counterclockwise, got {numbering!r}')


@dataclasses.dataclass
class ReferenceResult:
    """Result of a reference run."""

    exited: bool
    t_exit: float | None
    y_exit: np.ndarray | None
    angle_deg: float | None
    t_final: float
    y_final: np.ndarray
    t_out: np.ndarray
    y_out: np.ndarray
    n_rhs: int
    segments: list[tuple[float, float, OdeSolution]] = dataclasses.field(
        default_factory=list, repr=False)

    def state_at(self, times: ArrayLike) -> np.ndarray:
        """
        Interpolate the state at given times from the solver's dense output.

        The dense output of Radau is its collocation polynomial (lower order than the
        step itself); for full accuracy pass the times as ``t_out`` to the run.

        :param times: Scalar or sequence of times inside [t_start, t_final].
        :return: (9,) for a scalar time, else (len(times), 9).
        """
        scalar = np.ndim(times) == 0
        ts = np.atleast_1d(np.asarray(times, dtype=float))
        out = np.empty((ts.size, 9))
        t_lo, t_hi = self.segments[0][0], self.segments[-1][1]
        for k, tk in enumerate(ts):
            if tk < t_lo or tk > t_hi:
                raise ValueError(f'time {tk} outside the run [{t_lo}, {t_hi}]')
            for t_a, t_b, sol in self.segments:
                if t_a <= tk <= t_b:
                    out[k] = sol(tk)
                    break
        return out[0] if scalar else out


def reference_trajectory(p: dict[str, Any], y0: ArrayLike,
                         table: ArrayLike, t_end: float,
                         rtol: float = 1e-10, atol: ArrayLike | None = None,
                         r_exit: bool = True, t_start: float = 0.0,
                         t_out: ArrayLike | None = None) -> ReferenceResult:
    """
    Integrate one particle with Radau, segment by segment, until exit or t_end.

    The run is split at every breakpoint of the rotation table (so that kinks in
    omega are never stepped over) and at every requested output time (so that
    those states are solver step end points, not interpolated). The solver is
    restarted at each split. With ``r_exit`` a terminal event stops the run when the
    true radius sqrt(q1**2 + q2**2) crosses the cone radius r upwards.

    :param p: Parameter dict.
    :param y0: Initial state (9,).
    :param table: Rotation table [[t_i, omega_i], ...].
    :param t_end: End time (s).
    :param rtol: Relative tolerance.
    :param atol: Absolute tolerance, scalar or (9,); default DEFAULT_ATOL.
    :param r_exit: Stop at the rim crossing.
    :param t_start: Start time (s).
    :param t_out: Optional output times in [t_start, t_end] (states in y_out).
    :return: ReferenceResult.
    """
    if t_end <= t_start:
        raise ValueError('t_end must be after t_start')
    times, _ = _check_table(table)
    r, _ = cone_geometry(p)
    y = np.asarray(y0, dtype=float).copy()
    if y.shape != (9,):
        raise ValueError('y0 must have 9 components')
    if r_exit and math.hypot(y[0], y[1]) >= r:
        raise ValueError('the particle starts outside the cone radius')
    atol_arr = DEFAULT_ATOL if atol is None else atol
    fun = compiled_rhs(p)

    out_times = np.array(sorted({float(t) for t in ([] if t_out is None else t_out)}))
    if out_times.size and (out_times[0] < t_start or out_times[-1] > t_end):
        raise ValueError('t_out must lie in [t_start, t_end]')
    inner = [t for t in list(times) + list(out_times) if t_start < t < t_end]
    cuts = [t_start] + sorted(set(inner)) + [t_end]

    def rim(t: float, yy: np.ndarray) -> float:
        return math.hypot(yy[0], yy[1]) - r

    rim.terminal = True    # type: ignore[attr-defined]
    rim.direction = 1.0    # type: ignore[attr-defined]

    segments: list[tuple[float, float, OdeSolution]] = []
    recorded: dict[float, np.ndarray] = {}
    if out_times.size and out_times[0] == t_start:
        recorded[t_start] = y.copy()
    n_rhs = 0
    exited = False
    t_now = t_start
    for t_a, t_b in itertools.pairwise(cuts):
        # omega is linear on [t_a, t_b] (no table breakpoint inside): write it out
        # once per segment instead of searching the table at every call.
        w_a = omega_of_t(table, t_a)
        slope = (omega_of_t(table, t_b) - w_a) / (t_b - t_a)

        def rhs(t: float, yy: np.ndarray, w_a: float = w_a, slope: float = slope,
                t_a: float = t_a) -> np.ndarray:
            return fun(yy, w_a + slope * (t - t_a))

        sol = solve_ivp(rhs, (t_a, t_b), y, method='Radau', rtol=rtol, atol=atol_arr,
                        dense_output=True, events=rim if r_exit else None,
                        vectorized=True)
        if sol.status < 0:
            raise RuntimeError(f'solve_ivp failed on [{t_a}, {t_b}]: {sol.message}')
        n_rhs += int(sol.nfev)
        t_now = float(sol.t[-1])
        y = sol.y[:, -1].copy()
        segments.append((t_a, t_now, sol.sol))
        if sol.status == 1:
            exited = True
            break
        if t_b in set(out_times.tolist()):
            recorded[t_b] = y.copy()

    t_rec = np.array(sorted(recorded))
    y_rec = np.array([recorded[t] for t in t_rec]).reshape(len(t_rec), 9)
    return ReferenceResult(
        exited=exited,
        t_exit=t_now if exited else None,
        y_exit=y.copy() if exited else None,
        angle_deg=exit_angle_deg(y) if exited else None,
        t_final=t_now,
        y_final=y.copy(),
        t_out=t_rec,
        y_out=y_rec,
        n_rhs=n_rhs,
        segments=segments,
    )
