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
The report of a fit (PNG, matplotlib's Agg canvas, no display).

Top left: the tracks (dots) and the fitted simulation (lines) seen from above, one colour per
piece, with the cone's rim. Top right: each piece's residual distance (mm) over time. With
``residual: exits``: the observed and fitted exit angles (left) and times (right) per piece.
Bottom: each free key's profile (Δχ² against the key's value, the 95 % threshold and the
interval) and the waterfall of the starts (each start's final cost over the lowest, in Δχ²,
sorted: a plateau at zero is the global minimum found from many starts).
"""

from pathlib import Path
import textwrap

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure, FigureBase
import numpy as np

from .exits import simulate_exits
from .problem import FitProblem, predict
from .profiles import DELTA_CHI2
from .solve import FitResult
from ..errors import ReportError

__all__ = ['draw_fit']


def draw_fit(problem: FitProblem, result: FitResult, path: str | Path) -> None:
    """Draw the tracks (or exits) against the fitted simulation into ``path``."""
    figure = Figure(figsize=(11, 9), dpi=100, layout='constrained')
    FigureCanvasAgg(figure)
    top, bottom = figure.subfigures(2, 1, height_ratios=(1.2, 1.0))
    if problem.spec.exits is not None:
        _draw_exits(problem, result, top)
    else:
        _draw_tracks(problem, result, top)
    _draw_profiles(result, bottom)
    estimates = ', '.join(f'{k} = {e:.4g} +- {s:.2g}' for k, e, s in zip(
        result.keys, result.estimate, result.stderr))
    test = result.fit_test
    if test is not None:
        estimates += (f'; test of fit {"passed" if test.passed else "FAILED"} (chi2/dof '
                      f'{test.reduced:.3g})')
    figure.suptitle('\n'.join(textwrap.wrap(estimates, 150)), fontsize=8)
    try:
        figure.savefig(path)
    except OSError as exc:
        raise ReportError(f'cannot write the fit report {path}: {exc}') from exc


def _draw_profiles(result: FitResult, figure: FigureBase) -> None:
    """Draw each key's profile and the starts' waterfall side by side."""
    panels = figure.subplots(1, len(result.keys) + 1, squeeze=False)[0]
    for axes, key, low, high in zip(panels, result.keys, result.low, result.high):
        profile = result.profiles.get(key)
        if profile is None:
            continue
        axes.plot(profile['values'], profile['delta_chi2'], 'o-', markersize=3)
        axes.axhline(DELTA_CHI2, color='red', linewidth=0.8, linestyle='--',
                     label='95 % threshold')
        axes.axvspan(low, high, color='green', alpha=0.15, label='95 % interval')
        axes.set_xlabel(key)
        axes.set_ylabel('Δχ² (profile)')
        axes.legend(fontsize=6)
    waterfall = panels[-1]
    costs = np.array(result.start_costs)
    if costs.size and result.fit_test is not None:
        sigma = result.fit_test.noise.sigma
        waterfall.plot(np.arange(1, costs.size + 1), 2.0 * (costs - costs[0]) / sigma ** 2 + 1,
                       'o-', markersize=4)
        waterfall.set_yscale('log')
    waterfall.set_xlabel('start (sorted by final cost)')
    waterfall.set_ylabel('Δχ² to the best + 1')
    waterfall.set_title(f'waterfall: {result.reached_best} of {costs.size} at the lowest',
                        fontsize=8)


def _draw_exits(problem: FitProblem, result: FitResult, figure: FigureBase) -> None:
    """Left: observed and fitted exit angles per piece; right: exit times."""
    exits = problem.spec.exits
    assert exits is not None
    angle, t = simulate_exits(problem.scenario(result.estimate))
    where, when = figure.subplots(1, 2)
    where.plot(exits.particle, exits.angle_deg, 'x', markersize=9, label='observed (none: '
               'stayed)')
    where.plot(exits.particle, angle[exits.particle], 'o', fillstyle='none', markersize=9,
               label='fitted simulation')
    where.set_xlabel('piece')
    where.set_ylabel('exit angle (deg)')
    where.set_ylim(0.0, 360.0)
    where.legend(fontsize=7)
    known = np.isfinite(exits.t)
    when.plot(exits.particle[known], exits.t[known], 'x', markersize=9, label='observed')
    when.plot(exits.particle, t[exits.particle], 'o', fillstyle='none', markersize=9,
              label='fitted simulation (end: stayed)')
    when.set_xlabel('piece')
    when.set_ylabel('exit time (s)')
    when.legend(fontsize=7)


def _draw_tracks(problem: FitProblem, result: FitResult, figure: FigureBase) -> None:
    """Left: tracks and the fitted simulation from above; right: residuals over time."""
    tracks = problem.spec.tracks
    scenario = problem.scenario(result.estimate)
    fitted = predict(scenario, tracks)
    top, residual = figure.subplots(1, 2)
    rim = np.linspace(0.0, 2.0 * np.pi, 200)
    top.plot(scenario.model.r * np.cos(rim), scenario.model.r * np.sin(rim), color='grey',
             linewidth=0.8)
    for piece in np.unique(tracks.particle):
        rows = tracks.particle == piece
        line, = top.plot(fitted[rows, 0], fitted[rows, 1], linewidth=1.2,
                         label=f'piece {piece}')
        top.plot(tracks.xyz[rows, 0], tracks.xyz[rows, 1], '.', markersize=2.5,
                 color=line.get_color())
        distance = np.hypot(*(fitted[rows, :2] - tracks.xyz[rows, :2]).T)
        residual.plot(tracks.t[rows], 1e3 * distance, color=line.get_color(), linewidth=1.0)
    top.set_aspect('equal')
    top.set_xlabel('x (m)')
    top.set_ylabel('y (m)')
    top.set_title('tracks (dots) and the fitted simulation (lines)')
    top.legend(fontsize=7, loc='upper right')
    residual.set_xlabel('t (s)')
    residual.set_ylabel('distance fitted - tracked (mm)')
