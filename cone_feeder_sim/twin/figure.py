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
The headless twin's one-page report (PNG, matplotlib's Agg canvas, no display).

Read from the run's CSVs (:mod:`.run`) apart from drawing them. The forecasts are scored
against the exits the twin saw (``exits.csv``: each piece followed to the rim), the only
outcome a recorded stream holds without channel sensors; a twin that loses a piece before
the rim has no score for it.

- the most likely channel, right or not, against the lead time (the time from the forecast
  to the exit), per lead bin;
- the channel masses' mean absolute error summed over the channels, per horizon, against
  the empty forecast's (every channel nothing: with sparse channels, the one to beat);
- the traces of d and mu_C with their spreads;
- the consistency test over time: per second, the NIS over its degrees of freedom, with its
  two-sided chi-square bounds at alpha = 1e-3.
"""

import csv
from dataclasses import dataclass
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
import numpy as np
from scipy.stats import chi2

__all__ = ['LEAD_BINS', 'read_scores', 'Scores', 'write_report']

#: The lead-time bins (s) of the channel score: (0, 0.25], (0.25, 0.5], (0.5, 1], (1, 2].
LEAD_BINS = (0.0, 0.25, 0.5, 1.0, 2.0)


@dataclass(frozen=True)
class Scores:
    """
    The forecasts' scores against the exits the twin saw.

    right, cases: (B,) per lead bin (:data:`LEAD_BINS`) the forecasts of a piece that then
    left whose most likely channel was its channel, and all of them; horizons: (H,) s;
    mae, empty: (H,) the mean over forecast times of the channel masses' absolute error
    summed over the channels (kg), the twin's and the empty forecast's; forecasts: (H,)
    the forecast times scored (those whose horizon ends within the stream).
    """

    right: np.ndarray
    cases: np.ndarray
    horizons: np.ndarray
    mae: np.ndarray
    empty: np.ndarray
    forecasts: np.ndarray


Tables = dict[str, list[dict[str, str]]]


def _tables(out: Path) -> Tables:
    """Read the run directory's CSVs once: file name -> its rows."""
    tables = {}
    for name in ('exits.csv', 'frames.csv', 'pieces.csv', 'channel_forecast.csv',
                 'parameters.csv'):
        with (out / name).open(newline='', encoding='utf-8') as stream:
            tables[name] = list(csv.DictReader(stream))
    return tables


def read_scores(out: Path) -> Scores:
    """Score the forecasts in the run directory out against its exits (see the module)."""
    return _scores(_tables(out))


def _scores(tables: Tables) -> Scores:
    exits = {int(r['piece']): (float(r['t']), int(r['channel']), float(r['mass']))
             for r in tables['exits.csv']}
    frames = [float(r['t']) for r in tables['frames.csv']]
    end = max(frames, default=0.0)
    right = np.zeros(len(LEAD_BINS) - 1, dtype=int)
    cases = np.zeros_like(right)
    for r in tables['pieces.csv']:
        left = exits.get(int(r['piece']))
        if left is None:
            continue
        lead = left[0] - float(r['t'])
        k = int(np.searchsorted(LEAD_BINS, lead)) - 1  # (edge[k], edge[k + 1]]
        if 0 <= k < len(cases):
            cases[k] += 1
            right[k] += int(r['channel']) == left[1]
    forecast = tables['channel_forecast.csv']
    horizons = np.array(sorted({float(r['horizon']) for r in forecast}))
    times = np.array([t for t, _, _ in exits.values()])
    channels = np.array([c for _, c, _ in exits.values()], dtype=int)
    masses = np.array([m for _, _, m in exits.values()])
    mae, empty = np.zeros(len(horizons)), np.zeros(len(horizons))
    count = np.zeros(len(horizons), dtype=int)
    errors: dict[tuple[float, float], float] = {}
    for r in forecast:
        t, h = float(r['t']), float(r['horizon'])
        if t + h > end:
            continue
        channel = int(r['channel'])
        within = (times > t) & (times <= t + h) & (channels == channel)
        errors[t, h] = errors.get((t, h), 0.0) + abs(float(r['mass']) - masses[within].sum())
    for k, h in enumerate(horizons):
        scored = [t for (t, hh) in errors if hh == h]
        count[k] = len(scored)
        if scored:
            mae[k] = np.mean([errors[t, h] for t in scored])
            empty[k] = np.mean([masses[(times > t) & (times <= t + h)].sum() for t in scored])
    return Scores(right=right, cases=cases, horizons=horizons, mae=mae, empty=empty,
                  forecasts=count)


