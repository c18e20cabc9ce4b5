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
Drawing the one-page PNG report of a run (``cone-feeder-sim report RUN.mcap``).

:func:`build_figure` draws a :class:`~cone_feeder_sim.report.read.RunData` with matplotlib
(Agg canvas, no display): the top view with trajectories and channel sectors, the exits per
channel, omega(t) and the piece count. :func:`write_report` reads the run and saves the PNG.
"""

import math
import os
import pathlib
from typing import Any

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PatchCollection
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Wedge
import numpy as np
from scipy.spatial.distance import pdist

from .read import (
    check_channel_mass, DEFAULT_MAX_TRAJECTORIES, DEFAULT_MAX_TRAJECTORY_POINTS, read_run, RunData)
from ..errors import ReportError

__all__ = ['build_figure', 'write_report']


_FEW_TRAJECTORIES = 10
_MANY_EXITS = 300


def _no_data(ax: Any, text: str) -> None:
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha='center', va='center',
            color='0.4', fontsize=11)


def draw_top_view(ax: Any, run: RunData) -> None:
    """Draw the trajectories on the cone seen from above, with the channel sectors."""
    r = run.cone_radius
    layout = run.layout
    outer = 1.16 * r
    for channel in range(1, layout.count + 1):
        start, end = layout.sector_edges(channel)
        shade = '0.93' if channel % 2 else '0.85'
        ax.add_patch(Wedge((0.0, 0.0), outer, start, end, width=outer - r, facecolor=shade,
                           edgecolor='0.55', linewidth=0.6, zorder=0))
        angle = math.radians(start)
        ax.plot([0.0, r * math.cos(angle)], [0.0, r * math.sin(angle)], color='0.75',
                linewidth=0.6, linestyle=(0, (4, 3)), zorder=1)
        middle = math.radians(0.5 * (start + end))
        ax.text(1.08 * r * math.cos(middle), 1.08 * r * math.sin(middle), str(channel),
                ha='center', va='center', fontsize=9 if layout.count <= 24 else 6,
                fontweight='bold', zorder=5)
    ax.add_patch(Circle((0.0, 0.0), r, fill=False, edgecolor='black', linewidth=1.5,
                        zorder=2))
    ax.plot([0.0], [0.0], marker='+', color='black', markersize=8, zorder=2)
    handles = []
    trajectories = run.trajectories.by_id()
    exits = run.exits
    exit_at = {int(i): (float(x), float(y)) for i, (x, y) in zip(exits.ids, exits.position[:, :2])
               if i >= 0 and int(i) in trajectories}
    if trajectories:
        segments = []
        for key, rows in trajectories.items():
            xy = rows[:, 1:3]
            if key in exit_at:
                xy = np.vstack((xy, exit_at[key]))
            segments.append(xy)
        starts = np.array([rows[0, 1:3] for rows in trajectories.values()])
        if len(trajectories) <= _FEW_TRAJECTORIES:
            colors = [f'C{i}' for i in range(len(segments))]
            for key, xy, color in zip(trajectories, segments, colors):
                (line,) = ax.plot(xy[:, 0], xy[:, 1], color=color, linewidth=1.4, zorder=3,
                                  label=f'piece {key}')
                handles.append(line)
        else:
            first_seen = np.array([rows[0, 0] for rows in trajectories.values()])
            lines = LineCollection(segments, cmap='viridis', linewidths=0.7, alpha=0.75,
                                   zorder=3)
            lines.set_array(first_seen)
            ax.add_collection(lines)
            colorbar = ax.figure.colorbar(lines, ax=ax, fraction=0.035, pad=0.02)
            colorbar.set_label('first seen (s)')
            shown = len(trajectories)
            handles.append(ax.plot([], [], color='tab:green', linewidth=1.0,
                                   label=f'trajectories, coloured by first seen ({shown} '
                                         f'of {run.trajectories.pieces_seen} pieces)')[0])
        handles.append(ax.scatter(starts[:, 0], starts[:, 1], s=14, facecolor='white',
                                  edgecolor='black', linewidth=0.7, zorder=4,
                                  label='first position'))
    if run.last_frame is not None and len(run.last_frame[1]):
        t_last, xy = run.last_frame
        s0 = run.piece_radius()
        ax.add_collection(PatchCollection(
            [Circle((float(x), float(y)), s0) for x, y in xy], facecolor='tab:orange',
            edgecolor='saddlebrown', alpha=0.35, linewidth=0.6, zorder=5))
        touching = int((pdist(xy) < 2.0 * s0).sum()) if len(xy) > 1 else 0
        handles.append(ax.scatter([], [], s=40, facecolor='tab:orange', alpha=0.35,
                                  edgecolor='saddlebrown',
                                  label=f'{len(xy)} pieces at {t_last:.2f} s to scale '
                                        f'(s0 {1e3 * s0:.0f} mm; {touching} pairs < 2 s0)'))
    if len(exits):
        many = len(exits) > _MANY_EXITS
        ax.scatter(exits.position[:, 0], exits.position[:, 1], s=10 if many else 28,
                   marker='o' if many else 'x',
                   color='tab:red', alpha=0.3 if many else 1.0, linewidth=0.0 if many else 1.2,
                   zorder=6)
        handles.append(ax.plot([], [], linestyle='none', marker='o' if many else 'x',
                               markersize=5, color='tab:red', label=f'exit ({len(exits)})')[0])
    limit = 1.22 * r
    ax.set_xlim(-limit, limit)
    ax.set_ylim(-limit, limit)
    ax.set_aspect('equal')
    ax.set_xlabel('x (m)')
    ax.set_ylabel('y (m)')
    ax.grid(True, linewidth=0.3, alpha=0.5)
    source = 'metadata' if run.layout_from_metadata else 'defaults'
    ax.set_title(
        f'Top view: trajectories on the cone (r = {r:.3f} m, {layout.count} channels '
        f'numbered {layout.numbering.replace("_", " ")}; {source})', fontsize=10)
    if not trajectories and not len(exits):
        _no_data(ax, 'no particle_states or exit_events')
    if handles:
        ax.legend(handles=handles, loc='upper center', bbox_to_anchor=(0.5, -0.07),
                  ncol=2 if len(handles) > 2 else len(handles), fontsize=8.5, frameon=False)


def draw_exits(ax: Any, run: RunData) -> None:
    """Draw exits per channel: count (left axis) and mass (right axis), with channel_mass."""
    totals = run.exit_totals()
    channels = np.arange(1, totals.count.shape[0] + 1)
    width = 0.4
    count_bars = ax.bar(channels - width / 2, totals.count, width, color='tab:blue',
                        label='exits (count)')
    ax.set_xlabel('channel')
    ax.set_ylabel('exits (count)', color='tab:blue')
    ax.tick_params(axis='y', labelcolor='tab:blue')
    ax.set_xticks(channels)
    ax.set_xlim(0.4, channels[-1] + 0.6 if channels.shape[0] else 1.6)
    ax.yaxis.get_major_locator().set_params(integer=True)
    ax.set_ylim(0, max(1, int(totals.count.max(initial=0))) * 1.3)
    mass_ax = ax.twinx()
    mass_bars = mass_ax.bar(channels + width / 2, totals.mass, width, color='tab:orange',
                            label='mass from exit_events (kg)')
    mass_ax.set_ylabel('mass (kg)', color='tab:orange')
    mass_ax.tick_params(axis='y', labelcolor='tab:orange')
    handles = [count_bars, mass_bars]
    top = float(totals.mass.max(initial=0.0))
    check = check_channel_mass(run, totals)
    if run.channel_mass is not None:
        recorded = run.channel_mass
        handles.append(mass_ax.scatter(
            np.arange(1, recorded.shape[0] + 1) + width / 2, recorded, marker='D', s=22,
            color='black', zorder=5,
            label=f'last channel_mass (t = {run.channel_mass_time:.2f} s)'))
        top = max(top, float(recorded.max(initial=0.0)))
    mass_ax.set_ylim(0, (top if top > 0 else 1.0) * 1.3)
    total_mass = float(totals.mass.sum())
    title = f'Exits per channel: {int(totals.count.sum())} pieces, {total_mass:.3f} kg'
    if check is not None:
        agree, delta = check
        title += ('; channel_mass agrees' if agree else
                  f'; channel_mass differs by up to {delta:.4g} kg')
    ax.set_title(title, fontsize=10)
    ax.legend(handles=handles, loc='upper left', fontsize=8, framealpha=0.85, ncol=3)


def draw_omega(ax: Any, run: RunData) -> None:
    """Draw the cone's angular velocity over simulation time."""
    if len(run.omega):
        ax.plot(run.omega.t, run.omega.value, color='tab:purple', linewidth=1.2,
                label=r'cone $\omega$')
    else:
        _no_data(ax, 'no cone_state messages')
    ax.axhline(0.0, color='0.5', linewidth=0.6)
    ax.set_ylabel(r'$\omega$ (rad/s)')
    ax.set_title(r'Cone angular velocity $\omega(t)$ (> 0: counter-clockwise from above)',
                 fontsize=10)
    ax.grid(True, linewidth=0.3, alpha=0.5)


