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
RODAS4: a 6-stage, order 4(3), L-stable, stiffly accurate Rosenbrock method.

Coefficients are those of Hairer and Wanner, "Solving Ordinary Differential Equations II",
2nd ed., Springer 1996, section IV.7 (code RODAS, method 1), written for the form

    W = I/(gamma h) - J,   W k_i = f(t0 + c_i h, y0 + sum_j a_ij k_j) + h d_i f_t
                                    + sum_j c_ij k_j / h,

    y1 = y0 + sum_{j<=4} a_5j k_j + k_5 + k_6,  error estimate k_6.

This module knows nothing about the physics: it takes a step of a 9-dimensional system
whose vector field it calls through :func:`cone_feeder_sim.physics.model.rhs`. test_rosenbrock
checks the order of convergence on problems with exact solutions.
"""

import numba
import numpy as np

from .model import rhs, rhs_jacobian, rhs_omega_derivative

jit = numba.njit(cache=True, error_model='numpy', nogil=True)

GAMMA = 0.25
C2, C3, C4 = 0.386, 0.21, 0.63
D1, D2, D3, D4 = 0.25, -0.1043, 0.1035, -0.3620000000000023e-01
A21 = 0.1544e1
A31, A32 = 0.9466785280815826, 0.2557011698983284
A41, A42, A43 = 0.3314825187068521e1, 0.2896124015972201e1, 0.9986419139977817
A51, A52, A53, A54 = (0.1221224509226641e1, 0.6019134481288629e1, 0.1253708332932087e2,
                      -0.6878860361058950)
C21 = -0.56688e1
C31, C32 = -0.2430093356833875e1, -0.2063599157091915
C41, C42, C43 = -0.1073529058151375, -0.9594562251023355e1, -0.2047028614809616e2
C51, C52, C53, C54 = (0.7496443313967647e1, -0.1024680431464352e2, -0.3399990352819905e2,
                      0.1170890893206160e2)
C61, C62, C63, C64, C65 = (0.8083246795921522e1, -0.7981132988064893e1,
                           -0.3152159432874371e2, 0.1631930543123136e2,
                           -0.6058818238834054e1)
#: Order of the embedded error estimate (the method itself is of order 4).
ERROR_ORDER = 3


@jit
def lu_factor(a, piv):
    """
    Factor the square matrix a in place (LU with partial pivoting); piv receives the rows.

    Returns False when a pivot is zero or not finite (the step is then rejected).
    """
    n = a.shape[0]
    for k in range(n):
        p = k
        big = abs(a[k, k])
        for i in range(k + 1, n):
            if abs(a[i, k]) > big:
                big = abs(a[i, k])
                p = i
        piv[k] = p
        if not big > 0.0 or not np.isfinite(big):
            return False
        if p != k:
            for j in range(n):
                tmp = a[k, j]
                a[k, j] = a[p, j]
                a[p, j] = tmp
        inv = 1.0 / a[k, k]
        for i in range(k + 1, n):
            a[i, k] *= inv
            f = a[i, k]
            if f != 0.0:
                for j in range(k + 1, n):
                    a[i, j] -= f * a[k, j]
    return True


@jit
def lu_solve(lu, piv, b):
    """Solve lu x = b in place in b, with lu and piv from :func:`lu_factor`."""
    n = lu.shape[0]
    for k in range(n):
        p = piv[k]
        if p != k:
            tmp = b[k]
            b[k] = b[p]
            b[p] = tmp
    for i in range(1, n):
        s = b[i]
        for j in range(i):
            s -= lu[i, j] * b[j]
        b[i] = s
    for i in range(n - 1, -1, -1):
        s = b[i]
        for j in range(i + 1, n):
            s -= lu[i, j] * b[j]
        b[i] = s / lu[i, i]


@jit
def solve3(lu, piv, b0, b1, b2):
    """
    Solve a 3x3 system factored by :func:`factor3`; return the solution as a tuple.

    The diagonal of lu holds the reciprocals of the pivots, so no division is needed.
    """
    # row interchanges, in the order the factorisation made them
    p = piv[0]
    if p == 1:
        b0, b1 = b1, b0
    elif p == 2:
        b0, b2 = b2, b0
    if piv[1] == 2:
        b1, b2 = b2, b1
    b1 -= lu[1, 0] * b0
    b2 -= lu[2, 0] * b0 + lu[2, 1] * b1
    b2 *= lu[2, 2]
    b1 = (b1 - lu[1, 2] * b2) * lu[1, 1]
    b0 = (b0 - lu[0, 1] * b1 - lu[0, 2] * b2) * lu[0, 0]
    return b0, b1, b2


@jit
def factor3(a, piv):
    """Factor a 3x3 matrix in place like :func:`lu_factor`, then invert its pivots."""
    if not lu_factor(a, piv):
        return False
    for i in range(3):
        a[i, i] = 1.0 / a[i, i]
    return True


@jit
def invert_filter_block(jac, alpha, m_inv):
    """
    Write M^-1 into m_inv (3, 3), M = alpha I - F, in closed form; False if M is singular.

    F = J[6:9, 6:9], the filter's block, has the form [[f00, f01, 0], [f10, f11, 0],
    [0, 0, f22]] (the filter's rate on the diagonal, the turning frame's omega coupling the
    first two rows; :func:`.model.rhs_jacobian`): a 2x2 block and a scalar.
    """
    a00 = alpha - jac[6, 6]
    a01 = -jac[6, 7]
    a10 = -jac[7, 6]
    a11 = alpha - jac[7, 7]
    a22 = alpha - jac[8, 8]
    det = a00 * a11 - a01 * a10
    if not (det != 0.0 and np.isfinite(det) and a22 != 0.0 and np.isfinite(a22)):
        return False
    inv = 1.0 / det
    m_inv[0, 0] = a11 * inv
    m_inv[0, 1] = -a01 * inv
    m_inv[1, 0] = -a10 * inv
    m_inv[1, 1] = a00 * inv
    m_inv[2, 2] = 1.0 / a22
    return True


@jit
def filter_solve(m_inv, b0, b1, b2):
    """Return M^-1 b as a tuple, m_inv from :func:`invert_filter_block`."""
    return (m_inv[0, 0] * b0 + m_inv[0, 1] * b1, m_inv[1, 0] * b0 + m_inv[1, 1] * b1,
            m_inv[2, 2] * b2)


@jit
def eliminate_filter(jac, alpha, m_inv, tmat, s):
    """
    Eliminate x and P from W = alpha I - J; write the velocity block S into s (3, 3).

    J as in :func:`factor_mechanical`: m_inv (3, 3) receives M^-1, M = alpha I - F
    (:func:`invert_filter_block`); tmat (3, 3) receives T = M^-1 (D/alpha + E);
    s = alpha I - B - A/alpha - C T, not factored (the contact kernels add pair blocks to
    it). Returns False if M is singular.
    """
    inv_a = 1.0 / alpha
    if not invert_filter_block(jac, alpha, m_inv):
        return False
    for j in range(3):
        c0, c1, c2 = filter_solve(m_inv, jac[6, j] * inv_a + jac[6, 3 + j],
                                  jac[7, j] * inv_a + jac[7, 3 + j],
                                  jac[8, j] * inv_a + jac[8, 3 + j])
        tmat[0, j] = c0
        tmat[1, j] = c1
        tmat[2, j] = c2
    for i in range(3):
        for j in range(3):
            s[i, j] = (-jac[3 + i, 3 + j] - jac[3 + i, j] * inv_a
                       - jac[3 + i, 6] * tmat[0, j] - jac[3 + i, 7] * tmat[1, j]
                       - jac[3 + i, 8] * tmat[2, j])
        s[i, i] += alpha
    return True


@jit
def factor_mechanical(jac, alpha, m_inv, lu_s, tmat, piv_s):
    """
    Factor W = alpha I - J for a mechanical system, using its block structure.

    J (9, 9) must have the block rows [0, I, 0] (dx/dt = w), [A, B, C] and [D, E, F] for
    the state blocks (x, w, P), F as :func:`invert_filter_block` needs it. Eliminating x and
    P leaves two 3x3 systems: M = alpha I - F, inverted in closed form, and the Schur
    complement S = alpha I - B - A/alpha - C M^-1 (D/alpha + E), factored. m_inv (3, 3)
    receives M^-1, lu_s (3, 3) LU(S) (see :func:`factor3`), tmat (3, 3) is scratch, piv_s
    (3,) receives S's pivots. Much cheaper than a dense 9x9 factorisation; test_rosenbrock
    compares it with a dense solve. Returns False if a pivot vanishes or is not finite.
    """
    if not eliminate_filter(jac, alpha, m_inv, tmat, lu_s):
        return False
    return factor3(lu_s, piv_s)


@jit
def solve_mechanical(jac, alpha, m_inv, lu_s, piv_s, kk, r):
    """Solve W k = b in place in row r of kk (·, 9), using :func:`factor_mechanical`'s."""
    inv_a = 1.0 / alpha
    bx0 = kk[r, 0] * inv_a
    bx1 = kk[r, 1] * inv_a
    bx2 = kk[r, 2] * inv_a
    b6 = kk[r, 6]
    b7 = kk[r, 7]
    b8 = kk[r, 8]
    # c = M^-1 (b_P + D b_x / alpha)
    c0, c1, c2 = filter_solve(
        m_inv,
        b6 + jac[6, 0] * bx0 + jac[6, 1] * bx1 + jac[6, 2] * bx2,
        b7 + jac[7, 0] * bx0 + jac[7, 1] * bx1 + jac[7, 2] * bx2,
        b8 + jac[8, 0] * bx0 + jac[8, 1] * bx1 + jac[8, 2] * bx2)
    # S k_w = b_w + A b_x / alpha + C c
    kw0, kw1, kw2 = solve3(
        lu_s, piv_s,
        kk[r, 3] + jac[3, 0] * bx0 + jac[3, 1] * bx1 + jac[3, 2] * bx2
        + jac[3, 6] * c0 + jac[3, 7] * c1 + jac[3, 8] * c2,
        kk[r, 4] + jac[4, 0] * bx0 + jac[4, 1] * bx1 + jac[4, 2] * bx2
        + jac[4, 6] * c0 + jac[4, 7] * c1 + jac[4, 8] * c2,
        kk[r, 5] + jac[5, 0] * bx0 + jac[5, 1] * bx1 + jac[5, 2] * bx2
        + jac[5, 6] * c0 + jac[5, 7] * c1 + jac[5, 8] * c2)
    kx0 = bx0 + kw0 * inv_a
    kx1 = bx1 + kw1 * inv_a
    kx2 = bx2 + kw2 * inv_a
    # k_P = M^-1 (b_P + D k_x + E k_w)
    kp0, kp1, kp2 = filter_solve(
        m_inv,
        b6 + jac[6, 0] * kx0 + jac[6, 1] * kx1 + jac[6, 2] * kx2
        + jac[6, 3] * kw0 + jac[6, 4] * kw1 + jac[6, 5] * kw2,
        b7 + jac[7, 0] * kx0 + jac[7, 1] * kx1 + jac[7, 2] * kx2
        + jac[7, 3] * kw0 + jac[7, 4] * kw1 + jac[7, 5] * kw2,
        b8 + jac[8, 0] * kx0 + jac[8, 1] * kx1 + jac[8, 2] * kx2
        + jac[8, 3] * kw0 + jac[8, 4] * kw1 + jac[8, 5] * kw2)
    kk[r, 0] = kx0
    kk[r, 1] = kx1
    kk[r, 2] = kx2
    kk[r, 3] = kw0
    kk[r, 4] = kw1
    kk[r, 5] = kw2
    kk[r, 6] = kp0
    kk[r, 7] = kp1
    kk[r, 8] = kp2


