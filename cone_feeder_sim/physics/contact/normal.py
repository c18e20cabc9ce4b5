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
The normal part of the pair law: Hertz with restitution damping (LIGGGHTS ``hertz``).

With overlap delta (m) and the pair's effective modulus Y* (Pa), radius R* (m) and mass
m* (kg), the normal stiffness is S_n = 2 Y* sqrt(R* delta), the elastic force
4/3 Y* sqrt(R*) delta^(3/2), and the damping 2 sqrt(5/6) |beta| sqrt(S_n m*) times the
closing speed, beta = ln e / sqrt(ln^2 e + pi^2) for the restitution e. The force is not
clipped at zero: it may pull for a moment before the pieces part, and that is what gives
a collision the restitution e at every speed (Antypov & Elliott 2011; measured:
test/physics/test_contact.py).
"""

import math

import numba

__all__ = ['damping_ratio', 'hertz']

jit = numba.njit(cache=True, error_model='numpy', nogil=True)

#: sqrt(5/6), the factor of the damping (Tsuji et al. 1992, as LIGGGHTS writes it).
SQRT_FIVE_SIXTHS = math.sqrt(5.0 / 6.0)


def damping_ratio(restitution: float) -> float:
    """Return beta = ln e / sqrt(ln^2 e + pi^2), <= 0 (0 for e = 1)."""
    log_e = math.log(restitution)
    return log_e / math.sqrt(log_e * log_e + math.pi * math.pi)


@jit
def hertz(delta, v_n, y_star, r_star, m_star, beta):
    """
    Return (F_n, S_n): the normal force (N, > 0 pushes apart) and stiffness (N/m).

    delta (m) > 0 the overlap; v_n (m/s) the normal relative velocity, > 0 separating.
    """
    root = math.sqrt(r_star * delta)
    s_n = 2.0 * y_star * root
    elastic = (4.0 / 3.0) * y_star * root * delta
    gamma = -2.0 * SQRT_FIVE_SIXTHS * beta * math.sqrt(s_n * m_star)
    return elastic - gamma * v_n, s_n
