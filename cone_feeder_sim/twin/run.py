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
The headless twin: a twin file's recorded streams through the estimator, faster than real time.

Frames are the detections sharing a stamp. Before each frame the cone speeds and measured
exits up to its stamp are taken; the frame is then associated and analysed
(:class:`.estimator.Twin`; it takes the exits up to :data:`.estimator.EXIT_LAG` before it).
Every ``every`` s of stream time the twin forecasts (:func:`.forecast.forecast`, under the
measured speed held). A bad frame (a coordinate not finite, more than
:data:`.frames.MAX_DETECTIONS` points, a stamp older than the twin, a mass no piece can
have) is refused with one line and the twin goes on; so is a cone speed that is not
finite, and a measured exit that is not in a channel of the layout or whose mass no piece
can have. A recording's messages are decoded and checked as twin_node decodes and checks
them (:mod:`.streams`): one the node would refuse is refused whole, its line logged when
the stream reaches its stamp. The output directory gets:

- ``channel_forecast.csv``: t, horizon, channel, mass, spread (s, s, -, kg, kg);
- ``pieces.csv``: t, piece, x, y, channel (0: stays), probability, exit_time, track_id (s,
  -, m, m, -, -, s, -; exit_time empty where no member lets the piece leave, track_id: the
  camera's track id last associated with the piece, empty where the detections have none);
- ``parameters.csv``: t, key, estimate, spread;
- ``frames.csv``: t, detections, associated, births, deaths, exits, nis, observed, measured,
  explained (the diagnostics; nis over observed is the consistency test; measured: the
  measured exits the frame took, explained: those an exit of the twin's or a piece
  explained);
- ``exits.csv``: t, piece, channel, mass (s, -, -, kg): the exits the twin saw, each piece
  followed to the rim (:class:`.estimator.Exit`): what the forecasts are scored against;
- ``report.png``: the one-page report (:mod:`.figure`): forecast error against lead time,
  the parameters' traces, the consistency test over time.
"""

from collections import deque
from collections.abc import Callable
import contextlib
import csv
from dataclasses import dataclass
import math
from pathlib import Path

import numpy as np

from .estimator import Twin
from .figure import write_report
from .forecast import forecast
from .frames import detection_frame
from .spec import TwinSpec
from ..errors import TwinError
from ..physics.simulation import SimParams

__all__ = ['run_twin', 'TwinSummary']

#: The output files and their columns (one table, written once).
FILES = {
    'channel_forecast.csv': ('t', 'horizon', 'channel', 'mass', 'spread'),
    'pieces.csv': ('t', 'piece', 'x', 'y', 'channel', 'probability', 'exit_time', 'track_id'),
    'parameters.csv': ('t', 'key', 'estimate', 'spread'),
    'frames.csv': ('t', 'detections', 'associated', 'births', 'deaths', 'exits', 'nis',
                   'observed', 'measured', 'explained'),
    'exits.csv': ('t', 'piece', 'channel', 'mass'),
}


@dataclass(frozen=True)
class TwinSummary:
    """What a headless twin run did: frames taken and refused, forecasts, NIS and its dof."""

    frames: int
    refused: int
    forecasts: int
    nis: float
    observed: int


def run_twin(spec: TwinSpec, out: Path, log: Callable[[str], None] = lambda line: None,
             riders: bool = True) -> TwinSummary:
    """
    Run the twin over the spec's streams; write the CSVs into out; return a summary.

    riders: as :func:`~.forecast.forecast`'s (False: every piece integrated to the horizon).
    """
    out.mkdir(parents=True, exist_ok=True)
    scenario = spec.scenario
    firsts = [table[0, 0] for table in (spec.detections, spec.cone, spec.exits) if len(table)]
    twin = Twin(SimParams(model=scenario.model, solver=scenario.solver), spec.settings(),
                t0=float(min(firsts, default=0.0)))
    stamps, starts = np.unique(spec.detections[:, 0], return_index=True)
    ends = list(starts[1:]) + [len(spec.detections)]
    cone = iter(spec.cone.tolist())
    pending = next(cone, None)
    unfit = deque(spec.refused)  # a recording's messages refused whole, as twin_node does

    def log_refused(until: float) -> None:
        while unfit and unfit[0][0] <= until:
            log(unfit.popleft()[2])

    exits = iter(spec.exits.tolist())
    measured = next(exits, None)
    frames = forecasts = observed = 0
    refused = sum(what == 'frame' for _, what, _ in spec.refused)
    nis = 0.0
    due = stamps[0] if len(stamps) else 0.0
    with contextlib.ExitStack() as stack:
        writers = {}
        for name, columns in FILES.items():
            stream = stack.enter_context((out / name).open('w', newline='', encoding='utf-8'))
            writers[name] = csv.writer(stream)
            writers[name].writerow(columns)
        for t, a, b in zip(stamps.tolist(), starts, ends):
            while pending is not None and pending[0] <= t:
                try:
                    twin.cone_speed(pending[0], pending[1])
                except ValueError as exc:
                    log(f'cone speed refused: {exc}')
                pending = next(cone, None)
            log_refused(t)
            while measured is not None and measured[0] <= t:
                try:
                    when, channel, mass = measured
                    twin.measured_exit(when, int(channel) if channel == channel // 1
                                       else channel, mass)
                except ValueError as exc:
                    log(f'exit refused: {exc}')
                measured = next(exits, None)
            rows = spec.detections[a:b]
            points = np.rec.fromarrays(rows[:, 1:5].T, names=('x', 'y', 'mass', 'track_id'))
            try:
                found = detection_frame(t, points)
                frame = twin.update(t, found.xy, found.masses, found.track_ids)
            except TwinError as exc:
                refused += 1
                log(str(exc))
                continue
            except ValueError as exc:
                refused += 1
                log(f'frame at t = {t:.4f} s refused: {exc}')
                continue
            frames += 1
            nis += frame.nis
            observed += frame.observed
            writers['frames.csv'].writerow([f'{t:.6f}', len(rows), frame.associated,
                                            frame.births, frame.deaths, frame.exits,
                                            f'{frame.nis:.6g}', frame.observed,
                                            frame.measured, frame.explained])
            for left in frame.left:
                writers['exits.csv'].writerow([f'{left.t:.6f}', left.piece, left.channel,
                                               f'{left.mass:.6g}'])
            if t + 1e-9 >= due:
                _write_forecast(twin, spec, writers, riders)
                forecasts += 1
                while due <= t + 1e-9:
                    due += spec.every
    log_refused(math.inf)  # after the last frame
    write_report(out)
    return TwinSummary(frames=frames, refused=refused, forecasts=forecasts, nis=nis,
                       observed=observed)


def _write_forecast(twin: Twin, spec: TwinSpec, writers: dict, riders: bool) -> None:
    """Forecast now; add its rows to the channel, piece and parameter files."""
    result = forecast(twin, spec.horizons, riders=riders)
    t = f'{result.t:.6f}'
    for h, masses, spreads in zip(result.horizons, result.mass, result.mass_spread):
        for channel, (mass, spread) in enumerate(zip(masses, spreads), start=1):
            writers['channel_forecast.csv'].writerow([t, f'{h:g}', channel, f'{mass:.6g}',
                                                      f'{spread:.6g}'])
    ids, mean, _ = twin.pieces()
    best, probability = result.most_likely()
    for i, (x, y), c, p, when in zip(ids.tolist(), mean, best, probability, result.exit_time):
        track = twin.tracks.get(i)
        writers['pieces.csv'].writerow([t, i, f'{x:.6f}', f'{y:.6f}', int(c), f'{p:.4g}',
                                        '' if np.isnan(when) else f'{when:.6f}',
                                        '' if track is None else track])
    for key, (estimate, spread) in twin.parameters().items():
        writers['parameters.csv'].writerow([t, key, f'{estimate:.6g}', f'{spread:.4g}'])
