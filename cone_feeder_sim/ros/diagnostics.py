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
``sim_node``'s diagnostics: the counters of a window and the statuses built from them.

Every ``diagnostics_period`` the node publishes a ``diagnostic_msgs/DiagnosticArray`` with
three statuses (as mappings for the CDR encoder): the simulation (real-time factor, tick
times, pieces, mass balance), the recording, and, with a weigher, its pack statistics. The
functions here build them from plain values; the node only gathers and publishes them.
"""

from dataclasses import dataclass
from typing import Any

from .pacing import Pacer
from ..feeder.engine import FeederEngine, TickResult
from ..formats.messages import stamp
from ..formats.run_recorder import RunRecorder
from ..weigher.machine import WeigherStats

__all__ = ['diagnostic_status', 'diagnostics_message', 'DiagnosticsWindow', 'recording_status',
           'RunTotals', 'simulation_status', 'weigher_status']

#: The hardware_id of every status.
HARDWARE_ID = 'cone_feeder'
#: Diagnostic levels (diagnostic_msgs/DiagnosticStatus).
OK, WARN, ERROR = 0, 1, 2


class DiagnosticsWindow:
    """
    Counters of the current diagnostics window.

    wall0 (s, perf_counter) and sim0 (s, simulation time) at its start; ticks done; step_s,
    step_max (s) total and longest tick; publish_s (s) total publishing; callback_max (s)
    longest executor callback; overruns: ticks longer than the period; lag_max (s) behind
    the wall clock; given_up (s) of simulation time beyond catch_up; integration steps
    accepted and rejected; largest_island (pieces linked by pairs within reach) and
    contacts (touching pairs) at most; coupling_forced: multirate coupling intervals
    accepted at the shortest interval above interactions.coupling_tolerance.
    """

    def __init__(self, wall: float, sim: float) -> None:
        """Start a window at wall time ``wall`` and simulation time ``sim``."""
        self.wall0 = wall
        self.sim0 = sim
        self.ticks = 0
        self.step_s = 0.0
        self.step_max = 0.0
        self.publish_s = 0.0
        self.callback_max = 0.0
        self.overruns = 0
        self.lag_max = 0.0
        self.given_up = 0.0
        self.accepted = 0
        self.rejected = 0
        self.largest_island = 0
        self.contacts = 0
        self.coupling_forced = 0

    def count(self, result: TickResult, step_s: float, publish_s: float, period: float
              ) -> None:
        """Count a published tick: it took step_s (s) to run, publish_s (s) to publish."""
        self.ticks += 1
        self.step_s += step_s
        self.step_max = max(self.step_max, step_s)
        self.publish_s += publish_s
        if period > 0.0 and step_s > period:
            self.overruns += 1
        self.accepted += result.stats.accepted
        self.rejected += result.stats.rejected
        self.largest_island = max(self.largest_island, result.stats.largest_island)
        self.contacts = max(self.contacts, result.stats.contacts)
        self.coupling_forced += result.stats.coupling_forced


@dataclass
class RunTotals:
    """
    Counts since the node started.

    ticks published; step_s, publish_s (s) wall time running and publishing them; exits and
    failures of pieces; refused inputs; last_tick the last published tick's result.
    """

    ticks: int = 0
    step_s: float = 0.0
    publish_s: float = 0.0
    exits: int = 0
    failures: int = 0
    refused: int = 0
    last_tick: TickResult | None = None

    def count(self, result: TickResult, step_s: float, publish_s: float) -> None:
        """Count a published tick: it took step_s (s) to run, publish_s (s) to publish."""
        self.ticks += 1
        self.step_s += step_s
        self.publish_s += publish_s
        self.exits += len(result.exits)
        self.failures += len(result.failures)
        self.last_tick = result


def diagnostic_status(level: int, name: str, message: str,
                      values: dict[str, str]) -> dict[str, Any]:
    """Return a diagnostic_msgs/DiagnosticStatus mapping (the package's hardware id)."""
    return {'level': level, 'name': name, 'message': message, 'hardware_id': HARDWARE_ID,
            'values': [{'key': k, 'value': v} for k, v in values.items()]}


def weigher_status(node: str, stats: WeigherStats) -> dict[str, Any]:
    """Return the diagnostic status of the weigher: its pack statistics so far."""
    values = {
        'packs': str(stats.packs),
        'packs per minute': f'{stats.packs_per_minute:.2f}',
        'giveaway mean (g)': f'{1e3 * stats.giveaway_mean:.2f}',
        'giveaway std (g)': f'{1e3 * stats.giveaway_std:.2f}',
        'under target (fraction)': f'{stats.under_target:.4f}',
        'below target - TNE (fraction)': f'{stats.below_tne:.4f}',
        'starved heads per cycle': f'{stats.starved_per_cycle:.2f}',
        'cycles': str(stats.cycles),
    }
    message = (f'{stats.packs} packs, {stats.packs_per_minute:.1f}/min, giveaway '
               f'{1e3 * stats.giveaway_mean:.1f} g')
    return diagnostic_status(WARN if stats.below_tne > 0.0 else OK, f'{node}: weigher', message,
                             values)


def recording_status(node: str, recorder: RunRecorder | None,
                     error: str | None) -> dict[str, Any]:
    """Return the diagnostic status of the recording: OK, off, or ERROR once it stopped."""
    values = {}
    if error is not None:
        level, message = ERROR, f'recording stopped: {error}'
    elif recorder is None:
        level, message = OK, 'not recording'
    else:
        level, message = OK, f'recording to {recorder.paths[-1]}'
    if recorder is not None:
        values = {'files': str(len(recorder.paths)),
                  'messages written': str(recorder.message_count),
                  'first file': str(recorder.path)}
    return diagnostic_status(level, f'{node}: recording', message, values)


def simulation_status(node: str, window: DiagnosticsWindow, now: float, engine: FeederEngine,
                      pacer: Pacer, paused: bool, res: TickResult | None, exits: int,
                      failures: int, refused: int) -> dict[str, Any]:
    """
    Return the diagnostic status of the simulation over the window ending at ``now``.

    WARN when the node cannot keep its real-time factor, or when a contact island was cut.
    exits, failures, refused: totals since the start.
    """
    wall = now - window.wall0
    sim = engine.t - window.sim0
    achieved = sim / wall if wall > 0 else 0.0
    ticks = max(window.ticks, 1)
    level = OK
    rtf = pacer.rtf
    if paused:
        message = f'paused at t = {engine.t:.3f} s'
    elif rtf == 0.0:
        message = f'running as fast as possible: real-time factor {achieved:.2f}'
    elif window.ticks and (window.given_up > 0.0 or achieved < 0.9 * rtf):
        level = WARN
        message = (f'cannot keep up: real-time factor {achieved:.2f} < {rtf:g} '
                   f'(tick {1e3 * window.step_s / ticks:.3g} ms, longest '
                   f'{1e3 * window.step_max:.3g} ms, period {1e3 * pacer.period:.3g} '
                   f'ms); {window.given_up:.3g} s beyond catch_up = '
                   f'{pacer.catch_up:g} s given up: simulation time runs slower')
    else:
        message = f'real-time factor {achieved:.2f} (target {rtf:g})'
    if window.coupling_forced and not paused:
        level = WARN
        message += (f'; {window.coupling_forced} coupling intervals accepted above '
                    f'interactions.coupling_tolerance = '
                    f'{engine.config.model.interactions.coupling_tolerance:g} m (at the '
                    f'shortest interval)')
    values = {
        'simulation time (s)': f'{engine.t:.6f}',
        'paused': str(paused),
        'real-time factor (achieved)': f'{achieved:.4f}',
        'real-time factor (target)': f'{rtf:g}',
        'update rate (Hz)': f'{1.0 / engine.dt:g}',
        'ticks in window': str(window.ticks),
        'step time mean (ms)': f'{1e3 * window.step_s / ticks:.3f}',
        'step time max (ms)': f'{1e3 * window.step_max:.3f}',
        'publish time mean (ms)': f'{1e3 * window.publish_s / ticks:.3f}',
        'overruns (ticks longer than the period)': str(window.overruns),
        'lag behind the wall clock max (ms)': f'{1e3 * window.lag_max:.3f}',
        'time given up (s)': f'{window.given_up:.3f}',
        'executor callback max (ms)': f'{1e3 * window.callback_max:.3f}',
        'pieces': str(engine.piece_count),
        'accepted steps': str(window.accepted),
        'rejected steps': str(window.rejected),
        'largest contact island (pieces)': str(window.largest_island),
        'touching pairs (max)': str(window.contacts),
        'coupling intervals above tolerance': str(window.coupling_forced),
        'exits (total)': str(exits),
        'failures (total)': str(failures),
        'mass in (kg)': f'{res.mass_in:.6f}' if res is not None else '0',
        'mass exited (kg)': f'{res.channel_mass.sum():.6f}' if res is not None else '0',
        'mass failed (kg)': f'{res.failed_mass:.6f}' if res is not None else '0',
        'refused inputs (total)': str(refused),
        'cone omega (rad/s)': f'{engine.omega:.4f}',
        'drive mode': res.mode if res is not None else 'not started',
    }
    return diagnostic_status(level, f'{node}: simulation', message, values)


def diagnostics_message(node: str, window: DiagnosticsWindow, now: float,
                        engine: FeederEngine, pacer: Pacer, paused: bool, totals: 'RunTotals',
                        recorder: RunRecorder | None, recording_error: str | None,
                        t: float) -> dict[str, Any]:
    """
    Return the node's diagnostic_msgs/DiagnosticArray (a mapping) at wall time ``now``.

    Statuses: the simulation over ``window``, the recording, and the weigher when there is
    one; t (s): the stamp, the time of the last published tick.
    """
    res = totals.last_tick
    statuses = [
        simulation_status(node, window, now, engine, pacer, paused, res, totals.exits,
                          totals.failures, totals.refused),
        recording_status(node, recorder, recording_error)]
    if res is not None and res.weigher_stats is not None:
        statuses.append(weigher_status(node, res.weigher_stats))
    return {'header': {'stamp': stamp(t), 'frame_id': ''}, 'status': statuses}
