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

`run` appends every exit to the CSV as its output interval ends (flushed). SIGINT (Ctrl-C)
or SIGTERM ends it cleanly within a step of the integration (:class:`StopOnSignals`): the
interval under way is dropped, the CSV keeps the exits of the finished ones, the MCAP file
is closed complete, and one line says where the run stopped. With `--view` the
run is served live on a Foxglove WebSocket (:mod:`cone_feeder_sim.view.live`), paced to
`--speed` simulated seconds per second; the view stays up after the run's end until Ctrl-C
(exit code 0 then), and the files are the same as without it.

Exit codes: 0 success, 2 bad input (scenario or arguments), 1 other errors; 130 (SIGINT) or
143 (SIGTERM), i.e. 128 + the signal number as a shell reports it, for an interrupted run.
"""

import argparse
from collections.abc import Callable, Iterator, Sequence
import contextlib
import dataclasses
import os
from pathlib import Path
import signal
import sys
import threading
import time
from types import FrameType, TracebackType
from typing import Any, Self, TextIO

from . import __version__
from .errors import ConeFeederError
from .feeder.realtime import RealTime
from .feeder.runner import Progress, scenario_weigher
from .feeder.scenario import Scenario
from .formats.mcap_reader import recover_mcap
from .formats.run_files import run_to_files, RunFiles
from .formats.scenario_file import load_scenario
from .physics.simulation import kernel_cache_note, Simulator, StepResult, warm_up
from .physics.stop import StopFlag
from .view.live import DEFAULT_FPS, DEFAULT_PORT, LiveView
from .view.topics import layout_file


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
        self.pending = False  # a redrawn line without its newline
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
        self.pending = self.tty
        if self.tty and frac >= 1.0:
            self.end()
        self.stream.flush()

    def end(self) -> None:
        """End the line of a bar redrawn in place, so that what follows starts a new one."""
        if self.pending:
            self.stream.write('\n')
            self.stream.flush()
            self.pending = False


#: Signals that end a headless run cleanly; its exit code is then 128 + the signal number.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)

SignalHandler = Callable[[int, FrameType | None], Any] | int | None


class StopOnSignals(StopFlag):
    """
    While active, SIGINT and SIGTERM only note that the run is to stop (no KeyboardInterrupt).

    A :class:`~cone_feeder_sim.physics.stop.StopFlag`: the runner calls it between intervals
    (its stop predicate) and the kernels read it between steps, so a signal ends even an
    interval that computes for seconds within a step. Python runs its signal handlers only
    between bytecodes of the main thread, which a kernel holds for the whole interval; so
    the signal's byte on the wake-up fd (``signal.set_wakeup_fd``, written by the C handler
    at once) wakes a watcher thread that sets the flag. ``signum`` is the first signal
    received, None if none; later ones change nothing. The previous handlers (and wake-up
    fd) come back at the end of the with block. A signal ignored on entry (as a shell script
    leaves SIGINT for a command it runs with ``&``) stays ignored. Outside the main thread,
    where Python cannot install signal handlers, it installs none.
    """

    def __init__(self, signals: Sequence[signal.Signals] = STOP_SIGNALS) -> None:
        """Prepare to catch `signals`."""
        super().__init__()
        self.signals = tuple(signals)
        self.signum: int | None = None
        self._previous: dict[int, SignalHandler] = {}
        self._previous_fd = -1
        self._write_fd = -1
        self._watcher: threading.Thread | None = None

    def __enter__(self) -> Self:
        """Install the handlers and the watcher of the wake-up fd."""
        if threading.current_thread() is threading.main_thread():
            for signum in self.signals:
                if signal.getsignal(signum) != signal.SIG_IGN:
                    self._previous[signum] = signal.signal(signum, self._handle)
        if self._previous:
            read_fd, self._write_fd = os.pipe()
            os.set_blocking(self._write_fd, False)
            self._previous_fd = signal.set_wakeup_fd(self._write_fd, warn_on_full_buffer=False)
            self._watcher = threading.Thread(target=self._watch, args=(read_fd,),
                                             name='stop-on-signals', daemon=True)
            self._watcher.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        """Restore the previous handlers (the default one where Python had none)."""
        for signum, handler in self._previous.items():
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)
        self._previous.clear()
        if self._watcher is not None:
            signal.set_wakeup_fd(self._previous_fd)
            os.close(self._write_fd)  # the watcher reads the end of the pipe and returns
            self._watcher.join()
            self._watcher = None

    def _watch(self, read_fd: int) -> None:
        """Set the flag on every stop signal written to the wake-up fd (watcher thread)."""
        try:
            while data := os.read(read_fd, 64):  # waits without the GIL
                for signum in data:
                    if signum in self.signals:
                        self._stop(signum)
                if self._previous_fd >= 0:  # whoever had the wake-up fd before gets it too
                    with contextlib.suppress(OSError):
                        os.write(self._previous_fd, data)
        finally:
            os.close(read_fd)

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self._stop(signum)

    def _stop(self, signum: int) -> None:
        if self.signum is None:
            self.signum = signum
        self.request()


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
    run.add_argument('--packs', metavar='PACKS.csv',
                     help="CSV file for the weigher's packs (the scenario needs a weigher: "
                          'section; weigher: {} is the default machine)')
    run.add_argument('--mcap', metavar='OUT.mcap',
                     help='also record the run to an MCAP file (the topics of sim_node)')
    run.add_argument('--view', action='store_true',
                     help='serve the run live on a Foxglove WebSocket, paced to real time, '
                          'until Ctrl-C (needs foxglove-sdk: the [view] extra)')
    run.add_argument('--port', type=int, default=None, metavar='PORT',
                     help=f'--view: the WebSocket port (default {DEFAULT_PORT}; 0: any free '
                          'one)')
    run.add_argument('--speed', type=float, default=None, metavar='S',
                     help='--view: simulated seconds per wall second (default 1; inf: as '
                          'fast as possible)')
    run.add_argument('--fps', type=float, default=None, metavar='HZ',
                     help=f'--view: frames per second (default {DEFAULT_FPS:g})')
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
    sub.add_parser(
        'compile', help='compile the integration and weigher kernels into the numba cache '
                        '(run once after installing, so that no start has to)')
    sweep = sub.add_parser(
        'sweep', help='run a scenario many times with other parameters and seeds, on Dask '
                      '(pip install cone_feeder_sim[sweep])')
    sweep.add_argument('sweep', metavar='SWEEP.yaml', help='sweep file: a scenario and what '
                       'varies (grid, random, seeds)')
    sweep.add_argument('--out', required=True, metavar='DIR',
                       help='directory of the results (created; a re-run resumes it)')
    sweep.add_argument('--scheduler', metavar='ADDRESS',
                       help='address of a running Dask scheduler (tcp://host:port); default: '
                            'a local cluster of this machine')
    sweep.add_argument('--workers', type=int, metavar='N',
                       help='worker processes of the local cluster (default: one per core)')
    sweep.add_argument('--retry-failed', action='store_true',
                       help='run the jobs that failed before again')
    fit = sub.add_parser(
        'fit', help="fit a scenario's free parameters to tracked pieces (bounded least "
                    'squares, standard errors, correlations, identifiability warnings)')
    fit.add_argument('fit', metavar='FIT.yaml', help='fit file: scenario, tracks, free keys')
    fit.add_argument('--out', required=True, metavar='RESULT.yaml',
                     help='where to write the estimates, errors and correlations')
    fit.add_argument('--report', metavar='PNG',
                     help='draw the tracks against the fitted simulation, and the residuals')
    fit.add_argument('--tracks', metavar='TRACKS',
                     help="tracks (CSV) or a recording (RUN.mcap) instead of the fit file's")
    fit.add_argument('--quick', action='store_true',
                     help="one start (the fit file's values) instead of the fit file's "
                          'starts (auto by default: batches of 8 until 3 reach the lowest '
                          'cost)')
    fit.add_argument('--scheduler', metavar='ADDRESS',
                     help="run the fit's simulations on a running Dask scheduler "
                          "(tcp://host:port), the sweep's cluster; default: this process")
    fit.add_argument('--workers', type=int, metavar='N',
                     help="run the fit's simulations on a local Dask cluster of N worker "
                          'processes; default: this process')
    twin = sub.add_parser(
        'twin', help='follow recorded detections with the digital twin; write its forecasts '
                     '(channel_forecast.csv, pieces.csv, parameters.csv, frames.csv)')
    twin.add_argument('twin', metavar='TWIN.yaml',
                      help='twin file: scenario, detections, cone and settings (doc/twin.md)')
    twin.add_argument('--out', required=True, metavar='DIR', help='directory for the CSVs')
    recover = sub.add_parser(
        'recover', help='copy the readable part of an unfinished or damaged MCAP file into a '
                        'complete one (with summary and footer)')
    recover.add_argument('mcap', metavar='IN.mcap', help='MCAP file to recover')
    recover.add_argument('out', metavar='OUT.mcap', help='complete MCAP file to write')
    return parser


def check_view_flags(args: argparse.Namespace) -> None:
    """Refuse --port, --speed and --fps without --view, and a port out of range."""
    given = [f'--{name}' for name in ('port', 'speed', 'fps') if getattr(args, name) is not None]
    if given and not args.view:
        raise ConeFeederError(f'{", ".join(given)}: only with --view')
    if args.port is not None and not 0 <= args.port <= 65535:
        raise ConeFeederError(f'--port must be 0..65535, got {args.port}')


def cmd_run(args: argparse.Namespace, err: TextIO) -> int:
    """Run a scenario, writing exits as they happen; return the exit code."""
    check_view_flags(args)
    scenario: Scenario = load_scenario(args.scenario)
    check_writable(args.events)
    if args.packs is not None:
        if scenario.weigher is None:
            raise ConeFeederError(f'--packs needs a weigher: section in {args.scenario} '
                                  '(weigher: {} is the default machine)')
        check_writable(args.packs, 'the packs')
    weigher = scenario_weigher(scenario)
    bar = None if args.quiet else ProgressBar(scenario.duration, err)
    progress: list[Progress] = [bar] if bar is not None else []
    with contextlib.ExitStack() as stack:
        stop = stack.enter_context(StopOnSignals())
        view = None
        if args.view:  # before any file: a bad --speed or --fps, a port in use stop here
            pace = RealTime(1.0 if args.speed is None else args.speed, stop=stop)
            view = stack.enter_context(LiveView(
                scenario.model, weigher=weigher,
                fps=DEFAULT_FPS if args.fps is None else args.fps,
                port=DEFAULT_PORT if args.port is None else args.port))
            err.write(f'live view on {view.url} (Foxglove: Open connection; layout: '
                      f'{layout_file()})\n')
            err.flush()
            progress += [view, pace]
        try:
            files = run_to_files(scenario, args.events, packs=args.packs, mcap=args.mcap,
                                 source=args.scenario, progress=progress, stop=stop,
                                 weigher=weigher)
        finally:
            if bar is not None:
                bar.end()
        code = report_run(args, files, stop.signum, err)
        if view is not None and stop.signum is None:
            err.write(f'the run ended at t = {files.result.end_time:.3f} s; the live view '
                      f'stays on {view.url} until Ctrl-C\n')
            err.flush()
            while not stop():
                time.sleep(0.1)
        if view is not None and view.error is not None:
            err.write(f'warning: the live view stopped showing the run: {view.error!r}\n')
    return code


def report_run(args: argparse.Namespace, files: RunFiles, signum: int | None,
               err: TextIO) -> int:
    """Write what a run did (or where it was interrupted); return its exit code."""
    result = files.result
    for failure in result.failures:
        err.write(f'warning: particle {failure.particle_id} removed at t={failure.t:.6f} s: '
                  f'{failure.reason}\n')
    recorded = f', run recorded to {args.mcap}' if args.mcap else ''
    if result.stopped and signum is not None:
        err.write(f'interrupted by {signal.Signals(signum).name} at '
                  f't = {result.end_time:.3f} s: {files.events} exits written to '
                  f'{args.events}{recorded}\n')
        return 128 + signum
    err.write(f'{files.events} of {result.pieces} pieces left the cone; '
              f'{result.remaining_ids.size} still on it, {len(result.failures)} failed; '
              f'events written to {args.events}\n')
    if args.mcap:
        err.write(f'run recorded to {args.mcap}\n')
    if result.weigher is not None:
        stats = result.weigher.stats()
        err.write(f'weigher: {stats.packs} packs ({stats.packs_per_minute:.1f} per minute), '
                  f'giveaway {1e3 * stats.giveaway_mean:.1f} +- {1e3 * stats.giveaway_std:.1f} '
                  f'g, {100 * stats.under_target:.1f} % under target, '
                  f'{stats.starved_per_cycle:.2f} starved heads per cycle\n')
    if args.packs is not None:
        err.write(f'{files.packs} packs written to {args.packs}\n')
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


def cmd_compile(err: TextIO) -> int:
    """Compile or load the kernel (numba's cache); say where it is and how long it took."""
    from .weigher.combination import warm_up as warm_up_weigher
    start = time.perf_counter()
    warm_up()
    warm_up_weigher()
    err.write(kernel_cache_note(time.perf_counter() - start, hint=False) + '\n')
    return 0


@contextlib.contextmanager
def needs_dask() -> Iterator[None]:
    """Turn a missing dask.distributed, inside the block, into the one-line install hint."""
    try:
        yield
    except ImportError as exc:
        if exc.name not in ('dask', 'distributed'):
            raise
        raise ConeFeederError(SWEEP_INSTALL) from None


def check_cluster(args: argparse.Namespace) -> None:
    """Refuse --workers with --scheduler, and a local cluster of no workers."""
    if args.workers is not None:
        if args.scheduler is not None:
            raise ConeFeederError('--workers sets the local cluster; a scheduler has its own '
                                  'workers (give one or the other)')
        if args.workers < 1:
            raise ConeFeederError(f'--workers must be at least 1, got {args.workers}')


def cmd_fit(args: argparse.Namespace, err: TextIO) -> int:
    """Fit a scenario to tracks; write RESULT.yaml; warn of what the data cannot identify."""
    import yaml

    from .fit.problem import FitProblem
    from .fit.solve import fit
    from .fit.spec import load_fit

    check_cluster(args)
    spec = load_fit(args.fit, args.tracks)
    if args.quick:
        spec = dataclasses.replace(spec, starts=1)
    check_writable(args.out, 'the result')
    if args.report:
        check_writable(args.report, 'the report')
    warm_up()
    start = time.perf_counter()
    problem = FitProblem(spec)
    if args.scheduler is None and args.workers is None:
        result = fit(problem)
    else:
        with needs_dask():
            from .fit.solve import dask_mapper
            from .sweep.cluster import dask_client
        with dask_client(args.scheduler, args.workers) as client:
            result = fit(problem, mapper=dask_mapper(client))
    Path(args.out).write_text(yaml.safe_dump(result.as_mapping(), sort_keys=False),
                              encoding='utf-8')
    for key, estimate, stderr, low, high in zip(result.keys, result.estimate, result.stderr,
                                                result.low, result.high):
        err.write(f'{key} = {estimate:.6g} +- {stderr:.3g}, 95 % [{low:.6g}, {high:.6g}]\n')
    if result.fit_test is not None:
        test = result.fit_test
        err.write(f'test of fit: chi2 = {test.chi2:.4g} for {test.dof} degrees of freedom '
                  f'(threshold {test.threshold:.4g}): {"passed" if test.passed else "FAILED"}; '
                  f'{result.reached_best} of {len(result.start_costs)} starts reached the '
                  'lowest cost\n')
    for restart in result.restarts:
        err.write(f'restarted from the better point {restart.found_by} found: cost '
                  f'{restart.from_cost + restart.profile_cost:.4g} -> {restart.to_cost:.4g}\n')
    for warning in result.warnings:
        err.write(f'warning: {warning}\n')
    windows = (f' and {result.window_simulations} window simulations'
               if result.window_simulations else '')
    unit = ' m^2' if spec.exits is None else ' (residuals in sigmas)'
    err.write(f'{result.simulations} simulations{windows} in '
              f'{time.perf_counter() - start:.1f} s, cost {result.cost:.3g}{unit}; result '
              f'written to {args.out}\n')
    if args.report:
        from .fit.figure import draw_fit
        draw_fit(problem, result, args.report)
        err.write(f'report written to {args.report}\n')
    return 0


SWEEP_INSTALL = ('the sweep runs on Dask, which is not installed; install it with '
                 "pip install 'cone_feeder_sim[sweep]' (or pip install 'dask[distributed]')")


def cmd_twin(args: argparse.Namespace, err: TextIO) -> int:
    """Run the twin over a twin file's recorded streams; write its CSVs."""
    from .twin.estimator import parameter_note
    from .twin.run import run_twin
    from .twin.spec import load_twin

    spec = load_twin(args.twin)
    out = Path(args.out)
    warm_up()
    start = time.perf_counter()
    summary = run_twin(spec, out, log=lambda line: err.write(f'{line}\n'))
    wall = time.perf_counter() - start
    span = float(spec.detections[-1, 0] - spec.detections[0, 0]) if len(spec.detections) else 0.0
    err.write(f'{summary.frames} frames ({summary.refused} refused), {summary.forecasts} '
              f'forecasts; NIS {summary.nis:.1f} for {summary.observed} observations; '
              f'{span:.2f} s of stream in {wall:.2f} s; written to {out}\n')
    if note := parameter_note(spec.settings()):
        err.write(f'{note}\n')
    return 0


def cmd_sweep(args: argparse.Namespace, err: TextIO) -> int:
    """Run a sweep's pending jobs; return 0 if all are done, 1 if some failed."""
    from .sweep.spec import load_sweep

    check_cluster(args)
    sweep = load_sweep(args.sweep)  # a sweep file is checked without Dask too
    with needs_dask():
        from .sweep.run import run_sweep

    def log(line: str) -> None:
        err.write(line + '\n')
        err.flush()

    caught: list[int] = []

    def interrupt(signum: int, frame: FrameType | None) -> None:
        caught.append(signum)
        raise KeyboardInterrupt  # as Ctrl-C: the sweep closes its cluster and keeps its jobs

    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, interrupt) if main_thread else None
    try:
        report = run_sweep(sweep, args.out, scheduler=args.scheduler, workers=args.workers,
                           retry_failed=args.retry_failed, log=log)
    except KeyboardInterrupt:
        signum = caught[0] if caught else signal.SIGINT
        err.write(f'interrupted by {signal.Signals(signum).name}: the finished jobs are in '
                  f'{args.out} (summary.csv); run the same command again to run the others\n')
        return 128 + signum
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)
    figure = f', figure {report.figure}' if report.figure else ''
    err.write(f'{report.done} of {report.jobs} jobs done, {report.failed} failed '
              f'({report.ran} run now, {report.skipped} finished before); summary '
              f'{report.summary}{figure}\n')
    return 1 if report.failed else 0


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
        if args.command == 'sweep':
            return cmd_sweep(args, sys.stderr)
        if args.command == 'compile':
            return cmd_compile(sys.stderr)
        if args.command == 'fit':
            return cmd_fit(args, sys.stderr)
        if args.command == 'twin':
            return cmd_twin(args, sys.stderr)
    except ConeFeederError as exc:
        sys.stderr.write(f'error: {exc}\n')
        return 2
    except KeyboardInterrupt:  # Ctrl-C outside a run's intervals (loading, report, recover)
        sys.stderr.write('interrupted\n')
        return 128 + signal.SIGINT
    return 1


if __name__ == '__main__':
    sys.exit(main())
