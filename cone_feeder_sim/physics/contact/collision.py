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
What the pair law predicts for a head-on collision in free flight (for tools and docs).

Two pieces approach along their line of centres; with no tangential motion and gravity
acting on both alike, their overlap delta obeys one equation,
m* delta'' = -(F_n(delta, -delta') - F_coh(delta)), integrated here to a tight tolerance
from first touch until they part (or stay together). doc/model.md quotes these figures.
"""

from dataclasses import dataclass
import math

import numpy as np
from scipy.integrate import solve_ivp

from .cohesion import contact_area
from .law import I_BETA, I_COHESION, pair_constants
from .normal import hertz
from ..params import P_S0

__all__ = ['Collision', 'head_on_collision']


@dataclass(frozen=True)
class Collision:
    """
    A head-on collision.

    restitution (separation over closing speed; 0 if the pieces stay together), duration
    (s) of the contact (0 < delta), the largest overlap (m) and the largest push (N).
    """

    restitution: float
    duration: float
    max_overlap: float
    max_force: float


def head_on_collision(pi: np.ndarray, pj: np.ndarray, inter: np.ndarray, speed: float,
                      t_max: float = 5.0) -> Collision:
    """
    Return the collision of pieces with product rows pi, pj at closing speed ``speed`` m/s.

    inter: the law's row (:func:`.law.interaction_row`). Radau at rtol 1e-11 from first
    touch until the overlap returns to zero, or t_max (s).
    """
    r_star, m_star, y_star, _ = pair_constants(pi, pj)
    r_i, r_j = float(pi[P_S0]), float(pj[P_S0])

    def normal(delta: float, rate: float) -> float:
        if delta <= 0.0:
            return 0.0
        push, _ = hertz(delta, -rate, y_star, r_star, m_star, inter[I_BETA])
        return push - inter[I_COHESION] * contact_area(r_i + r_j - delta, r_i, r_j)

    def field(_t: float, z: np.ndarray) -> list[float]:
        return [z[1], -normal(z[0], z[1]) / m_star]

    def parted(t: float, z: np.ndarray) -> float:
        return z[0] if t > 0.0 else 1.0

    parted.terminal = True  # type: ignore[attr-defined]
    parted.direction = -1.0  # type: ignore[attr-defined]
    scale = max(speed, 1e-6)
    sol = solve_ivp(field, (0.0, t_max), [0.0, speed], method='Radau', rtol=1e-11,
                    atol=[1e-14, 1e-12 * scale], events=parted, dense_output=True,
                    max_step=t_max / 1000.0)
    times = np.linspace(0.0, float(sol.t[-1]), 4001)
    delta, rate = sol.sol(times)
    force = np.array([normal(d, v) for d, v in zip(delta, rate)])
    together = sol.status != 1
    return Collision(restitution=0.0 if together else -float(sol.y[1, -1]) / speed,
                     duration=math.inf if together else float(sol.t[-1]),
                     max_overlap=float(delta.max()), max_force=float(force.max()))
