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
The command line: `cone-feeder-sim run`, `report` and `recover`.

`cone-feeder-sim run SCENARIO.yaml --events EVENTS.csv` runs a scenario;
`cone-feeder-sim report RUN.mcap --out REPORT.png` draws the report of a recorded run;
`cone-feeder-sim recover IN.mcap OUT.mcap` makes a complete file of an unfinished one.

Exit codes: 0 success, 2 bad input (scenario or arguments), 1 other errors.
"""

import argparse
from collections.abc import Sequence
import os
from pathlib import Path
import sys
import time
from typing import TextIO

from . import __version__
from .errors import ConeFeederError
from .feeder.runner import run_scenario
from .feeder.scenario import Scenario
from .formats.events_csv import write_events_csv
from .formats.mcap_reader import recover_mcap
from .formats.runlog import ScenarioRecorder
from .formats.scenario_file import load_scenario
from .physics.simulation import Simulator, StepResult


class ProgressBar:
    """A text progress bar on a stream: redrawn in place on a terminal, else every 10%."""

    def __init__(self, total: float, stream: TextIO, width: int = 30) -> None:
        """Prepare a bar for a run of `total` simulated seconds."""
        self.total = total
        self.stream = stream
        self.width = width
        self.tty = stream.isatty()
        self.exits = 0
        self.last_draw = 0.0
        self.last_decile = -1
        self.start = time.monotonic()

    def __call__(self, t: float, sim: Simulator, step: StepResult) -> None:
        """Update after an output interval."""
        self.exits += len(step.exits)
        frac = min(1.0, t / self.total)
        now = time.monotonic()
        decile = int(frac * 10)
        if self.tty and (now - self.last_draw < 0.1 and frac < 1.0):
            return
        if not self.tty and decile == self.last_decile:
            return
        self.last_draw = now
        self.last_decile = decile
        filled = int(round(frac * self.width))
        line = (f'[{"#" * filled}{"." * (self.width - filled)}] {100 * frac:5.1f}% '
                f't={t:.3f}/{self.total:.3f} s pieces={sim.state.count} exits={self.exits} '
                f'wall={now - self.start:.1f} s')
        self.stream.write(('\r' + line) if self.tty else (line + '\n'))
        if self.tty and frac >= 1.0:
            self.stream.write('\n')
        self.stream.flush()


def check_writable(path: str, what: str = 'events') -> None:
    """Refuse an output path whose directory does not exist or cannot be written, up front."""
    parent = Path(path).resolve().parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise ConeFeederError(f'cannot write {what} to {path}: directory {parent} does not '
                              'exist or is not writable')


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of the command line."""
    parser = argparse.ArgumentParser(
        prog='cone-feeder-sim',
        description='Simulate pieces of product on the rotating cone feeder of a multihead '
                    'weigher.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    sub = parser.add_subparsers(dest='command', required=True)
    run = sub.add_parser('run', help='run a scenario headless and write its exit events')
    run.add_argument('scenario', help='scenario YAML file')
    run.add_argument('--events', required=True, help='CSV file for the exit events')
    run.add_argument('--quiet', action='store_true', help='no progress bar')
    run.add_argument('--mcap', metavar='OUT.mcap',
                     help='also record the run to an MCAP file (the topics of sim_node)')
    report = sub.add_parser(
        'report', help='draw a one-page PNG report of a recorded run (MCAP file)')
    report.add_argument('mcap', help='MCAP file of a run (sim_node or the headless runner)')
    report.add_argument('--out', help='PNG file to write (default: the MCAP path with .png)')
    report.add_argument('--namespace', default=None,
                        help='use the topics of this namespace (default: the first found)')
    report.add_argument('--max-trajectories', type=int, default=None, metavar='N',
                        help='draw at most N trajectories (default 60)')
    report.add_argument('--dpi', type=float, default=100.0,
                        help='resolution; the page is 17 x 9.6 inches (default 100)')
    recover = sub.add_parser(
        'recover', help='copy the readable part of an unfinished or damaged MCAP file into a '
                        'complete one (with summary and footer)')
    recover.add_argument('mcap', metavar='IN.mcap', help='MCAP file to recover')
    recover.add_argument('out', metavar='OUT.mcap', help='complete MCAP file to write')
    return parser


def cmd_run(args: argparse.Namespace, err: TextIO) -> int:
    """Run a scenario; return the exit code."""
    scenario: Scenario = load_scenario(args.scenario)
    check_writable(args.events)
    bar = None if args.quiet else ProgressBar(scenario.duration, err)
    recorder = ScenarioRecorder(args.mcap, scenario, args.scenario) if args.mcap else None
    try:
        callbacks = [c for c in (recorder, bar) if c is not None]

        def progress(t: float, sim: Simulator, step: StepResult) -> None:
            for callback in callbacks:
                callback(t, sim, step)

        result = run_scenario(scenario, progress if callbacks else None)
    finally:
        if recorder is not None:
            recorder.close()
    rows = write_events_csv(args.events, result.exit_table())
    for failure in result.failures:
        err.write(f'warning: particle {failure.particle_id} removed at t={failure.t:.6f} s: '
                  f'{failure.reason}\n')
    err.write(f'{rows} of {len(scenario.particles)} pieces left the cone; '
              f'{result.remaining_ids.size} still on it, {len(result.failures)} failed; '
              f'events written to {args.events}\n')
    if recorder is not None:
        err.write(f'run recorded to {args.mcap}\n')
    return 0


def cmd_report(args: argparse.Namespace, err: TextIO) -> int:
    """Write the PNG report of a recorded run; return the exit code."""
    from .report.draw import DEFAULT_MAX_TRAJECTORIES, write_report  # matplotlib when needed

    out = args.out if args.out else str(Path(args.mcap).with_suffix('.png'))
    if args.max_trajectories is not None and args.max_trajectories < 1:
        raise ConeFeederError('--max-trajectories must be at least 1')
    if not args.dpi > 0:
        raise ConeFeederError('--dpi must be positive')
    if Path(out).resolve() == Path(args.mcap).resolve():
        raise ConeFeederError(f'the report would overwrite the recording {args.mcap}')
    check_writable(out, 'the report')
    run = write_report(
        args.mcap, out, dpi=args.dpi, namespace=args.namespace,
        max_trajectories=args.max_trajectories or DEFAULT_MAX_TRAJECTORIES)
    for note in run.notes:
        err.write(f'note: {note}\n')
    totals = run.exit_totals()
    err.write(f'report written to {out}: {run.message_count} messages, '
              f'{run.trajectories.pieces_seen} pieces seen, {len(run.exits)} exits '
              f'({float(totals.mass.sum()):.3f} kg)\n')
    return 0


def cmd_recover(args: argparse.Namespace, err: TextIO) -> int:
    """Recover the readable part of an MCAP file; return the exit code."""
    if Path(args.out).resolve() == Path(args.mcap).resolve():
        raise ConeFeederError(f'recovering {args.mcap} into itself would destroy it')
    check_writable(args.out, 'the recovered file')
    count = recover_mcap(args.mcap, args.out)
    err.write(f'recovered {count} messages from {args.mcap} into {args.out}\n')
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `cone-feeder-sim`."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command == 'run':
            return cmd_run(args, sys.stderr)
        if args.command == 'report':
            return cmd_report(args, sys.stderr)
        if args.command == 'recover':
            return cmd_recover(args, sys.stderr)
    except ConeFeederError as exc:
        sys.stderr.write(f'error: {exc}\n')
        return 2
    return 1


if __name__ == '__main__':
    sys.exit(main())