@jit
def add_load(load, rate, dt, f):
    """
    Add the acceleration load + rate dt to the velocity rows of f (9,).

    load (3,) (m/s^2) at the step's start, rate (3,) (m/s^3) its time derivative, dt (s) the
    time since the step's start.
    """
    f[3] += load[0] + rate[0] * dt
    f[4] += load[1] + rate[1] * dt
    f[5] += load[2] + rate[2] * dt


@jit
def prepare_step(y0, omega0, domega, product, machine, work, k, f0):
    """
    Evaluate what a step from y0 needs, whatever its size.

    The field goes into f0 (9,), the Jacobian into work[0] (one call at the same point)
    and the time derivative of the field, domega * df/domega, into k[7].

    A rejected step is retried with the same Jacobian: only W = I/(gamma h) - J changes.
    """
    rhs_jacobian(y0, product, machine, omega0, domega, f0, work[0])
    ft = k[7]
    rhs_omega_derivative(y0, omega0, ft)
    for i in range(ft.shape[0]):
        ft[i] *= domega


@jit
def rodas_step(y0, f0, h, omega0, domega, product, machine, load, rate, work, piv, k,
               y1):
    """
    Take one RODAS4 step of size h from y0 (f0 = rhs at y0) and write the result into y1.

    load (3,) (m/s^2) is an acceleration added to the velocity rows of the field at the
    step's start, changing at rate (3,) (m/s^3) (the pair forces of the multirate coupling,
    :mod:`coupling`; zeros for a piece alone); f0 must include it, and the time derivative
    k[7] its rate.

    :func:`prepare_step` must have been called for y0 first. The cone's angular velocity is
    omega0 + domega * (t - t0) during the step (the step must not cross a breakpoint of the
    rotation input). work (2, 9, 9) float64 and piv (2, 3) int64 are scratch arrays; k (9, 9)
    receives the stages in rows 0..5 (row 5 is the embedded error estimate) and uses rows
    6..8 as scratch (row 7 holds the time derivative from prepare_step). Returns False if
    the linear system could not be factored.
    """
    n = y0.shape[0]
    jac = work[0]
    m_inv = work[1, 0:3, 0:3]
    lu_s = work[1, 3:6, 0:3]
    tmat = work[1, 6:9, 0:3]
    piv_s = piv[1]
    f = k[6]
    ft = k[7]
    ys = k[8]
    alpha = 1.0 / (GAMMA * h)
    if not factor_mechanical(jac, alpha, m_inv, lu_s, tmat, piv_s):
        return False
    # stage 1
    for i in range(n):
        k[0, i] = f0[i] + h * D1 * ft[i]
    solve_mechanical(jac, alpha, m_inv, lu_s, piv_s, k, 0)
    # stage 2
    for i in range(n):
        ys[i] = y0[i] + A21 * k[0, i]
    rhs(ys, product, machine, omega0 + domega * C2 * h, domega, f)
    add_load(load, rate, C2 * h, f)
    for i in range(n):
        k[1, i] = f[i] + h * D2 * ft[i] + C21 * k[0, i] / h
    solve_mechanical(jac, alpha, m_inv, lu_s, piv_s, k, 1)
    # stage 3
    for i in range(n):
        ys[i] = y0[i] + A31 * k[0, i] + A32 * k[1, i]
    rhs(ys, product, machine, omega0 + domega * C3 * h, domega, f)
    add_load(load, rate, C3 * h, f)
    for i in range(n):
        k[2, i] = f[i] + h * D3 * ft[i] + (C31 * k[0, i] + C32 * k[1, i]) / h
    solve_mechanical(jac, alpha, m_inv, lu_s, piv_s, k, 2)
    # stage 4
    for i in range(n):
        ys[i] = y0[i] + A41 * k[0, i] + A42 * k[1, i] + A43 * k[2, i]
    rhs(ys, product, machine, omega0 + domega * C4 * h, domega, f)
    add_load(load, rate, C4 * h, f)
    for i in range(n):
        k[3, i] = (f[i] + h * D4 * ft[i]
                   + (C41 * k[0, i] + C42 * k[1, i] + C43 * k[2, i]) / h)
    solve_mechanical(jac, alpha, m_inv, lu_s, piv_s, k, 3)
    # stage 5
    for i in range(n):
        ys[i] = y0[i] + A51 * k[0, i] + A52 * k[1, i] + A53 * k[2, i] + A54 * k[3, i]
    omega1 = omega0 + domega * h
    rhs(ys, product, machine, omega1, domega, f)
    add_load(load, rate, h, f)
    for i in range(n):
        k[4, i] = f[i] + (C51 * k[0, i] + C52 * k[1, i] + C53 * k[2, i]
                          + C54 * k[3, i]) / h
    solve_mechanical(jac, alpha, m_inv, lu_s, piv_s, k, 4)
    # stage 6 (error estimate)
    for i in range(n):
        ys[i] += k[4, i]
    rhs(ys, product, machine, omega1, domega, f)
    add_load(load, rate, h, f)
    for i in range(n):
        k[5, i] = f[i] + (C61 * k[0, i] + C62 * k[1, i] + C63 * k[2, i] + C64 * k[3, i]
                          + C65 * k[4, i]) / h
    solve_mechanical(jac, alpha, m_inv, lu_s, piv_s, k, 5)
    for i in range(n):
        y1[i] = ys[i] + k[5, i]
    return True
