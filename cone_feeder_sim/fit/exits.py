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
Observed exits, the data of ``residual: exits``: where and when each piece left the cone.

An exits file is a CSV with the columns ``particle`` (the 0-based index of the piece in the
scenario), ``angle_deg`` (atan2(y, x) in degrees, where it crossed the rim; an empty cell: the
piece stayed on the cone to the end) and, optionally, ``t`` (s, when; an empty cell: not
known). The events file of ``cone-feeder-sim run --events`` has these columns, so a simulated
run is a test subject here too.

:func:`simulate_exits` runs the scenario to its end and returns each piece's exit. A piece that
has not left by the end counts as leaving at the end, at the angle where it is: a continuous
penalty that a search can follow.
"""

from dataclasses import dataclass, replace
import math
from pathlib import Path

import numpy as np

from .tracks import read_table
from ..errors import ScenarioError
from ..feeder.runner import run_scenario
from ..feeder.scenario import Scenario
from ..physics.simulation import Simulator, StepResult

__all__ = ['Exits', 'read_exits_csv', 'simulate_exits', 'wrap_degrees']

#: The columns an exits file must have (``t`` is optional).
COLUMNS = ('particle', 'angle_deg')
#: The runner's output interval (s) here. Exits are located inside steps, so it changes the
#: results only within the solver's tolerance (0.002 deg against the runner's default
#: 0.01 s, measured), and a run stops as soon as no piece is left.
STRIDE = 0.1


@dataclass(frozen=True, eq=False)
class Exits:
    """
    Observed exits: particle (M,) int64, angle_deg (M,) deg, t (M,) s.

    angle_deg NaN: the piece stayed on the cone to the end; t NaN: the time is not known.
    """

    particle: np.ndarray
    angle_deg: np.ndarray
    t: np.ndarray

    def __len__(self) -> int:
        """Return the number of observed exits."""
        return int(self.particle.shape[0])

    def residuals(self, angle: np.ndarray, t: np.ndarray, duration: float,
                  sigma: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
        """
        Return the residuals against simulated exits, and the piece of each residual.

        angle (P,) deg and t (P,) s: :func:`simulate_exits`; sigma: (deg, s). The residuals
        (1) are, in this order: the angle differences of the pieces that left, wrapped into
        [-180, 180), over sigma[0]; the time differences where the time is known, over
        sigma[1]; for the pieces that stayed, how long before the end the simulated piece
        left (0 if it stayed too), over sigma[1].
        """
        left = np.isfinite(self.angle_deg)
        timed = np.isfinite(self.t)
        stayed = ~left
        owner = np.concatenate([self.particle[left], self.particle[timed],
                                self.particle[stayed]])
        return np.concatenate([
            wrap_degrees(angle[self.particle[left]] - self.angle_deg[left]) / sigma[0],
            (t[self.particle[timed]] - self.t[timed]) / sigma[1],
            (duration - t[self.particle[stayed]]) / sigma[1]]), owner


def read_exits_csv(path: str | Path) -> Exits:
    """Read an exits file; raise ScenarioError naming the file, the line and the column."""
    path = Path(path)
    _, lines = read_table(path, COLUMNS, 't', 'exits')
    rows = []
    for number, row in lines:
        try:
            particle = int(row['particle'])
            cell = (row.get('angle_deg') or '').strip()
            angle = float(cell) if cell else math.nan
            cell = (row.get('t') or '').strip()
            t = float(cell) if cell else math.nan
        except (TypeError, ValueError) as exc:
            raise ScenarioError(f'{path} line {number}: {exc}') from None
        if particle < 0 or math.isinf(angle) or math.isinf(t):
            raise ScenarioError(f'{path} line {number}: particle must be >= 0, angle_deg and '
                                't finite')
        if math.isnan(angle) and not math.isnan(t):
            raise ScenarioError(f'{path} line {number}: a piece that stayed (no angle_deg) '
                                'has no exit time')
        rows.append((particle, angle, t))
    if not rows:
        raise ScenarioError(f'{path}: no exits')
    particles = [p for p, _, _ in rows]
    twice = sorted({p for p in particles if particles.count(p) > 1})
    if twice:
        raise ScenarioError(f'{path}: particle(s) {", ".join(map(str, twice))} leave more '
                            'than once')
    rows.sort()
    return Exits(particle=np.array([p for p, _, _ in rows], dtype=np.int64),
                 angle_deg=np.array([a for _, a, _ in rows]),
                 t=np.array([t for _, _, t in rows]))


def simulate_exits(scenario: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """
    Run the scenario to its end; return each piece's exit angle (P,) (deg) and time (P,) (s).

    The headless runner runs it, without its feed and weigher, at :data:`STRIDE`.
    A piece still on the cone at the end gets the end time and the angle where it is.
    """
    last: list[Simulator] = []

    def keep(t: float, sim: Simulator, step: StepResult) -> None:
        last[:] = [sim]

    run = run_scenario(replace(scenario, output_interval=STRIDE, weigher=None, feed=None),
                       keep)
    count = len(scenario.particles)
    angle = np.zeros(count)
    t = np.full(count, scenario.duration)
    for exits in run.exits:
        angle[exits.ids] = exits.angle_deg
        t[exits.ids] = exits.t
    for failure in run.failures:
        if all(math.isfinite(v) for v in failure.position):
            angle[failure.particle_id] = math.degrees(
                math.atan2(failure.position[1], failure.position[0]))
            t[failure.particle_id] = failure.t
    if last and last[0].state.count:
        position = last[0].positions()
        angle[last[0].state.ids] = np.degrees(np.arctan2(position[:, 1], position[:, 0]))
    return np.mod(angle, 360.0), t


def wrap_degrees(angle: np.ndarray) -> np.ndarray:
    """Return angles (deg) wrapped into [-180, 180)."""
    return np.mod(np.asarray(angle) + 180.0, 360.0) - 180.0
