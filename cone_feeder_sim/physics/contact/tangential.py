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
The tangential part of the pair law: a Mindlin spring with history, capped by Coulomb.

Each contact keeps its tangential displacement xi (m, 3-vector in the tangent plane): the
relative displacement of the two pieces' surfaces accumulated over the contact (LIGGGHTS
``tangential_model_history``). The spring's stiffness is S_t = 8 G* sqrt(R* delta). The
force is -S_t xi - gamma_t v_t while the spring holds (gamma_t = 2 sqrt(5/6) |beta|
sqrt(S_t m*), the tangential damping), that force scaled down to mu |F_n| where it would
exceed it, and mu |F_n| against xi once the spring alone would pull harder (or as hard:
with mu = 0, or no normal force, the contact has no tangential force at all): then the
contact slides and its history is rescaled to the cap. Sticking between
pieces is thus elastic, with no stiff regularisation. The history is dropped when the
contact ends.
"""

import math

import numba

from .normal import SQRT_FIVE_SIXTHS

__all__ = ['mindlin', 'rotate_and_cap', 'SLIDING_MARGIN']

jit = numba.njit(cache=True, error_model='numpy', nogil=True)

#: A history within this relative margin of its cap slides: the update leaves a sliding
#: contact's history at the cap (to round-off), and it must go on sliding, without the
#: damping of a sticking one (LIGGGHTS decides before it rescales, so a loaded sliding
#: contact never gets the damping).
SLIDING_MARGIN = 1.0e-9


@jit
def mindlin(h0, h1, h2, t0, t1, t2, s_t, m_star, beta, cap):
    """
    Return the tangential force (3 floats, N) and whether the contact slides.

    h (m) the history, t (m/s) the tangential relative velocity, s_t (N/m) the spring's
    stiffness, cap (N) = mu |F_n|. The spring and its damping together are capped (LAMMPS
    and LIGGGHTS cap the sum): a force that would exceed the cap is scaled down to it.
    """
    size = math.sqrt(h0 * h0 + h1 * h1 + h2 * h2)
    if s_t * size >= cap * (1.0 - SLIDING_MARGIN):  # no cap (mu = 0, F_n = 0): none holds
        if size == 0.0:
            return 0.0, 0.0, 0.0, True
        scale = -cap / size
        return scale * h0, scale * h1, scale * h2, True
    gamma = -2.0 * SQRT_FIVE_SIXTHS * beta * math.sqrt(s_t * m_star)
    f0, f1, f2 = -s_t * h0 - gamma * t0, -s_t * h1 - gamma * t1, -s_t * h2 - gamma * t2
    total = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
    if total > cap:
        scale = cap / total
        return scale * f0, scale * f1, scale * f2, True
    return f0, f1, f2, False


@jit
def rotate_and_cap(h0, h1, h2, n0, n1, n2, s_t, cap):
    """
    Return the history (3 floats, m) in the tangent plane of n, rescaled to the cap.

    The normal component is removed (the tangent plane turned with the contact), and a
    history whose spring would pull harder than cap (N) is shortened to S_t |xi| = cap.
    """
    along = h0 * n0 + h1 * n1 + h2 * n2
    h0, h1, h2 = h0 - along * n0, h1 - along * n1, h2 - along * n2
    size = math.sqrt(h0 * h0 + h1 * h1 + h2 * h2)
    if s_t * size > cap:
        scale = cap / (s_t * size)
        return scale * h0, scale * h1, scale * h2
    return h0, h1, h2
