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
The paper's equations (2)-(38) as small compiled functions, plus the vector field.

Two forms of the vector field are provided for one particle:

* :func:`rhs_world`, eq. (38) with (37) exactly as the paper writes it, in the fixed world
  frame (z up, origin at the centre of the cone base, the cone turning about +z with angular
  velocity omega, omega > 0 counter-clockwise seen from above). State y, shape (9,):
  q (m), qdot (m/s), Q_d (N).
* :func:`rhs`, the same system written in the frame that turns with the cone. State y,
  shape (9,): x (m) position in cone axes, w = dx/dt (m/s) velocity relative to the cone
  surface (it equals v_dif of eq. 3 expressed in cone axes), P (N) the filtered friction
  force Q_d in cone axes. Centrifugal, Coriolis and Euler terms appear; the filter state
  picks up -omega z x P. A piece sticking to the turning cone is at rest in this frame, so
  an adaptive integrator can take long steps through sticking phases. The transformation
  is exact: world = R(phi) * cone, with phi the cone angle.

Per-piece constants come in a row `product` (see cone_feeder_sim.physics.params.product_row)
and the constants of the machine and the model in a row `machine` (see
ModelParams.global_row). Every function here is compiled with numba (no Python objects), so
the integrator can call them per particle.
"""

import math

import numba
import numpy as np

from .params import (
    G_EPS, G_G, G_H, G_K, G_LITERAL, G_TANGENTIAL, G_TIP_EPS, P_C_S, P_D, P_M, P_MU_C, P_QDOT_F,
    P_R_C, P_R_D, P_R_F, P_R_T, P_T_F, P_V_C, P_V_S)

jit = numba.njit(cache=True, fastmath=False, error_model='numpy', nogil=True)

STATE_SIZE = 9


# --- eqs. (2)-(5): relative velocity ---------------------------------------------------

@jit
def relative_velocity(q, qdot, omega):
    """
    Return v_dif = qdot - omega z x q (m/s), eqs. (2)-(3), as a tuple of 3 floats.

    q (m), qdot (m/s): shape (3,) world-frame position and velocity; omega (rad/s).
    """
    return (qdot[0] + omega * q[1], qdot[1] - omega * q[0], qdot[2])


@jit
def friction_direction(u0, u1, u2, epsilon):
    """Return (e_v, v): e_v = -u/(|u| + epsilon) (eq. 4) and v = |u| (eq. 5)."""
    v = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    return direction_of(u0, u1, u2, v, epsilon), v


@jit
def direction_of(u0, u1, u2, v, epsilon):
    """Return e_v = -u/(v + epsilon) (eq. 4) for v = |u| already known, as 3 floats."""
    s = -1.0 / (v + epsilon)
    return s * u0, s * u1, s * u2


# --- eqs. (6)-(10): static friction ------------------------------------------------------

@jit
def stribeck_shape(v, v_s):
    """Return sigma(v) = (v/v_S) exp(1/2 - (v/v_S)^2 / 2), the Stribeck factor of eq. (9)."""
    xi = v / v_s
    return xi * math.exp(0.5 - 0.5 * xi * xi)


@jit
def static_friction_magnitude(v, normal, r_a_act, d, mu_c, v_c, v_s, c_s):
    """
    Return the magnitude of Q_s^c along e_v (N), eqs. (6)-(10) with the constraint coupling.

    v (m/s) relative speed; normal (N) the normal force N used in the friction terms;
    r_a_act the activation R_a (scales viscous friction and the -d v_S of F_S^Delta);
    c_s = mu_S - mu_C tanh(v_S / v_C). Viscous R_a d v + Coulomb mu_C N tanh(v/v_C) +
    Stribeck F_S^Delta sigma(v), F_S^Delta = c_s N - R_a d v_S.
    """
    f_delta = c_s * normal - r_a_act * d * v_s
    return (r_a_act * d * v + mu_c * normal * math.tanh(v / v_c)
            + f_delta * stribeck_shape(v, v_s))


# --- eqs. (13)-(14): dynamic friction filter ----------------------------------------------

@jit
def filter_gain(v, qdot_f):
    """Return a = 1 - exp(-(v/qdot_F)^2), eq. (14); v (m/s) is |v_dif|."""
    z = v / qdot_f
    return 1.0 - math.exp(-z * z)


# --- eqs. (15)-(29), (36): cone distance, normal velocity, constraint direction --------

@jit
def regularised_radius(x0, x1, tip_epsilon):
    """Return rho = sqrt(x^2 + y^2 + tip_epsilon^2) (m), the regularised eq. (17) radius."""
    return math.sqrt(x0 * x0 + x1 * x1 + tip_epsilon * tip_epsilon)


@jit
def cone_distance(x0, x1, x2, h, k, tip_epsilon):
    """Return (s_perp, rho): s_perp = q3 - h (1 - rho/r) (m), eqs. (27)-(28); k = h/r."""
    rho = regularised_radius(x0, x1, tip_epsilon)
    return x2 - h + k * rho, rho


@jit
def constraint_direction(x0, x1, k, rho):
    """Return e_Fc = d v_perp / d qdot = (k x/rho, k y/rho, 1), eq. (36), not normalised."""
    k_rho = k / rho
    return (k_rho * x0, k_rho * x1, 1.0)


@jit
def normal_velocity(x0, x1, w0, w1, w2, k, rho):
    """Return v_perp = qdot_3 + k (q1 qdot1 + q2 qdot2)/rho (m/s), eq. (29)."""
    return w2 + k * (x0 * w0 + x1 * w1) / rho


# --- eqs. (30)-(35): restriction function -------------------------------------------------

@jit
def activation(s_perp, r_t, r_c):
    """Return R_a = (1 - tanh(r_t (s_perp - r_c)))/2, eq. (31)."""
    return 0.5 * (1.0 - math.tanh(r_t * (s_perp - r_c)))


@jit
def power_function(v_perp, r_d, r_f):
    """
    Return R_p = (v/2 - log(cosh(r_d v))/(2 r_d)) r_f (W), eq. (34).

    log(cosh(z)) is evaluated as |z| + log1p(exp(-2|z|)) - log(2) so it does not overflow.
    """
    z = abs(r_d * v_perp)
    log_cosh = z + math.log1p(math.exp(-2.0 * z)) - math.log(2.0)
    return (0.5 * v_perp - log_cosh / (2.0 * r_d)) * r_f


@jit
def constraint_force(v_perp, r_d, r_f):
    """Return F_c = dR_p/dv_perp = r_f (1 - tanh(r_d v_perp))/2 (N), eq. (35)."""
    return 0.5 * r_f * (1.0 - math.tanh(r_d * v_perp))


@jit
def normal_force(s_perp, v_perp, r_t, r_c, r_d, r_f):
    """Return (R_a, F_c, R_a F_c): activation, constraint force and normal force (N)."""
    r_a_act = activation(s_perp, r_t, r_c)
    f_c = constraint_force(v_perp, r_d, r_f)
    return r_a_act, f_c, r_a_act * f_c


@jit
def friction_target(u0, u1, u2, u_n, v_full, n_fric, r_a_act, e0, e1, e2, product, machine):
    """
    Return (Q_s^c as 3 floats, a/T_F): the filter's target force (N) and rate (1/s).

    u (m/s) the relative velocity, u_n = u . e_Fc, v_full = |u| (eq. 14 uses the full
    relative speed); with the tangential option the component along e_Fc is removed first.
    """
    if machine[G_TANGENTIAL] != 0.0:
        c = u_n / (e0 * e0 + e1 * e1 + e2 * e2)
        u0, u1, u2 = u0 - c * e0, u1 - c * e1, u2 - c * e2
        (ev0, ev1, ev2), v = friction_direction(u0, u1, u2, machine[G_EPS])
    else:  # u is the full relative velocity: its norm is v_full, not taken again
        v = v_full
        ev0, ev1, ev2 = direction_of(u0, u1, u2, v, machine[G_EPS])
    mag = static_friction_magnitude(v, n_fric, r_a_act, product[P_D], product[P_MU_C],
                                    product[P_V_C], product[P_V_S], product[P_C_S])
    rate = filter_gain(v_full, product[P_QDOT_F]) / product[P_T_F]
    return mag * ev0, mag * ev1, mag * ev2, rate


# --- eq. (38): combined dynamics, world frame ----------------------------------------------

@jit
def rhs_world(y, product, machine, omega, out):
    """
    Evaluate eq. (38) with (37) in the world frame, as written in the paper.

    y: (9,) [q (m), qdot (m/s), Q_d (N)]; product: product row; machine: global row; omega (rad/s);
    out: (9,) receives [qdot, qddot (m/s^2), dQ_d/dt (N/s)].
    """
    h = machine[G_H]
    k = machine[G_K]
    s_perp, rho = cone_distance(y[0], y[1], y[2], h, k, machine[G_TIP_EPS])
    e0, e1, e2 = constraint_direction(y[0], y[1], k, rho)
    v_perp = normal_velocity(y[0], y[1], y[3], y[4], y[5], k, rho)
    r_a_act, _, n_force = normal_force(s_perp, v_perp, product[P_R_T], product[P_R_C],
                                       product[P_R_D], product[P_R_F])
    n_fric = n_force / product[P_R_F] if machine[G_LITERAL] != 0.0 else n_force
    u0, u1, u2 = relative_velocity(y[0:3], y[3:6], omega)
    v_full = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    q0, q1, q2, rate = friction_target(u0, u1, u2, u0 * e0 + u1 * e1 + u2 * e2, v_full,
                                       n_fric, r_a_act, e0, e1, e2, product, machine)
    m = product[P_M]
    out[0] = y[3]
    out[1] = y[4]
    out[2] = y[5]
    out[3] = (y[6] + n_force * e0) / m
    out[4] = (y[7] + n_force * e1) / m
    out[5] = (y[8] + n_force * e2) / m - machine[G_G]
    out[6] = rate * (q0 - y[6])
    out[7] = rate * (q1 - y[7])
    out[8] = rate * (q2 - y[8])


# --- the same system in the frame turning with the cone, with its Jacobian ---------------

@jit
def rhs(y, product, machine, omega, domega, out):
    """
    Evaluate the vector field in cone axes.

    y: (9,) [x (m), w (m/s), P (N)] in cone axes; omega (rad/s), domega (rad/s^2) the cone's
    angular velocity and acceleration; out: (9,) receives dy/dt.
    """
    h = machine[G_H]
    k = machine[G_K]
    x0, x1, x2 = y[0], y[1], y[2]
    w0, w1, w2 = y[3], y[4], y[5]
    s_perp, rho = cone_distance(x0, x1, x2, h, k, machine[G_TIP_EPS])
    e0, e1, e2 = constraint_direction(x0, x1, k, rho)
    v_perp = normal_velocity(x0, x1, w0, w1, w2, k, rho)
    r_a_act, _, n_force = normal_force(s_perp, v_perp, product[P_R_T], product[P_R_C],
                                       product[P_R_D], product[P_R_F])
    n_fric = n_force / product[P_R_F] if machine[G_LITERAL] != 0.0 else n_force
    v_full = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    q0, q1, q2, rate = friction_target(w0, w1, w2, v_perp, v_full, n_fric, r_a_act, e0, e1,
                                       e2, product, machine)
    write_field(y, product[P_M], machine[G_G], omega, domega, n_force, e0, e1, e2, q0, q1, q2,
                rate, out)


@jit
def write_field(y, m, g, omega, domega, n_force, e0, e1, e2, q0, q1, q2, rate, out):
    """
    Write dy/dt of :func:`rhs` into out (9,) from the forces at y.

    m (kg), g (m/s^2); n_force (N) along e = (e0, e1, e2); Q_s^c = (q0, q1, q2) (N) the
    filter's target and rate (1/s) its gain; plus the rotating frame's terms.
    """
    x0, x1 = y[0], y[1]
    w0, w1, w2 = y[3], y[4], y[5]
    om2 = omega * omega
    out[0] = w0
    out[1] = w1
    out[2] = w2
    inv_m = 1.0 / m
    out[3] = (y[6] + n_force * e0) * inv_m + 2.0 * omega * w1 + om2 * x0 + domega * x1
    out[4] = (y[7] + n_force * e1) * inv_m - 2.0 * omega * w0 + om2 * x1 - domega * x0
    out[5] = (y[8] + n_force * e2) * inv_m - g
    out[6] = rate * (q0 - y[6]) + omega * y[7]
    out[7] = rate * (q1 - y[7]) - omega * y[6]
    out[8] = rate * (q2 - y[8])


@jit
def rhs_omega_derivative(y, omega, out):
    """
    Return d(rhs)/d(omega) into out, shape (9,).

    Within a segment of constant angular acceleration, df/dt = domega * df/domega; the
    Rosenbrock method needs this time derivative of the non-autonomous field.
    """
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    out[3] = 2.0 * y[4] + 2.0 * omega * y[0]
    out[4] = -2.0 * y[3] + 2.0 * omega * y[1]
    out[5] = 0.0
    out[6] = y[7]
    out[7] = -y[6]
    out[8] = 0.0


@jit
def _vec3(a, b, c):
    return (a, b, c)


@jit
def jacobian(y, product, machine, omega, domega, jac):
    """Write the exact Jacobian d(rhs)/dy, shape (9, 9), of :func:`rhs` into jac."""
    rhs_jacobian(y, product, machine, omega, domega, np.empty(STATE_SIZE), jac)


@jit
def rhs_jacobian(y, product, machine, omega, domega, out, jac):
    """
    Write :func:`rhs` into out (9,) and its exact Jacobian d(rhs)/dy into jac (9, 9).

    One call at the same point: the radius, the activation, the speed and the friction
    curve's exp and tanh are evaluated once for both; out is bit for bit what :func:`rhs`
    gives (test_model). The Jacobian is derived by hand from the functions above;
    test_model checks it against finite differences for both friction-direction options
    and both normal-force readings. Small vectors are tuples.
    """
    h = machine[G_H]
    k = machine[G_K]
    eps = machine[G_EPS]
    m = product[P_M]
    inv_m = 1.0 / m
    d = product[P_D]
    mu_c = product[P_MU_C]
    v_c = product[P_V_C]
    v_s = product[P_V_S]
    c_s = product[P_C_S]
    r_t = product[P_R_T]
    r_d = product[P_R_D]
    r_f = product[P_R_F]
    t_f = product[P_T_F]
    qf = product[P_QDOT_F]
    x0, x1, x2 = y[0], y[1], y[2]
    w = _vec3(y[3], y[4], y[5])
    p = _vec3(y[6], y[7], y[8])
    # geometry: g = grad s_perp = e_Fc, hess = d g / d x (only the x-y block is non-zero)
    rho = regularised_radius(x0, x1, machine[G_TIP_EPS])
    s_perp = x2 - h + k * rho
    g = constraint_direction(x0, x1, k, rho)
    inv_rho = 1.0 / rho
    k_rho3 = k * inv_rho * inv_rho * inv_rho
    h00 = k * inv_rho - x0 * x0 * k_rho3
    h01 = -x0 * x1 * k_rho3
    h11 = k * inv_rho - x1 * x1 * k_rho3
    hess = (_vec3(h00, h01, 0.0), _vec3(h01, h11, 0.0), _vec3(0.0, 0.0, 0.0))
    v_perp = g[0] * w[0] + g[1] * w[1] + g[2] * w[2]
    hw = _vec3(h00 * w[0] + h01 * w[1], h01 * w[0] + h11 * w[1], 0.0)  # d v_perp / d x
    hg = _vec3(h00 * g[0] + h01 * g[1], h01 * g[0] + h11 * g[1], 0.0)
    # normal force and its gradients
    th_a = math.tanh(r_t * (s_perp - product[P_R_C]))
    r_a_act = 0.5 * (1.0 - th_a)
    dra_ds = -0.5 * r_t * (1.0 - th_a * th_a)
    th_c = math.tanh(r_d * v_perp)
    f_c = 0.5 * r_f * (1.0 - th_c)
    dfc_dv = -0.5 * r_f * r_d * (1.0 - th_c * th_c)
    n_force = r_a_act * f_c
    dra_dx = _vec3(dra_ds * g[0], dra_ds * g[1], dra_ds * g[2])
    dn_dx = _vec3(f_c * dra_dx[0] + r_a_act * dfc_dv * hw[0],
                  f_c * dra_dx[1] + r_a_act * dfc_dv * hw[1],
                  f_c * dra_dx[2] + r_a_act * dfc_dv * hw[2])
    cw = r_a_act * dfc_dv
    dn_dw = _vec3(cw * g[0], cw * g[1], cw * g[2])
    nscale = 1.0 / r_f if machine[G_LITERAL] != 0.0 else 1.0
    n_fric = n_force * nscale
    # friction velocity u and its Jacobians du/dx, du/dw
    if machine[G_TANGENTIAL] != 0.0:
        ig = 1.0 / (g[0] * g[0] + g[1] * g[1] + g[2] * g[2])  # 1/|g|^2
        c = v_perp * ig
        u = _vec3(w[0] - c * g[0], w[1] - c * g[1], w[2] - c * g[2])
        c2 = 2.0 * v_perp * ig * ig
        du_dw = (_vec3(1.0 - g[0] * g[0] * ig, -g[0] * g[1] * ig, -g[0] * g[2] * ig),
                 _vec3(-g[1] * g[0] * ig, 1.0 - g[1] * g[1] * ig, -g[1] * g[2] * ig),
                 _vec3(-g[2] * g[0] * ig, -g[2] * g[1] * ig, 1.0 - g[2] * g[2] * ig))
        du_dx = (_vec3(-(g[0] * hw[0] + v_perp * hess[0][0]) * ig + c2 * g[0] * hg[0],
                       -(g[0] * hw[1] + v_perp * hess[0][1]) * ig + c2 * g[0] * hg[1],
                       -(g[0] * hw[2] + v_perp * hess[0][2]) * ig + c2 * g[0] * hg[2]),
                 _vec3(-(g[1] * hw[0] + v_perp * hess[1][0]) * ig + c2 * g[1] * hg[0],
                       -(g[1] * hw[1] + v_perp * hess[1][1]) * ig + c2 * g[1] * hg[1],
                       -(g[1] * hw[2] + v_perp * hess[1][2]) * ig + c2 * g[1] * hg[2]),
                 _vec3(-(g[2] * hw[0] + v_perp * hess[2][0]) * ig + c2 * g[2] * hg[0],
                       -(g[2] * hw[1] + v_perp * hess[2][1]) * ig + c2 * g[2] * hg[1],
                       -(g[2] * hw[2] + v_perp * hess[2][2]) * ig + c2 * g[2] * hg[2]))
    else:
        u = w
        du_dw = (_vec3(1.0, 0.0, 0.0), _vec3(0.0, 1.0, 0.0), _vec3(0.0, 0.0, 1.0))
        du_dx = (_vec3(0.0, 0.0, 0.0), _vec3(0.0, 0.0, 0.0), _vec3(0.0, 0.0, 0.0))
    v = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    # friction magnitude phi(v, N, R_a) and psi = phi / (v + eps); Q_s = -psi u
    xi = v / v_s
    ex = math.exp(0.5 - 0.5 * xi * xi)
    sig = xi * ex
    dsig = ex * (1.0 - xi * xi) / v_s
    th_v = math.tanh(v / v_c)
    f_delta = c_s * n_fric - r_a_act * d * v_s
    phi = r_a_act * d * v + mu_c * n_fric * th_v + f_delta * sig
    dphi_dv = r_a_act * d + mu_c * n_fric * (1.0 - th_v * th_v) / v_c + f_delta * dsig
    dphi_dn = (mu_c * th_v + c_s * sig) * nscale
    dphi_dra = d * v - d * v_s * sig
    inv_ve = 1.0 / (v + eps)
    psi = phi * inv_ve
    dpsi_dv = (dphi_dv - psi) * inv_ve
    dpsi_dn = dphi_dn * inv_ve
    dpsi_dra = dphi_dra * inv_ve
    inv_v = 1.0 / v if v > 0.0 else 0.0  # grad v = u^T du/dz / v, taken as 0 where u = 0
    # the field itself, as rhs evaluates it (its normal velocity and force are its own)
    v_perp_f = normal_velocity(x0, x1, w[0], w[1], w[2], k, rho)
    n_force_f = r_a_act * constraint_force(v_perp_f, r_d, r_f)
    n_fric_f = n_force_f / r_f if machine[G_LITERAL] != 0.0 else n_force_f
    if machine[G_TANGENTIAL] != 0.0:
        v_full = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
        q0, q1, q2, rate_f = friction_target(w[0], w[1], w[2], v_perp_f, v_full, n_fric_f,
                                             r_a_act, g[0], g[1], g[2], product, machine)
    else:  # u = w: the speed, exp and tanh of the friction curve are the ones above
        f_delta_f = c_s * n_fric_f - r_a_act * d * v_s
        mag = r_a_act * d * v + mu_c * n_fric_f * th_v + f_delta_f * sig
        ev0, ev1, ev2 = direction_of(w[0], w[1], w[2], v, eps)
        q0, q1, q2 = mag * ev0, mag * ev1, mag * ev2
        rate_f = filter_gain(v, qf) / t_f
    write_field(y, m, machine[G_G], omega, domega, n_force_f, g[0], g[1], g[2], q0, q1, q2,
                rate_f, out)
    # filter gain a(|w|)
    ea = math.exp(-(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) / (qf * qf))
    rate = (1.0 - ea) / t_f
    da = 2.0 * ea / (qf * qf * t_f)
    for j in range(3):
        dv_dx_j = (u[0] * du_dx[0][j] + u[1] * du_dx[1][j] + u[2] * du_dx[2][j]) * inv_v
        dv_dw_j = (u[0] * du_dw[0][j] + u[1] * du_dw[1][j] + u[2] * du_dw[2][j]) * inv_v
        dpsi_dx_j = dpsi_dv * dv_dx_j + dpsi_dn * dn_dx[j] + dpsi_dra * dra_dx[j]
        dpsi_dw_j = dpsi_dv * dv_dw_j + dpsi_dn * dn_dw[j]
        for i in range(3):
            jac[i, j] = 0.0
            jac[i, 3 + j] = 1.0 if i == j else 0.0
            jac[i, 6 + j] = 0.0
            jac[3 + i, j] = (g[i] * dn_dx[j] + n_force * hess[i][j]) * inv_m
            jac[3 + i, 3 + j] = g[i] * dn_dw[j] * inv_m
            jac[3 + i, 6 + j] = inv_m if i == j else 0.0
            jac[6 + i, j] = rate * (-u[i] * dpsi_dx_j - psi * du_dx[i][j])
            jac[6 + i, 3 + j] = ((-psi * u[i] - p[i]) * da * w[j]
                                 + rate * (-u[i] * dpsi_dw_j - psi * du_dw[i][j]))
            jac[6 + i, 6 + j] = -rate if i == j else 0.0
    # rotating-frame terms
    om2 = omega * omega
    jac[3, 0] += om2
    jac[3, 1] += domega
    jac[4, 0] -= domega
    jac[4, 1] += om2
    jac[3, 4] += 2.0 * omega
    jac[4, 3] -= 2.0 * omega
    jac[6, 7] += omega
    jac[7, 6] -= omega
