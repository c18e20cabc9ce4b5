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
Multiple shooting: the tracked time cut into windows, each simulated from a start of its own.

Single shooting simulates the whole run from the scenario's start: a wrong parameter bends
the whole trajectory, errors pile up over time, and the sum of squares has valleys far from
the truth. Multiple shooting (Bock's) cuts the time into windows of ``segments`` seconds.
Window 0 starts from the scenario; window k >= 1 starts, for each piece whose track spans its
start t_k, from a state that is an unknown of the fit. The residuals are the tracks' (each
window predicts its own rows) and the continuity gaps, the end of window k - 1 minus the start
of window k, which the fit drives to zero. Each window sees only its own time, so a wrong
parameter is corrected before its errors pile up.

The unknown start of a piece is its world position, velocity and friction-filter force in
the cone's plane: (x, y) (m), (x', y') (m/s), (P_x, P_y) (N). The filter force must be an
unknown: a piece that sticks (|v_dif| far below qdot_F) keeps the P it had, eq. (14), and a
restart from P = 0 moved such pieces by 0.7 mm in 0.5 s. The first guesses come from the track
(a polynomial through the observations within :data:`SLOPE_SPAN` of t_k: position, velocity,
and the tangential part of m (a + g z) as P). The piece starts at its resting height, moving
along the surface, P tangential; a piece that slides fast rides a little higher than it rests
(measured: restarts from the true x, y, velocity and P drift by up to 0.6 mm in 0.3 s for
pieces sliding at 1 m/s, 3 µm for pieces that stick). A gap is weighed as the position error it
makes over a window of length T: (Δx, Δy, T Δx', T Δy', T² ΔP_x / 2m, T² ΔP_y / 2m) (m).

