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
A twin fed as a live feeder reports: frame by frame, forecasts on a schedule, its state.

:class:`Follower` is what ``twin_node`` runs, without ROS: the twin is made at the first
input (its time starts at that stamp), each accepted frame is analysed
(:meth:`.estimator.Twin.update`), a forecast is made when ``forecast_period`` s of stream
time have passed since the last, and a cone speed that arrives while no frame has come for
``open_loop_after`` s moves a copy of the twin on by itself (open loop: the forecasts go on
from the model alone; it takes the measured exits as they come due, any of its pieces a
candidate, :meth:`.estimator.Twin.open_loop_exits`). Its state is one of

- ``waiting``: no input yet;
- ``following``: frames arrive and most detections are associated;
- ``open loop``: no frame for ``open_loop_after`` s (the cone speeds move a copy of the
  twin on, :attr:`Follower.current`, and the forecasts go on from it);
- ``lost``: frames arrive but fewer than half of the last second's detections were
  associated with a piece or bore one (the twin's pieces are not where the camera sees
  them, and the camera's are near the rim, where none is born).

With ``background`` the forecasts run on a thread of their own, from a snapshot of the twin
(the kernels release the GIL): a frame is answered after its own analysis, not after a
forecast over the longest horizon, and :attr:`Follower.outlook` is the newest forecast
finished (a forecast due while one runs is skipped: never a queue). Without it (the
default) the forecast is made in the call that finds it due: deterministic, for tests and
the headless run.
"""

from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
import math
import time

from .estimator import EXIT_LAG, Frame, Twin, TwinSettings
from .forecast import Forecast, forecast
from .frames import DetectionFrame
from ..errors import Stopped
from ..physics.simulation import SimParams
from ..physics.stop import StopFlag

__all__ = ['Follower', 'LiveSettings', 'STATES']

#: The follower's states, as diagnostics name them.
STATES = ('waiting', 'following', 'open loop', 'lost')


@dataclass(frozen=True)
class LiveSettings:
    """
    The estimator's settings, the forecasts' horizons (s) and period (s), open loop (s).

    max_delay: how late (s of stream time behind the twin) a frame may arrive and still be
    analysed, by going back to the twin as it was before it and analysing again;
    background: the forecasts on a thread of their own (see the module).
    """

    twin: TwinSettings = TwinSettings()
    horizons: tuple[float, ...] = (0.5, 1.0, 2.0)
    forecast_period: float = 0.1
    open_loop_after: float = 1.0
    max_delay: float = 0.2
    background: bool = False


class Follower:
    """A twin fed frame by frame (see the module)."""

    def __init__(self, params: SimParams, settings: LiveSettings = LiveSettings()) -> None:
        """Wait for the first input."""
        self.params, self.settings = params, settings
        #: set it to stop the computation under way (it raises Stopped within a step)
        self.stop = StopFlag()
        self.twin: Twin | None = None
        self.last_frame: float | None = None
        self.outlook: Forecast | None = None
        #: what the last analysed frame did
        self.last: Frame | None = None
        self._waiting: list[DetectionFrame] = []
        #: in open loop: a copy of the twin moved on by the cone speeds (see current)
        self._ahead: Twin | None = None
        #: (t, the twin before it moved to t, the frame analysed at t); the last max_delay s
        self._history: deque[tuple[float, Twin, DetectionFrame]] = deque()
        #: the cone speeds measured over the history: (t, omega); the measured exits: (t,
        #: channel, mass (kg; NaN: not weighed))
        self._speeds: deque[tuple[float, float]] = deque()
        self._measured: list[tuple[float, int, float]] = []
        self._cone_t = -math.inf
        self._due = 0.0
        #: per frame of the last second: (t, detections, associated or born)
        self._recent: deque[tuple[float, int, int]] = deque()
        #: counters since the last :meth:`figures` call
        self._window = {'frames': 0, 'nis': 0.0, 'observed': 0, 'detections': 0,
                        'associated': 0, 'busy': 0.0, 'stream': 0.0, 'forecasts': 0,
                        'forecast_busy': 0.0, 'measured': 0, 'explained': 0}
        self._pool = ThreadPoolExecutor(1, 'twin-forecast') if settings.background else None
        self._running: Future | None = None

    @property
    def t(self) -> float | None:
        """Return the twin's time (s), None before the first input."""
        return None if self.twin is None else self.twin.t

    def _start(self, t: float) -> Twin:
        if self.twin is None:
            self.twin = Twin(self.params, self.settings.twin, t0=t, stop=self.stop)
            self._due = t
        return self.twin

    def cone_speed(self, t: float, omega: float) -> list[float]:
        """
        Take a measured cone speed (rad/s) at t (s); return the stamps of the frames taken.

        Frames that waited for the speed at their stamp are analysed now; in open loop a
        copy of the twin moves on to t by itself (:attr:`current`). Raises ValueError for a
        speed out of order or not finite.
        """
        twin = self._start(t)
        twin.cone_speed(t, omega)
        self._speeds.append((t, omega))
        self._cone_t = t
        taken = self._take(lambda waiting: waiting.t <= t)
        if taken or self.state(t) != 'open loop' or t <= self.current.t:
            return taken
        start = time.perf_counter()
        if self._ahead is None:  # the twin stays where the last frame left it
            self._ahead = twin.snapshot()
        before = self._ahead.t
        self._ahead.cone_speed(t, omega)
        self._ahead.predict(t)
        self._ahead.open_loop_exits()
        self._window['stream'] += t - before
        self._forecast_if_due(t, self._ahead)
        self._window['busy'] += time.perf_counter() - start
        return taken

    @property
    def current(self) -> Twin | None:
        """
        Return the twin as it stands now: in open loop, a copy moved on by the model alone.

        The twin itself stays at its last frame, so that frames that come back late after a
        pause (or that a slow twin takes late) are analysed from there, never refused as
        older than a twin the cone speeds moved on.
        """
        return self._ahead if self._ahead is not None else self.twin

    def frame(self, found: DetectionFrame) -> list[float]:
        """
        Take a frame; return the stamps of the frames analysed now.

        A frame waits for the cone speed measured at or after its stamp (the encoder's
        reading of the same instant may arrive just after it): without it the members would
        turn the cone at the speed of the frame before. A newer frame releases the frames
        that still wait (no encoder: they go on the last speed measured). Raises ValueError
        for a mass a piece cannot have (:meth:`.estimator.Twin.check_masses`).
        """
        self._start(found.t).check_masses(found.masses)  # refused before it waits
        taken = self._take(lambda waiting: True)
        self._waiting.append(found)
        return taken + self._take(lambda waiting: waiting.t <= self._cone_t)

    def measured_exit(self, t: float, channel: int, mass: float = math.nan) -> list[float]:
        """
        Take an exit a channel's sensor measured at t (s); return the stamps analysed again.

        mass: the piece's (kg, a load cell's step; NaN: not weighed). The frame stamped
        :data:`~.estimator.EXIT_LAG` s after it takes it (:meth:`.estimator.Twin.update`);
        one that comes after that frame was analysed goes back to the twin before it, as a
        late frame does. Raises ValueError for a channel not in the layout, a mass neither
        NaN nor in (0, :attr:`~.estimator.Twin.heaviest`), or an exit older than the history.
        """
        if not math.isfinite(t):
            raise ValueError(f'measured exit at t = {t} s: not finite')
        twin = self._start(t)
        channel, mass = twin.exit_channel(channel), twin.exit_mass(mass)
        if t > twin.t - EXIT_LAG:  # no frame took it yet (Twin.measured_exit's test)
            twin.pend_exit(t, channel, mass)
            self._measured.append((t, channel, mass))
            if self._ahead is not None:  # in the dark, the copy takes it too, now if due
                self._ahead.pend_exit(t, channel, mass)
                self._ahead.open_loop_exits()
            return []
        later = [k for k, (stamp, _, _) in enumerate(self._history) if stamp - EXIT_LAG >= t]
        if not later or self._history[later[0]][1].t - EXIT_LAG >= t:
            raise ValueError(f'measured exit at t = {t} s is older than the twin can go back '
                             f'to (max_delay {self.settings.max_delay} s)')
        self._measured.append((t, channel, mass))
        frames = self._back_to(later[0])
        for found in frames:
            self._analyse(found)
        return [found.t for found in frames]

    def _take(self, ready: Callable[[DetectionFrame], bool]) -> list[float]:
        taken = []
        while self._waiting and ready(self._waiting[0]):
            found = self._waiting.pop(0)
            if found.t < self.twin.t:
                self._rewind(found)
            else:
                self._analyse(found)
            taken.append(found.t)
        return taken

    def _remember(self, t: float, found: DetectionFrame) -> None:
        """Keep the twin as it is before it moves to t (for frames that come late)."""
        self._history.append((t, self.twin.snapshot(), found))
        while self._history and self._history[0][0] < t - self.settings.max_delay:
            self._history.popleft()
        while self._speeds and self._speeds[0][0] < t - self.settings.max_delay - 1.0:
            self._speeds.popleft()
        oldest = self._history[0][1].t - EXIT_LAG  # the exits no snapshot can take again
        self._measured = [e for e in self._measured if e[0] > oldest]

    def _back_to(self, first: int) -> list[DetectionFrame]:
        """
        Go back to the twin before the history's frame ``first``; return the frames from it.

        The cone speeds and measured exits taken since are given to it again (stamp order:
        what they would have given in order).
        """
        _, twin, _ = self._history[first]
        frames = [found for _, _, found in list(self._history)[first:]]
        for _ in range(len(self._history) - first):
            self._history.pop()
        self.twin = twin
        for t, omega in self._speeds:
            if t > twin.times[-1]:
                twin.cone_speed(t, omega)
        twin.pending_exits = sorted(e for e in self._measured if e[0] > twin.t - EXIT_LAG)
        return frames

    def _rewind(self, late: DetectionFrame) -> None:
        """
        Go back to the twin before the first step past the late frame; analyse again.

        The late frame and the frames after it are analysed in stamp order, from the twin
        as it was (its random numbers included): the result is what the frames in order
        would have given. A frame older than the history raises ValueError.
        """
        later = [k for k, (t, _, _) in enumerate(self._history) if t > late.t]
        if not later or self._history[later[0]][1].t > late.t:
            since = self._history[0][1].t if self._history else self.twin.t
            raise ValueError(f'detections at t = {late.t} s are older than the twin '
                             f'({self.twin.t} s) can go back to ({since:g} s: max_delay '
                             f'{self.settings.max_delay} s, or the twin began later)')
        frames = self._back_to(later[0])
        for found in sorted(frames + [late], key=lambda f: f.t):
            self._analyse(found)

    def _analyse(self, found: DetectionFrame) -> Frame:
        """Analyse a frame; make the forecast if one is due."""
        self._ahead = None
        twin = self.twin
        start = time.perf_counter()
        before = twin.t
        self._remember(found.t, found)
        done = twin.update(found.t, found.xy, found.masses, found.track_ids)
        self.last_frame = found.t
        self.last = done
        window = self._window
        window['stream'] += found.t - before
        window['frames'] += 1
        window['nis'] += done.nis
        window['observed'] += done.observed
        window['detections'] += len(found.xy)
        window['associated'] += done.associated
        window['measured'] += done.measured
        window['explained'] += done.explained
        self._recent.append((found.t, len(found.xy), done.associated + done.births))
        while self._recent and self._recent[0][0] < found.t - 1.0:
            self._recent.popleft()
        self._forecast_if_due(found.t, twin)
        window['busy'] += time.perf_counter() - start
        return done

    def _forecast_if_due(self, t: float, twin: Twin) -> None:
        if self._running is not None and self._running.done():
            self._finish(self._running)
        if t + 1e-9 < self._due:
            return
        period = self.settings.forecast_period
        while self._due <= t + 1e-9:
            self._due += period
        if self._pool is None:
            self.outlook = forecast(twin, self.settings.horizons)
            self._window['forecasts'] += 1
        elif self._running is None:  # else skipped: the thread is still on the last one
            self._running = self._pool.submit(self._timed_forecast, twin.snapshot())

    def _timed_forecast(self, twin: Twin) -> tuple[Forecast, float]:
        start = time.perf_counter()
        return forecast(twin, self.settings.horizons), time.perf_counter() - start

    def _finish(self, running: Future) -> None:
        """Take a finished background forecast (a stopped one is dropped)."""
        self._running = None
        try:
            self.outlook, seconds = running.result()
        except Stopped:
            return
        self._window['forecasts'] += 1
        self._window['forecast_busy'] += seconds

    def close(self) -> None:
        """End the forecasts' thread (after the forecast under way, stopped or not)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)

    def state(self, t: float | None = None) -> str:
        """Return the state at stream time t (default: the twin's time)."""
        if self.twin is None:
            return 'waiting'
        t = self.current.t if t is None else t
        if self.last_frame is None or t - self.last_frame > self.settings.open_loop_after:
            return 'open loop'
        seen = sum(k for _, k, _ in self._recent)
        if seen and 2 * sum(a for _, _, a in self._recent) < seen:
            return 'lost'
        return 'following'

    def figures(self) -> dict[str, float]:
        """
        Return the figures since the last call, and start a new window.

        frames, forecasts; nis and observed (its degrees of freedom); association (the share
        of detections associated); measured: the measured exits the frames took, explained:
        the share of them an exit of the twin's or a piece explained (NaN: none); rtf: stream
        seconds taken per second of computing (at
        least 1: the twin keeps up with a live stream; background forecasts counted as if
        they took turns with the frames, which two cores need not); busy (s of computing).
        """
        if self._running is not None and self._running.done():
            self._finish(self._running)
        w = self._window
        w['busy'] += w['forecast_busy']
        out = {'frames': w['frames'], 'forecasts': w['forecasts'], 'nis': w['nis'],
               'observed': w['observed'], 'busy': w['busy'],
               'association': (w['associated'] / w['detections'] if w['detections']
                               else float('nan')),
               'measured': w['measured'],
               'explained': (w['explained'] / w['measured'] if w['measured']
                             else float('nan')),
               'rtf': w['stream'] / w['busy'] if w['busy'] > 0.0 else float('inf')}
        for key in w:
            w[key] = 0.0 if isinstance(w[key], float) else 0
        return out