def _consistency(rows: list[dict[str, str]]) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                      np.ndarray]:
    """Return per whole second of frames.csv's rows: its start, NIS / dof, the ratio's bounds."""
    t = np.array([float(r['t']) for r in rows])
    nis = np.array([float(r['nis']) for r in rows])
    dof = np.array([int(r['observed']) for r in rows])
    if not len(t):
        return (np.zeros(0),) * 4
    seconds = np.floor(t - t[0]).astype(int)
    starts, ratio, low, high = [], [], [], []
    for s in np.unique(seconds):
        d = dof[seconds == s].sum()
        if d:
            starts.append(t[0] + s)
            ratio.append(nis[seconds == s].sum() / d)
            low.append(chi2.ppf(5e-4, d) / d)
            high.append(chi2.ppf(1.0 - 5e-4, d) / d)
    return np.array(starts), np.array(ratio), np.array(low), np.array(high)


def build_figure(out: Path, title: str = 'digital twin', dpi: float = 100.0) -> Figure:
    """Return the one-page report of the run directory out (see the module)."""
    tables = _tables(out)
    scores = _scores(tables)
    figure = Figure(figsize=(15.0, 8.5), dpi=dpi)
    FigureCanvasAgg(figure)
    axes = figure.subplots(2, 3)
    ax = axes[0, 0]
    share = np.where(scores.cases > 0, scores.right / np.maximum(scores.cases, 1), np.nan)
    labels = [f'{a:g}–{b:g}' for a, b in zip(LEAD_BINS[:-1], LEAD_BINS[1:])]
    ax.bar(labels, 100.0 * share, color='tab:blue')
    for k, (r, c) in enumerate(zip(scores.right, scores.cases)):
        ax.annotate(f'{r}/{c}', (k, 0.0), xytext=(0, 3), textcoords='offset points',
                    ha='center')
    ax.set(title='most likely channel right', xlabel='lead time to the exit (s)',
           ylabel='% of forecasts', ylim=(0.0, 100.0))
    ax = axes[0, 1]
    x = np.arange(len(scores.horizons))
    ax.bar(x - 0.2, scores.mae, 0.4, label='twin')
    ax.bar(x + 0.2, scores.empty, 0.4, label='empty forecast', color='tab:gray')
    ax.set_xticks(x, [f'{h:g} s ({n})' for h, n in zip(scores.horizons, scores.forecasts)])
    ax.set(title='channel masses: error summed over channels', xlabel='horizon (forecasts)',
           ylabel='mean absolute error (kg)')
    ax.legend()
    parameters = tables['parameters.csv']
    for ax, key, unit in ((axes[0, 2], 'd', 'N s/m'), (axes[1, 0], 'mu_C', '-')):
        rows = [r for r in parameters if r['key'] == key]
        t = np.array([float(r['t']) for r in rows])
        value = np.array([float(r['estimate']) for r in rows])
        spread = np.array([float(r['spread']) for r in rows])
        ax.plot(t, value, color='tab:green')
        ax.fill_between(t, value - spread, value + spread, color='tab:green', alpha=0.25)
        ax.set(title=f'{key}: estimate ± spread', xlabel='t (s)', ylabel=f'{key} ({unit})')
    ax = axes[1, 1]
    starts, ratio, low, high = _consistency(tables['frames.csv'])
    ax.step(starts, ratio, where='post', label='NIS / dof')
    ax.fill_between(starts, low, high, step='post', color='tab:gray', alpha=0.3,
                    label='χ² bounds, α = 1e-3')
    ax.set(title='consistency per second', xlabel='t (s)', ylabel='NIS / degrees of freedom')
    ax.legend()
    ax = axes[1, 2]
    rows = tables['frames.csv']
    t = np.array([float(r['t']) for r in rows])
    ax.plot(t, [int(r['detections']) for r in rows], lw=0.8, label='detections')
    ax.plot(t, [int(r['associated']) for r in rows], lw=0.8, label='associated')
    ax.set(title='frames', xlabel='t (s)', ylabel='count')
    ax.legend()
    figure.suptitle(f'{title}: forecasts scored against the {len(tables["exits.csv"])} '
                    'exits the twin saw')
    figure.tight_layout()
    return figure


def write_report(out: Path, path: Path | None = None, dpi: float = 100.0) -> Path:
    """Draw the report of the run directory out into path (default out/report.png)."""
    path = path or out / 'report.png'
    build_figure(out, dpi=dpi).savefig(path)
    return path
