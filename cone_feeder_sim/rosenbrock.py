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
whose vector field it calls through :func:`cone_feeder_sim.model.rhs`. test_rosenbrock
checks the order of convergence on problems with exact solutions.
"""

import numba
import numpy as np

from cone_feeder_sim.model import jacobian, rhs, rhs_omega_derivative, STATE_SIZE

jit = numba.njit(cache=True, error_model='numpy')

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
ORDER = 4
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
def rodas_step(y0, f0, t0, h, omega0, domega, pp, gp, jac, piv, k, f, ft, ys, y1):
    """
    Take one RODAS4 step of size h from y0 (f0 = rhs at y0) and write the result into y1.

    The cone's angular velocity is omega0 + domega * (t - t0) during the step (the step must
    not cross a breakpoint of the rotation input). jac, piv, k (6, 9), f, ft, ys are scratch
    arrays. Returns False if the linear system could not be factored; otherwise k[5] holds
    the embedded error estimate.
    """
    n = y0.shape[0]
    jacobian(y0, pp, gp, omega0, domega, jac)
    rhs_omega_derivative(y0, omega0, ft)
    for i in range(n):
        ft[i] *= domega
    inv_gh = 1.0 / (GAMMA * h)
    for i in range(n):
        for j in range(n):
            jac[i, j] = -jac[i, j]
        jac[i, i] += inv_gh
    if not lu_factor(jac, piv):
        return False
    # stage 1
    for i in range(n):
        k[0, i] = f0[i] + h * D1 * ft[i]
    lu_solve(jac, piv, k[0])
    # stage 2
    for i in range(n):
        ys[i] = y0[i] + A21 * k[0, i]
    rhs(ys, pp, gp, omega0 + domega * C2 * h, domega, f)
    for i in range(n):
        k[1, i] = f[i] + h * D2 * ft[i] + C21 * k[0, i] / h
    lu_solve(jac, piv, k[1])
    # stage 3
    for i in range(n):
        ys[i] = y0[i] + A31 * k[0, i] + A32 * k[1, i]
    rhs(ys, pp, gp, omega0 + domega * C3 * h, domega, f)
    for i in range(n):
        k[2, i] = f[i] + h * D3 * ft[i] + (C31 * k[0, i] + C32 * k[1, i]) / h
    lu_solve(jac, piv, k[2])
    # stage 4
    for i in range(n):
        ys[i] = y0[i] + A41 * k[0, i] + A42 * k[1, i] + A43 * k[2, i]
    rhs(ys, pp, gp, omega0 + domega * C4 * h, domega, f)
    for i in range(n):
        k[3, i] = (f[i] + h * D4 * ft[i]
                   + (C41 * k[0, i] + C42 * k[1, i] + C43 * k[2, i]) / h)
    lu_solve(jac, piv, k[3])
    # stage 5
    for i in range(n):
        ys[i] = y0[i] + A51 * k[0, i] + A52 * k[1, i] + A53 * k[2, i] + A54 * k[3, i]
    omega1 = omega0 + domega * h
    rhs(ys, pp, gp, omega1, domega, f)
    for i in range(n):
        k[4, i] = f[i] + (C51 * k[0, i] + C52 * k[1, i] + C53 * k[2, i]
                          + C54 * k[3, i]) / h
    lu_solve(jac, piv, k[4])
    # stage 6 (error estimate)
    for i in range(n):
        ys[i] += k[4, i]
    rhs(ys, pp, gp, omega1, domega, f)
    for i in range(n):
        k[5, i] = f[i] + (C61 * k[0, i] + C62 * k[1, i] + C63 * k[2, i] + C64 * k[3, i]
                          + C65 * k[4, i]) / h
    lu_solve(jac, piv, k[5])
    for i in range(n):
        y1[i] = ys[i] + k[5, i]
    return True