The rows of a piece whose track starts inside a window, after the window's start, are left
out, and so are untracked pieces after window 0: multiple shooting finds the valley, and a
single-shooting fit from its estimate (:mod:`solve`) gives the final estimate and its
statistics on every row. The Jacobian is assembled from forward differences of the windows:
a window's unknowns touch only its own rows and the gaps at its two ends, so a difference in
one unknown of every window (of every piece at once without contact between pieces) costs
one simulation of the whole time, split into windows that run side by side.
"""

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .jacobian import Mapper
from .problem import started, trace
from .spec import FitSpec
from .tracks import Tracks
from ..feeder.scenario import Scenario
from ..physics.params import product_row
from ..physics.simulation import (
    cone_from_world, resting_height, SimParams, SimState, Simulator)

__all__ = ['initial_starts', 'split', 'Shooting', 'Windows']

#: Unknowns of a piece's start: x, y (m), x', y' (m/s), P_x, P_y (N), world frame.
UNKNOWNS = 6
#: Forward-difference steps of the unknowns (m, m, m/s, m/s, N, N).
STEPS = np.array([1.0e-5, 1.0e-5, 1.0e-4, 1.0e-4, 1.0e-4, 1.0e-4])
#: A window's simulation: its index k, the scenario and the starts (pieces, 6) of its pieces.
Task = tuple[int, Scenario, np.ndarray]
#: Half-width (s) of the observations a start velocity is fitted to.
SLOPE_SPAN = 0.1


@dataclass(frozen=True, eq=False)
class Windows:
    """
    The windows of a fit.

    edges (W + 1,) s; per window the piece ids it simulates and the track rows it predicts;
    per boundary k = 1 .. W - 1 the ids whose gap is a residual.
    """

    edges: np.ndarray
    pieces: tuple[np.ndarray, ...]
    rows: tuple[np.ndarray, ...]
    gaps: tuple[np.ndarray, ...]

    @property
    def count(self) -> int:
        """Return the number of windows W."""
        return len(self.pieces)


def split(tracks: Tracks, pieces: int, segment: float) -> Windows:
    """Cut the tracked time [0, last observation] into windows of ``segment`` s."""
    end = float(tracks.t.max())
    edges = np.arange(0.0, end, segment)
    if end - edges[-1] < 0.25 * segment and len(edges) > 1:
        edges = edges[:-1]  # a short last window joins the one before
    edges = np.append(edges, end)
    first = np.full(pieces, np.inf)
    last = np.full(pieces, -np.inf)
    np.minimum.at(first, tracks.particle, tracks.t)
    np.maximum.at(last, tracks.particle, tracks.t)
    members = [np.arange(pieces)]
    for k in range(1, len(edges) - 1):
        members.append(np.flatnonzero((first <= edges[k]) & (last >= edges[k])))
    window = np.clip(np.searchsorted(edges, tracks.t, side='right') - 1, 0, len(members) - 1)
    rows = tuple(np.flatnonzero((window == k) & np.isin(tracks.particle, members[k]))
                 for k in range(len(members)))
    gaps = tuple(np.intersect1d(members[k - 1], members[k]) for k in range(1, len(members)))
    return Windows(edges=edges, pieces=tuple(members), rows=rows, gaps=gaps)


def initial_starts(tracks: Tracks, windows: Windows, scenario: Scenario) -> list[np.ndarray]:
    """
    Return each window's start unknowns (pieces, 6) from the tracks (window 0: none).

    Position, velocity and acceleration come from a polynomial through the observations
    near the start; the filter force is the tangential part of m (a + g z), what holds the
    piece on its path besides the normal force.
    """
    model = scenario.model
    starts = [np.zeros((0, UNKNOWNS))]
    for k in range(1, windows.count):
        t0 = windows.edges[k]
        block = np.zeros((len(windows.pieces[k]), UNKNOWNS))
        for i, p in enumerate(windows.pieces[k]):
            mine = tracks.particle == p
            t, xy = tracks.t[mine], tracks.xyz[mine, :2]
            near = np.flatnonzero(np.abs(t - t0) <= SLOPE_SPAN)
            if len(near) < 2:
                near = np.argsort(np.abs(t - t0))[:2]
            coefficients = np.polyfit(t[near] - t0, xy[near], 2 if len(near) > 3 else 1)
            (x, y), (vx, vy) = coefficients[-1], coefficients[-2]
            ax, ay = 2.0 * coefficients[0] if len(coefficients) == 3 else (0.0, 0.0)
            rho = max(float(np.hypot(x, y)), 1e-9)
            slope = model.h / model.r
            rho_dot = (x * vx + y * vy) / rho
            az = -slope * ((vx * vx + vy * vy + x * ax + y * ay) / rho - rho_dot ** 2 / rho)
            normal = np.array([slope * x / rho, slope * y / rho, 1.0])
            force = scenario.particles[int(p)].product.m * np.array([ax, ay, az + model.g])
            tangential = force - normal * (force @ normal) / (normal @ normal)
            block[i] = [x, y, vx, vy, tangential[0], tangential[1]]
        starts.append(block)
    return starts


@dataclass(frozen=True, eq=False)
class WindowRun:
    """
    One window's simulation, picklable: what a thread, a process or a Dask worker runs.

    spec: the fit; windows: its windows; columns: 2 (x, y) or 3 (with z) per track row.
    """

    spec: FitSpec
    windows: Windows
    columns: int

    def __call__(self, task: Task) -> tuple[np.ndarray, np.ndarray]:
        """
        Simulate one window; return its rows' residuals (m) and the ends of its pieces.

        task: (k, scenario, start (pieces, 6)). The ends (pieces, 6) are x, y (m), x', y'
        (m/s) and P_x, P_y (N) at the window's end; a piece that left the cone keeps its exit
        point and the start's velocity and force.
        """
        k, scenario, start = task
        windows, tracks = self.windows, self.spec.tracks
        t0, t1 = windows.edges[k], windows.edges[k + 1]
        ids = windows.pieces[k]
        if k == 0:
            sim, where = started(scenario)
        else:
            params = SimParams(model=scenario.model, solver=scenario.solver)
            sim = Simulator(params, scenario.rotation, t0)
            where = np.zeros((len(scenario.particles), 3))
            if len(ids):
                sim.state = self._state(scenario, params, sim.state, ids, start)
                where[ids] = sim.positions()
        rows = windows.rows[k]
        predicted, where = trace(sim, where, tracks.particle[rows], tracks.t[rows], last=t1)
        residual = (predicted - tracks.xyz[rows])[:, :self.columns].reshape(-1)
        ends = np.zeros((len(ids), UNKNOWNS))
        if k > 0:
            ends[:, 2:] = start[:, 2:]
        position, velocity, force = sim.world()
        on = {int(i): j for j, i in enumerate(sim.state.ids)}
        for j, p in enumerate(ids):
            if int(p) in on:
                i = on[int(p)]
                ends[j] = [*position[i, :2], *velocity[i, :2], *force[i, :2]]
            else:
                ends[j, :2] = where[p, :2]
        return residual, ends

    @staticmethod
    def _state(scenario: Scenario, params: SimParams, empty: SimState, ids: np.ndarray,
               start: np.ndarray) -> SimState:
        """Return the state of the pieces ``ids`` on the cone at ``start`` (pieces, 6)."""
        model = scenario.model
        slope = model.h / model.r
        q = np.zeros((len(ids), 3))
        qdot = np.zeros((len(ids), 3))
        force = np.zeros((len(ids), 3))
        rows = []
        for j, p in enumerate(ids):
            product = scenario.particles[int(p)].product
            x, y, vx, vy, fx, fy = start[j]
            rho = max(float(np.hypot(x, y)), 1e-9)
            q[j] = (x, y, resting_height(model, product, x, y))
            qdot[j] = (vx, vy, -slope * (x * vx + y * vy) / rho)
            force[j] = (fx, fy, -slope * (x * fx + y * fy) / rho)
            rows.append(product_row(product))
        omega = scenario.rotation.omega(empty.t)
        y = cone_from_world(q, qdot, force, empty.angle, omega)
        return replace(empty, y=y, products=np.array(rows), ids=ids.astype(np.int64),
                       step_size=np.full(len(ids), params.solver.h_init),
                       next_id=len(scenario.particles))


class Shooting:
    """
    The multiple-shooting residuals and their Jacobian over z = (θ, the windows' starts).

    scenario: values -> Scenario; values: θ -> the free keys' values; start: the scenario at
    the start values (its masses weigh the gaps; whether its pieces touch groups the
    Jacobian's differences).
    """

    def __init__(self, spec: FitSpec, windows: Windows, scenario: Any, values: Any,
                 start: Scenario, mapper: Mapper = map) -> None:
        """Keep the fit and its windows; no simulation runs yet."""
        self.spec = spec
        self.windows = windows
        self._scenario = scenario
        self._values = values
        self.mapper = mapper
        self.simulations = 0  # window simulations
        self.columns = spec.tracks.columns
        self.run_window = WindowRun(spec, windows, self.columns)
        self.params = len(spec.keys)
        self.sizes = [len(p) * UNKNOWNS for p in windows.pieces]
        self.sizes[0] = 0
        self.offsets = np.concatenate([[0], np.cumsum(self.sizes)]) + self.params
        segment = float(np.diff(windows.edges).mean())
        self.interact = start.model.interactions.enabled
        masses = np.array([piece.product.m for piece in start.particles])
        self.gap_scales = [np.array([[1.0, 1.0, segment, segment, w, w]
                                     for w in segment ** 2 / (2.0 * masses[gap])])
                           for gap in windows.gaps]
        self._cache: tuple[bytes, Scenario, list[tuple[np.ndarray, np.ndarray]]] | None = None
        data = [len(rows) * self.columns for rows in windows.rows]
        self._data_offsets = np.concatenate([[0], np.cumsum(data)])
        gaps = [len(g) * UNKNOWNS for g in windows.gaps]
        self._gap_offsets = np.concatenate([[0], np.cumsum(gaps)]) + self._data_offsets[-1]
        self.size = int(self._gap_offsets[-1])

    def starts(self, z: np.ndarray) -> list[np.ndarray]:
        """Return each window's start unknowns (pieces, 6) in z."""
        return [z[self.offsets[k]:self.offsets[k + 1]].reshape(-1, UNKNOWNS)
                for k in range(self.windows.count)]

    def _evaluate(self, z: np.ndarray) -> tuple[Scenario, list[tuple[np.ndarray, np.ndarray]]]:
        """Return the scenario at z's θ and every window's run (the last z's are kept)."""
        key = z.tobytes()
        if self._cache is None or self._cache[0] != key:
            scenario = self._scenario(self._values(z[:self.params]))
            starts = self.starts(z)
            tasks = [(k, scenario, starts[k]) for k in range(self.windows.count)]
            self._cache = (key, scenario, list(self.mapper(self.run_window, tasks)))
            self.simulations += len(tasks)
        return self._cache[1], self._cache[2]

    def _gaps(self, outputs: list[tuple[np.ndarray, np.ndarray]],
              starts: list[np.ndarray]) -> np.ndarray:
        parts = []
        for k in range(1, self.windows.count):
            gap = self.windows.gaps[k - 1]
            before = outputs[k - 1][1][np.searchsorted(self.windows.pieces[k - 1], gap)]
            after = starts[k][np.searchsorted(self.windows.pieces[k], gap)]
            parts.append(((before - after) * self.gap_scales[k - 1]).reshape(-1))
        return np.concatenate(parts) if parts else np.zeros(0)

    def residuals(self, z: np.ndarray) -> np.ndarray:
        """Return the track residuals of every window (m), then the weighed gaps (m)."""
        outputs = self._evaluate(z)[1]
        return np.concatenate([*(out[0] for out in outputs),
                               self._gaps(outputs, self.starts(z))])

    def jacobian(self, z: np.ndarray, theta_steps: np.ndarray) -> np.ndarray:
        """Return the Jacobian (size, len(z)) by forward differences, windows side by side."""
        scenario0, base = self._evaluate(z)
        f0 = self.residuals(z)
        jac = np.zeros((self.size, len(z)))
        count = self.windows.count
        starts = self.starts(z)
        variants: list[tuple[Scenario, list[np.ndarray]]] = []
        for j, h in enumerate(theta_steps):
            theta = np.array(z[:self.params])
            theta[j] += h
            variants.append((self._scenario(self._values(theta)), starts))
        slots = max((len(p) for p in self.windows.pieces[1:]), default=0)
        groups = [(c, s) for c in range(UNKNOWNS)
                  for s in (range(slots) if self.interact else [-1])]
        for c, s in groups:
            moved = [block.copy() for block in starts]
            for k in range(1, count):
                if s < 0:
                    moved[k][:, c] += STEPS[c]
                elif s < len(moved[k]):
                    moved[k][s, c] += STEPS[c]
            variants.append((scenario0, moved))
        tasks = []
        for v, (scenario, blocks) in enumerate(variants):
            first = 0 if v < len(theta_steps) else 1
            tasks += [(k, scenario, blocks[k]) for k in range(first, count)]
        outputs = list(self.mapper(self.run_window, tasks))
        self.simulations += len(tasks)
        at = 0
        for j, h in enumerate(theta_steps):
            moved_outputs = outputs[at:at + count]
            at += count
            jac[:, j] = (np.concatenate([*(out[0] for out in moved_outputs),
                                         self._gaps(moved_outputs, starts)]) - f0) / h
        for c, s in groups:
            moved_outputs = [base[0], *outputs[at:at + count - 1]]
            at += count - 1
            self._unknown_columns(jac, base, moved_outputs, c, s)
        return jac

    def _unknown_columns(self, jac: np.ndarray, base: list, moved: list, c: int,
                         s: int) -> None:
        """Write the columns of unknown ``c`` of slot ``s`` (all pieces: -1) of each window."""
        windows, tracks = self.windows, self.spec.tracks
        step = STEPS[c]
        for k in range(1, windows.count):
            ids = windows.pieces[k]
            slots = range(len(ids)) if s < 0 else ([s] if s < len(ids) else [])
            rows = windows.rows[k]
            data = (moved[k][0] - base[k][0]) / step
            ends = (moved[k][1] - base[k][1]) / step
            owner = np.repeat(tracks.particle[rows], self.columns)
            for j in slots:
                column = self.offsets[k] + j * UNKNOWNS + c
                span = slice(self._data_offsets[k], self._data_offsets[k + 1])
                jac[span, column] = data if s >= 0 else np.where(owner == ids[j], data, 0.0)
                if k < windows.count - 1:  # the gap at this window's end
                    gap = windows.gaps[k]
                    base_gap = self._gap_offsets[k]
                    for i, p in enumerate(gap):
                        if s < 0 and p != ids[j]:
                            continue
                        local = int(np.searchsorted(ids, p))
                        rows_gap = slice(base_gap + i * UNKNOWNS, base_gap + (i + 1) * UNKNOWNS)
                        jac[rows_gap, column] = ends[local] * self.gap_scales[k][i]
                # the gap at this window's start: - the start itself
                gap = windows.gaps[k - 1]
                if ids[j] in gap:
                    i = int(np.searchsorted(gap, ids[j]))
                    jac[self._gap_offsets[k - 1] + i * UNKNOWNS + c,
                        column] = -self.gap_scales[k - 1][i, c]
