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
The residuals of a fit: the scenario simulated with given values, compared with the tracks.

:func:`predict` runs the headless simulator through the tracked times and returns where each
tracked piece is at each of them (a piece that left the cone stays where it left, a piece
whose integration failed where it was last). :class:`FitProblem` maps a parameter vector to
the residual vector: predicted minus tracked x and y (m, and z where tracked), one row per
observation; or, with ``residual: exits``, the exit angles' and times' differences in units
of their sigmas (:mod:`exits`).
"""

from dataclasses import dataclass
import threading

import numpy as np

from .exits import simulate_exits
from .spec import FitSpec
from .tracks import Tracks
from ..feeder.runner import start_simulator
from ..feeder.scenario import Scenario
from ..physics.simulation import Simulator

__all__ = ['exit_residuals', 'FitProblem', 'predict', 'Residuals', 'residuals_of',
           'started', 'SumOfSquares', 'trace']


def predict(scenario: Scenario, tracks: Tracks) -> np.ndarray:
    """Return the simulated positions (M, 3) (m, world frame) at the tracks' rows."""
    return trace(*started(scenario), tracks.particle, tracks.t)[0]


def started(scenario: Scenario) -> tuple[Simulator, np.ndarray]:
    """Return a simulator at t = 0 with the scenario's pieces and their positions (P, 3) m."""
    start = np.array([spec.position for spec in scenario.particles], dtype=float)
    return start_simulator(scenario), start


def trace(sim: Simulator, start: np.ndarray, particle: np.ndarray, t: np.ndarray,
          last: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """
    Advance ``sim`` through the times ``t`` (M,) (s, sorted); return the positions (M, 3).

    Row i is where the piece whose id is ``particle[i]`` is at ``t[i]`` (m, world frame): a
    piece that left the cone stays where it left, a piece whose integration failed where it
    was last. start (ids, 3) (m): where each id is before the first step. With ``last`` (s),
    the simulation then goes on to that time. Also returns where each id is at the end
    (ids, 3) (m).
    """
    where = np.array(start, dtype=float)
    out = np.empty((len(t), 3))
    times, first = np.unique(t, return_index=True)
    bounds = list(first) + [len(t)]
    ends = [*times, last] if last is not None else list(times)
    for k, moment in enumerate(ends):
        if moment > sim.t:
            step = sim.advance_to(float(moment))
            if len(step.exits):
                where[step.exits.ids] = step.exits.position
            for failure in step.failures:
                if np.all(np.isfinite(failure.position)):
                    where[failure.particle_id] = failure.position
        if k < len(times):
            if sim.state.count:
                where[sim.state.ids] = sim.positions()
            rows = slice(bounds[k], bounds[k + 1])
            out[rows] = where[particle[rows]]
    if sim.state.count:
        where[sim.state.ids] = sim.positions()
    return out, where


def residuals_of(spec: FitSpec, values: np.ndarray) -> np.ndarray:
    """
    Return the residual vector of the fit ``spec`` at the free values ``values``.

    Trajectory: predicted minus tracked positions (m), (M * 2,) or (M * 3,) with z.
    Exits: angle and time differences over their sigmas (:meth:`Exits.residuals`).
    """
    scenario = spec.scenario(values)
    if spec.exits is not None:
        return exit_residuals(spec, scenario)[0]
    tracks = spec.tracks
    diff = predict(scenario, tracks) - tracks.xyz
    return diff[:, :tracks.columns].reshape(-1)


def exit_residuals(spec: FitSpec, scenario: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Return the exits' residuals (1) in ``scenario`` and the piece of each."""
    assert spec.exits is not None
    angle, t = simulate_exits(scenario)
    return spec.exits.residuals(angle, t, scenario.duration, spec.exit_sigma)


@dataclass(frozen=True, eq=False)
class Residuals:
    """
    The residuals as a function of θ, picklable: what a thread, a process or a Dask worker runs.

    logs (n,): which free keys are searched in log scale (value = exp θ); the others θ = value.
    """

    spec: FitSpec
    logs: tuple[bool, ...]

    def values(self, theta: np.ndarray) -> np.ndarray:
        """Return the free values at θ."""
        return np.where(self.logs, np.exp(theta), theta)

    def __call__(self, theta: np.ndarray) -> np.ndarray:
        """Return the residual vector at θ."""
        return residuals_of(self.spec, self.values(theta))


@dataclass(frozen=True, eq=False)
class SumOfSquares:
    """The sum of squared residuals at θ, picklable (a global search's cost)."""

    residuals: Residuals

    def __call__(self, theta: np.ndarray) -> float:
        """Return |r(θ)|²."""
        r = self.residuals(theta)
        return float(r @ r)


class FitProblem:
    """The residuals of a fit as a function of the free values; counts the simulations."""

    def __init__(self, spec: FitSpec) -> None:
        """Keep the fit; no simulation runs yet."""
        self.spec = spec
        self.simulations = 0
        self.window_simulations = 0  # multiple shooting's windows (:mod:`shooting`)
        self._lock = threading.Lock()
        self._columns = spec.tracks.columns

    def scenario(self, values: np.ndarray) -> Scenario:
        """Return the scenario with the free keys set to ``values``."""
        return self.spec.scenario(values)

    def residuals(self, values: np.ndarray) -> np.ndarray:
        """Return the residual vector at ``values`` (:func:`residuals_of`); count it."""
        self.count(1)
        return residuals_of(self.spec, values)

    def count(self, simulations: int) -> None:
        """Count simulations run here or elsewhere (threads, processes, Dask workers)."""
        with self._lock:
            self.simulations += simulations

    def owners(self, values: np.ndarray) -> np.ndarray:
        """Return the piece of each residual (m,) at ``values`` (exits: one simulation)."""
        if self.spec.exits is not None:
            self.count(1)
            return exit_residuals(self.spec, self.scenario(values))[1]
        return np.repeat(self.spec.tracks.particle, self._columns)
