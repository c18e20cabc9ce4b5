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
Detections to the twin's pieces: a chi-square gate, then an optimal assignment.

Each piece the twin keeps has a predicted position (the ensemble mean) and its covariance
(the ensemble's, plus the detection noise): the squared Mahalanobis distance of a
detection to it is chi-square with 2 degrees of freedom when the detection is that piece.
Pairs beyond the gate (:data:`GATE_CHI2`, the 0.999 quantile) cannot be assigned; among
the rest, :func:`scipy.optimize.linear_sum_assignment` finds the assignment of least total
distance (the global nearest neighbour of tracking practice). Pieces left without a
detection were missed this frame; detections left without a piece are births or false
detections, for the caller to weigh.
"""

from dataclasses import dataclass
import math

import numpy as np
from scipy.optimize import linear_sum_assignment

__all__ = ['associate', 'Association', 'GATE_CHI2']

#: The gate: the 0.999 quantile of chi-square with 2 degrees of freedom (13.8). That
#: distribution is the exponential of mean 2, so the quantile is -2 ln(1 - 0.999), in closed
#: form (scipy.stats would add 0.4 s to twin_node's start-up).
GATE_CHI2 = -2.0 * math.log(1.0 - 0.999)
#: The cost of a gated-out pair in the assignment (never chosen over a real one).
_FORBIDDEN = 1.0e12


@dataclass(frozen=True)
class Association:
    """
    Which detection belongs to which piece.

    pairs: (k, 2) int, (piece, detection) rows; distance: (k,) their squared Mahalanobis
    distances; missed: the pieces without a detection; unassigned: the detections without
    a piece (indices into the caller's arrays, ascending).
    """

    pairs: np.ndarray
    distance: np.ndarray
    missed: np.ndarray
    unassigned: np.ndarray


def associate(predicted: np.ndarray, covariance: np.ndarray, detections: np.ndarray,
              gate: float = GATE_CHI2) -> Association:
    """
    Assign detections (k, 2) m to the pieces predicted at predicted (n, 2) m.

    covariance: (n, 2, 2) m^2, each piece's predicted position covariance with the
    detection noise added (positive definite). gate: the largest squared Mahalanobis
    distance of an assigned pair.
    """
    n, k = len(predicted), len(detections)
    if n == 0 or k == 0:
        return Association(np.empty((0, 2), dtype=np.int64), np.empty(0),
                           np.arange(n), np.arange(k))
    difference = detections[None, :, :] - predicted[:, None, :]  # (n, k, 2)
    inverse = np.linalg.inv(covariance)  # (n, 2, 2)
    distance = np.einsum('nki,nij,nkj->nk', difference, inverse, difference)
    cost = np.where(distance <= gate, distance, _FORBIDDEN)
    rows, cols = linear_sum_assignment(cost)
    keep = cost[rows, cols] < _FORBIDDEN
    rows, cols = rows[keep], cols[keep]
    return Association(np.column_stack([rows, cols]).astype(np.int64), distance[rows, cols],
                       np.setdiff1d(np.arange(n), rows), np.setdiff1d(np.arange(k), cols))
