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
The rotation input: the cone's angular velocity omega(t) as a piecewise-linear table.

omega > 0 turns the cone counter-clockwise seen from above (REP-103); the paper's
"clockwise" rotation is omega < 0. The cone angle phi(t) = integral of omega from t = 0
(phi(0) = 0) is computed exactly (omega is linear between points, so phi is piecewise
quadratic): no numerical integration error enters the cone angle.
"""

from collections.abc import Sequence
from dataclasses import dataclass
import math
from typing import Any

import numpy as np

from ..errors import ParameterError


@dataclass(frozen=True)
class RotationProfile:
    """
    Piecewise-linear omega(t): linear between points, held constant before and after.

    times: (K,) strictly increasing (s); omegas: (K,) angular velocity (rad/s).
    """

    times: np.ndarray
    omegas: np.ndarray

    def __post_init__(self) -> None:
        """Validate and freeze the arrays; precompute the angle at every point."""
        times = np.array(self.times, dtype=np.float64).reshape(-1)
        omegas = np.array(self.omegas, dtype=np.float64).reshape(-1)
        if times.size == 0 or times.shape != omegas.shape:
            raise ParameterError('rotation table needs at least one [t, omega] point, with '
                                 'as many times as angular velocities')
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(omegas))):
            raise ParameterError('rotation table contains a non-finite time or omega')
        if np.any(np.diff(times) <= 0.0):
            raise ParameterError('rotation table times must be strictly increasing')
        times.setflags(write=False)
        omegas.setflags(write=False)
        object.__setattr__(self, 'times', times)
        object.__setattr__(self, 'omegas', omegas)
        # angle accumulated from times[0] to each point (trapezoid is exact for linear omega)
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (omegas[1:] + omegas[:-1])
                                               * np.diff(times))])
        cum.setflags(write=False)
        object.__setattr__(self, '_cum', cum)

    @classmethod
    def from_table(cls, table: Any) -> 'RotationProfile':
        """Build from a sequence of [t (s), omega (rad/s)] pairs; errors name the problem."""
        if isinstance(table, (int, float)) and not isinstance(table, bool):
            return cls.constant(float(table))
        if not isinstance(table, Sequence) or isinstance(table, str) or len(table) == 0:
            raise ParameterError(
                'rotation must be a number (rad/s) or a list of [t, omega] pairs, '
                f'got {table!r}')
        times = []
        omegas = []
        for i, row in enumerate(table):
            if (not isinstance(row, Sequence) or isinstance(row, str) or len(row) != 2
                    or any(isinstance(v, bool) or not isinstance(v, (int, float))
                           for v in row)):
                raise ParameterError(
                    f'rotation[{i}] must be a pair [t s, omega rad/s] of numbers, got {row!r}')
            times.append(float(row[0]))
            omegas.append(float(row[1]))
        return cls(np.array(times), np.array(omegas))

    @classmethod
    def constant(cls, omega: float) -> 'RotationProfile':
        """Return a profile turning at a constant omega (rad/s)."""
        return cls(np.array([0.0]), np.array([float(omega)]))

    def omega(self, t: float) -> float:
        """Return the angular velocity at time t (rad/s)."""
        if t >= self.times[-1]:  # past the last breakpoint (a constant profile: always)
            return float(self.omegas[-1])
        return float(np.interp(t, self.times, self.omegas))

    def _angle_from_start(self, t: float) -> float:
        times, omegas, cum = self.times, self.omegas, self._cum  # type: ignore[attr-defined]
        if t <= times[0]:
            return omegas[0] * (t - times[0])
        if t >= times[-1]:
            return float(cum[-1] + omegas[-1] * (t - times[-1]))
        i = int(np.searchsorted(times, t, side='right')) - 1
        dt = t - times[i]
        slope = (omegas[i + 1] - omegas[i]) / (times[i + 1] - times[i])
        return float(cum[i] + omegas[i] * dt + 0.5 * slope * dt * dt)

    def angle(self, t: float) -> float:
        """Return the cone angle phi(t) = integral_0^t omega (rad), phi(0) = 0."""
        return self.integral(0.0, t)

    def integral(self, t0: float, t1: float) -> float:
        """Return the angle turned from t0 to t1, the exact integral of omega (rad)."""
        return self._angle_from_start(t1) - self._angle_from_start(t0)

    def segments(self, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Split [t0, t1] at the breakpoints into segments of constant angular acceleration.

        Returns seg_t (K+1,) (s), seg_omega (K,) omega at each segment start (rad/s) and
        seg_domega (K,) angular acceleration in each segment (rad/s^2).
        """
        if not t1 > t0:
            raise ParameterError(f'interval end {t1!r} must be after its start {t0!r}')
        if t0 >= self.times[-1]:  # no breakpoint inside: one segment (most intervals)
            omega0, omega1 = self.omega(t0), self.omega(t1)
            return (np.array([t0, t1], dtype=float), np.array([omega0]),
                    np.array([(omega1 - omega0) / (t1 - t0)]))
        inner = self.times[(self.times > t0) & (self.times < t1)]
        seg_t = np.concatenate([[t0], inner, [t1]])
        seg_omega = np.array([self.omega(t) for t in seg_t[:-1]])
        omega_end = np.array([self.omega(t) for t in seg_t[1:]])
        seg_domega = (omega_end - seg_omega) / np.diff(seg_t)
        return seg_t, seg_omega, seg_domega


def rotate_z(vectors: np.ndarray, angle: float) -> np.ndarray:
    """Rotate vectors (..., 3) about +z by angle (rad); returns a new array."""
    c = math.cos(angle)
    s = math.sin(angle)
    out = np.array(vectors, dtype=np.float64, copy=True)
    out[..., 0] = c * vectors[..., 0] - s * vectors[..., 1]
    out[..., 1] = s * vectors[..., 0] + c * vectors[..., 1]
    return out
