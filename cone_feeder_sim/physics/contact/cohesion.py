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
The cohesion part of the pair law: a pull in proportion to the contact area (SJKR).

Sticky meat: two overlapping pieces pull each other with k A, where A (m^2) is the area of
the circle in which their spheres intersect and k (N/m^2) a cohesion energy density
(LIGGGHTS ``cohesion_model_sjkr``). The pull is zero where the pieces just touch and
grows with the overlap, while Hertz's push grows faster: the net pull between two pieces
has a largest value, the pull-off force. The product sets k from that force for two
default pieces (:func:`density_for_pull_off`), a figure one can measure.
"""

import functools
import math

import numba

__all__ = ['contact_area', 'density_for_pull_off', 'largest_pull']

jit = numba.njit(cache=True, error_model='numpy', nogil=True)


@jit
def contact_area(dist, r_i, r_j):
    """Return the area (m^2) of the circle where spheres r_i, r_j at distance dist meet."""
    if dist >= r_i + r_j:
        return 0.0
    if dist <= abs(r_i - r_j):
        small = min(r_i, r_j)
        return math.pi * small * small
    return -0.25 * math.pi * ((dist - r_i - r_j) * (dist + r_i - r_j) * (dist - r_i + r_j)
                              * (dist + r_i + r_j)) / (dist * dist)


def _net_pull(delta: float, density: float, y_star: float, r_i: float, r_j: float) -> float:
    """Return the static pull (N) at overlap delta: cohesion minus Hertz's push."""
    r_star = r_i * r_j / (r_i + r_j)
    push = 4.0 / 3.0 * y_star * math.sqrt(r_star) * delta ** 1.5
    return density * contact_area(r_i + r_j - delta, r_i, r_j) - push


def largest_pull(density: float, y_star: float, r_i: float, r_j: float) -> float:
    """Return the largest static pull (N) of two pieces (radii r_i, r_j m, modulus Y* Pa)."""
    if density <= 0.0:
        return 0.0
    from scipy.optimize import minimize_scalar  # here: 0.3 s of a start without contact
    best = minimize_scalar(lambda d: -_net_pull(d, density, y_star, r_i, r_j),
                           bounds=(0.0, min(r_i, r_j)), method='bounded',
                           options={'xatol': 1e-12 * min(r_i, r_j)})
    return max(0.0, -float(best.fun))


@functools.lru_cache(maxsize=256)
def density_for_pull_off(pull_off: float, y_star: float, r_i: float, r_j: float) -> float:
    """
    Return the cohesion energy density k (N/m^2) whose largest pull is pull_off (N).

    Remembered for the last 256 arguments: every set of model parameters asks for it
    (3 ms of root finding each: 20 % of a fit's time on short tracks, measured).

    For pieces of radii r_i, r_j (m) and pair modulus Y* (Pa), static (no damping): the
    largest over the overlap of k A(delta) - 4/3 Y* sqrt(R*) delta^(3/2). For small
    overlaps A = 2 pi R* delta, which gives k = (3 Y*^2 P / (2 pi^3 R*^2))^(1/3) as a first
    guess; the exact area is solved for.
    """
    if pull_off <= 0.0:
        return 0.0
    r_star = r_i * r_j / (r_i + r_j)
    if not r_star > 0.0:  # radii that underflow (a limit's edge): nothing to size
        return 0.0
    guess = ((3.0 * pull_off / (2.0 * math.pi ** 3)) ** (1.0 / 3.0) * y_star ** (2.0 / 3.0)
             / r_star ** (2.0 / 3.0))
    lo, hi = guess / 4.0, guess * 4.0
    for _ in range(64):
        if largest_pull(hi, y_star, r_i, r_j) >= pull_off:
            break
        hi *= 4.0
    else:  # degenerate sizes (far below a millimetre): no density reaches the pull
        return guess if math.isfinite(guess) else 0.0
    from scipy.optimize import brentq
    return brentq(lambda k: largest_pull(k, y_star, r_i, r_j) - pull_off, lo, hi,
                  xtol=1e-14 * guess, rtol=1e-12)