def draw_pieces(ax: Any, run: RunData) -> None:
    """Draw the number of pieces on the cone and the cumulative exits over time."""
    handles = []
    if len(run.pieces):
        handles.append(ax.step(run.pieces.t, run.pieces.value, where='post',
                               color='tab:green', linewidth=1.2, label='pieces on the cone')[0])
    if len(run.exits):
        span = run.time_span()
        end = span[1] if span is not None else float(run.exit_log_time[-1])
        start = span[0] if span is not None else float(run.exit_log_time[0])
        t = np.concatenate(([start], run.exit_log_time, [end]))
        n = np.concatenate(([0], np.arange(1, len(run.exits) + 1), [len(run.exits)]))
        handles.append(ax.step(t, n, where='post', color='tab:red', linewidth=1.2,
                               label='exits so far')[0])
    if not handles:
        _no_data(ax, 'no particle_states or exit_events messages')
    else:
        ax.legend(handles=handles, loc='best', fontsize=8, framealpha=0.85)
    ax.set_ylim(bottom=0)
    ax.yaxis.get_major_locator().set_params(integer=True)
    ax.set_xlabel('simulation time (s)')
    ax.set_ylabel('pieces')
    ax.set_title('Pieces on the cone and exits over time', fontsize=10)
    ax.grid(True, linewidth=0.3, alpha=0.5)


