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
The live node's ticks: a job on a worker thread, as many ticks as the pacer says are due.

The node's timer calls :meth:`Ticker.start`; the ticks that are due (:class:`~.pacing.Pacer`)
run on one worker thread (the integration releases the GIL and uses every core), stopping
after one period of wall time, and ``done()`` is called when they can be collected, so
that the node's executor thread collects and publishes them (:meth:`Ticker.collect`) and
starts the next job at once while it publishes. Pause and step wait for the running job
(:meth:`Ticker.finish`); shutdown stops it within a step. Free of rclpy: the tests drive it
with a fake engine.
"""

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
import time
from typing import Protocol

from .diagnostics import DiagnosticsWindow
from .pacing import Pacer
from ..errors import Stopped
from ..feeder.engine import TickResult

__all__ = ['FAST_TIMER_PERIOD', 'TickEngine', 'Ticker', 'Ticks']

#: Period (s) of the tick timer when running as fast as possible (real_time_factor 0): the
#: worker's ticks follow each other directly; the timer only restarts them after a resume.
FAST_TIMER_PERIOD = 0.02

#: Finished ticks with the wall seconds each took, in tick order.
Ticks = list[tuple[TickResult, float]]


class TickEngine(Protocol):
    """What the ticker needs of an engine (a FeederEngine is one)."""

    @property
    def t(self) -> float:
        """Return the simulated time (s)."""

    def tick(self) -> TickResult:
        """Run one tick; raise Stopped once request_stop was called."""

    def request_stop(self) -> None:
        """Stop the tick under way within a step, from any thread."""


class Ticker:
    """
    Runs ``engine``'s ticks on a worker thread, paced by ``pacer`` (see the module docs).

    done: called after each job, once its ticks can be collected (on the worker thread, or
    on the starting thread when the job was already done; the node triggers a guard
    condition);
    before_tick: called before each tick on the thread that runs it (re-simulation submits
    the recorded inputs of the tick there); clock: the steady wall clock (s).
    """

    def __init__(self, engine: TickEngine, pacer: Pacer, done: Callable[[], None],
                 before_tick: Callable[[], None] | None = None,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        """Start with no job; the first :meth:`start` anchors the pacer."""
        self.engine = engine
        self.pacer = pacer
        self._done = done
        self._before_tick = before_tick
        self._clock = clock
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix='sim_tick')
        self._job: Future[Ticks] | None = None
        self._anchored = False
        #: what the pacer did and the ticks took since the last :meth:`new_window`
        self.window = DiagnosticsWindow(clock(), engine.t)

    @property
    def timer_period(self) -> float:
        """Return the period (s) for the node's tick timer."""
        # as fast as possible, the worker chains its hand-overs; the timer only restarts them
        return self.pacer.period or FAST_TIMER_PERIOD

    @property
    def busy(self) -> bool:
        """Tell whether a job was started and not collected yet."""
        return self._job is not None

    def restart(self) -> None:
        """Re-anchor the pacer at the next start (resume, new real-time factor)."""
        self._anchored = False
        self.new_window()

    def new_window(self) -> None:
        """Start a new diagnostics window now."""
        self.window = DiagnosticsWindow(self._clock(), self.engine.t)

    def start(self, limit: int | None = None) -> bool:
        """
        Hand the ticks that are due (at most ``limit``) to the worker; return whether any.

        Call it from one thread (the executor's) while no job is running.
        """
        begin = self._clock()
        if not self._anchored:  # (re)started: the first tick is due now
            self.pacer.restart(begin - self.pacer.period, self.engine.t)
            self._anchored = True
        due = self.pacer.due(begin, self.engine.t)
        self.window.given_up += due.given_up
        self.window.lag_max = max(self.window.lag_max, due.lag)
        count = due.ticks if limit is None else min(due.ticks, limit)
        if count <= 0:
            return False
        self._job = self._worker.submit(self._work, count, begin + self.pacer.period)
        # once the job's result is set (not from inside the job: a collect() woken before
        # the future is done would leave the job uncollected and the node stalled)
        self._job.add_done_callback(lambda _: self._done())
        return True

    def _work(self, count: int, deadline: float) -> Ticks:
        """Run up to ``count`` ticks, stopping after ``deadline`` (worker thread)."""
        results = []
        for _ in range(count):
            try:
                results.append(self.tick_once())
            except Stopped:  # shutdown: the ticks finished before it are kept
                break
            if self._clock() >= deadline:
                break
        return results

    def tick_once(self) -> tuple[TickResult, float]:
        """Run one tick on this thread; return it with its wall-clock duration (s)."""
        start = self._clock()
        if self._before_tick is not None:
            self._before_tick()
        result = self.engine.tick()
        return result, self._clock() - start

    def collect(self) -> Ticks | None:
        """Return the finished job's ticks (None: no job, or still running)."""
        job = self._job
        if job is None or not job.done():
            return None
        self._job = None
        return job.result()

    def finish(self) -> Ticks:
        """Wait for the running job, if any, and return its ticks (an error is raised here)."""
        job, self._job = self._job, None
        return [] if job is None else job.result()

    def shutdown(self) -> Ticks:
        """
        Stop the running job within a step, stop the worker thread; return the job's ticks.

        The tick under way is dropped (:meth:`TickEngine.request_stop`), however long its
        integration would have taken: a node asked to stop answers at once (``ros2 launch``
        escalates to SIGKILL after 5 s).
        """
        self.engine.request_stop()
        try:
            return self.finish()
        finally:
            self._worker.shutdown(wait=True)
