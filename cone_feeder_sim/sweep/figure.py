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
The summary figure of a sweep (PNG, matplotlib's Agg canvas, no display).

Three panels from the summary rows: the mass that reached each channel in each job (a
heat map, jobs down, channels across), the mean exit time and the exits against the first
numeric varied key (against the job where none is), and the CPU time of every job (failed
jobs in red, with their count in the title).
"""

from collections.abc import Sequence
import math
from pathlib import Path
from typing import Any

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
import numpy as np

from ..errors import SweepError


def _number(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return math.nan
    return float(value)


def _axis_key(keys: Sequence[str], rows: Sequence[dict[str, Any]]) -> str | None:
    """Return the first varied key with a number in every row, or None."""
    for key in keys:
        if rows and all(math.isfinite(_number(row.get(key))) for row in rows):
            return key
    return None


def build_figure(title: str, keys: Sequence[str], rows: Sequence[dict[str, Any]],
                 dpi: float = 100.0) -> Figure:
    """Return the summary figure of a sweep's rows (one per finished job, in job order)."""
    figure = Figure(figsize=(15.0, 5.2), dpi=dpi)
    FigureCanvasAgg(figure)
    ax_mass, ax_exit, ax_cpu = figure.subplots(1, 3, gridspec_kw={'width_ratios': [1.2, 1, 1]})
    done = [row for row in rows if row['status'] == 'done']
    failed = len(rows) - len(done)
    channels = sorted({k for row in done for k in row if k.startswith('mass_ch')})
    if done and channels:
        mass = np.array([[_number(row.get(c)) for c in channels] for row in done])
        image = ax_mass.imshow(1e3 * mass, aspect='auto', cmap='viridis', origin='upper',
                               interpolation='nearest',
                               extent=(0.5, len(channels) + 0.5, len(done) - 0.5, -0.5))
        figure.colorbar(image, ax=ax_mass, label='mass (g)')
        ticks = np.linspace(0, len(done) - 1, min(len(done), 12)).round().astype(int)
        ax_mass.set_yticks(ticks, [done[i]['job'] for i in ticks], fontsize=7)
    ax_mass.set_xlabel('channel')
    ax_mass.set_ylabel('job')
    ax_mass.set_title('mass per channel')
    key = _axis_key(keys, done)
    x = [(_number(row[key]) if key else int(row['job'])) for row in done]
    ax_exit.plot(x, [_number(row.get('mean_exit_time')) for row in done], 'o',
                 color='tab:blue', ms=4)
    ax_exit.set_xlabel(key or 'job')
    ax_exit.set_ylabel('mean exit time (s)', color='tab:blue')
    ax_exit.set_title('exits')
    twin = ax_exit.twinx()
    twin.plot(x, [_number(row.get('exits')) for row in done], 'x', color='tab:orange', ms=5)
    twin.set_ylabel('exits', color='tab:orange')
    index = np.arange(len(rows))
    ax_cpu.bar(index, [_number(row.get('cpu_s')) for row in rows],
               color=['tab:green' if row['status'] == 'done' else 'tab:red' for row in rows])
    ax_cpu.set_xlabel('job (index among the finished)')
    ax_cpu.set_ylabel('CPU time (s)')
    ax_cpu.set_title(f'CPU per job ({failed} failed, red)' if failed else 'CPU per job')
    figure.suptitle(f'{title}: {len(done)} done, {failed} failed')
    figure.tight_layout()
    return figure


def write_figure(path: str | Path, title: str, keys: Sequence[str],
                 rows: Sequence[dict[str, Any]]) -> Path:
    """Write the summary figure to ``path`` (PNG); return the path."""
    path = Path(path)
    try:
        build_figure(title, keys, rows).savefig(path, format='png')
    except OSError as exc:
        raise SweepError(f'cannot write the summary figure {path}: {exc}') from exc
    return path