def draw_hoppers(ax: Any, run: RunData) -> None:
    """Draw the weigh hoppers' readings over time, one row per head (a heat map)."""
    series = run.hoppers
    heads = series.weight.shape[1]
    t0, t1 = float(series.t[0]), float(series.t[-1])
    image = ax.imshow(series.weight.T, aspect='auto', origin='lower', interpolation='nearest',
                      extent=(t0, t1 if t1 > t0 else t0 + 1.0, 0.5, heads + 0.5),
                      cmap='YlOrBr')
    colorbar = ax.figure.colorbar(image, ax=ax, fraction=0.05, pad=0.02)
    colorbar.set_label('kg')
    ax.set_xlabel('simulation time (s)')
    ax.set_ylabel('head')
    ax.set_title('Weigh hoppers over time (0: empty or not weighed yet)', fontsize=10)


def draw_giveaway(ax: Any, run: RunData) -> None:
    """Draw the histogram of the packs' giveaway (g), with the target and -TNE marked."""
    packs = run.packs
    grams = 1e3 * packs.giveaway
    ax.hist(grams, bins=min(40, max(5, len(grams) // 4)), color='tab:green', alpha=0.8)
    ax.axvline(0.0, color='black', linewidth=1.0)
    tne = run.metadata.get('weigher.tolerable_negative_error')
    try:
        ax.axvline(-1e3 * float(tne), color='tab:red', linestyle='--', linewidth=1.0,
                   label='target - TNE')
        ax.legend(fontsize=8, frameon=False)
    except (TypeError, ValueError):
        pass
    span = float(packs.t[-1] - packs.t[0]) if len(packs.t) > 1 else 0.0
    rate = f', {60.0 * (len(grams) - 1) / span:.1f}/min' if span > 0 else ''
    ax.set_title(f'Giveaway: {len(grams)} packs{rate}, {grams.mean():.1f} ± '
                 f'{grams.std():.1f} g', fontsize=10)
    ax.set_xlabel('pack mass - target (g)')
    ax.set_ylabel('packs')


def _summary_line(run: RunData) -> str:
    span = run.time_span()
    parts = [f'{run.message_count} messages']
    if span is not None:
        parts.insert(0, f'simulation time {span[0]:.2f} to {span[1]:.2f} s')
    parts.append(f'{run.trajectories.pieces_seen} pieces seen')
    parts.append(f'{len(run.exits)} exits')
    for key in ('source', 'version', 'seed', 'feed.seed'):
        if run.metadata.get(key):
            parts.append(f'{key} {run.metadata[key]}')
    contact = run.contact()
    if contact is not None:
        parts.append(f'contact between pieces {contact}')
    return ' | '.join(parts)


def build_figure(run: RunData, *, dpi: float = 100.0) -> Figure:
    """Return the report page of ``run`` (a matplotlib Figure on an Agg canvas)."""
    figure = Figure(figsize=(17.0, 9.6), dpi=dpi)
    FigureCanvasAgg(figure)
    notes = list(run.notes[:6])
    if len(run.notes) > 6:
        notes.append(f'... and {len(run.notes) - 6} more notes')
    bottom = 0.065 + 0.018 * len(notes)
    left = figure.add_gridspec(1, 1, left=0.04, right=0.47, top=0.89, bottom=bottom + 0.07)
    weigher = run.packs is not None and run.hoppers is not None and len(run.hoppers.t) > 1
    right = figure.add_gridspec(4 if weigher else 3, 2 if weigher else 1, left=0.55,
                                right=0.95, top=0.89, bottom=bottom, hspace=0.55,
                                wspace=0.35)
    draw_top_view(figure.add_subplot(left[0, 0]), run)
    draw_exits(figure.add_subplot(right[0, :]), run)
    omega_ax = figure.add_subplot(right[1, :])
    pieces_ax = figure.add_subplot(right[2, :], sharex=omega_ax)
    draw_omega(omega_ax, run)
    draw_pieces(pieces_ax, run)
    if weigher:
        draw_hoppers(figure.add_subplot(right[3, 0]), run)
        draw_giveaway(figure.add_subplot(right[3, 1]), run)
    omega_ax.tick_params(labelbottom=True)
    figure.suptitle(f'Cone feeder run: {run.path.name}', fontsize=15, fontweight='bold',
                    y=0.985)
    figure.text(0.5, 0.935, _summary_line(run), ha='center', fontsize=10, color='0.25')
    for i, note in enumerate(notes):
        figure.text(0.01, 0.012 + 0.018 * (len(notes) - 1 - i), f'Note: {note}',
                    fontsize=8.5, color='darkred' if i == 0 and run.truncated else '0.2')
    return figure


def write_report(
    mcap_path: str | os.PathLike, out_path: str | os.PathLike, *, dpi: float = 100.0,
    namespace: str | None = None, max_trajectories: int = DEFAULT_MAX_TRAJECTORIES,
    max_trajectory_points: int = DEFAULT_MAX_TRAJECTORY_POINTS,
) -> RunData:
    """Read ``mcap_path``, write the report PNG to ``out_path`` and return the data shown."""
    run = read_run(mcap_path, namespace=namespace, max_trajectories=max_trajectories,
                   max_trajectory_points=max_trajectory_points)
    figure = build_figure(run, dpi=dpi)
    out = pathlib.Path(out_path)
    try:
        figure.savefig(out, format='png', dpi=dpi)
    except OSError as err:
        raise ReportError(f'cannot write report {str(out)!r}: {err.strerror or err}') from err
    return run
