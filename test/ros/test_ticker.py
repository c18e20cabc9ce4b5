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

"""The ticker on a fake engine and a made-up wall clock: no ROS, no physics."""

from collections.abc import Iterator
import concurrent.futures
import contextlib
import threading
from typing import Any

from cone_feeder_sim.errors import Stopped
from cone_feeder_sim.ros.pacing import Pacer
from cone_feeder_sim.ros.ticker import FAST_TIMER_PERIOD, Ticker
import pytest

DT = 0.02


class FakeClock:
    """A wall clock that moves only when told (s)."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


class FakeEngine:
    """Ticks of DT that cost ``cost`` seconds of the fake clock each; may fail at a tick."""

    def __init__(self, clock: FakeClock, cost: float = 0.0, fail_at: int = -1,
                 block_at: int = -1) -> None:
        self.clock = clock
        self.cost = cost
        self.fail_at = fail_at
        self.block_at = block_at  # this tick waits until request_stop, then is dropped
        self.blocked = threading.Event()
        self.stop = threading.Event()
        self.tick_index = 0
        self.threads: set[str] = set()

    def request_stop(self) -> None:
        self.stop.set()

    @property
    def t(self) -> float:
        return self.tick_index * DT

    def tick(self) -> Any:
        if self.tick_index == self.fail_at:
            raise RuntimeError('the tick failed')
        if self.stop.is_set():
            raise Stopped('stopped')
        if self.tick_index == self.block_at:  # a tick that would compute for ever
            self.blocked.set()
            self.stop.wait()
            raise Stopped('stopped')
        self.threads.add(threading.current_thread().name)
        self.clock.now += self.cost
        self.tick_index += 1
        return self.tick_index - 1


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


@contextlib.contextmanager
def ticking(engine: FakeEngine, rtf: float = 1.0,
            catch_up: float = 0.5) -> Iterator[tuple[Ticker, dict[str, int]]]:
    """Yield a ticker and the counts of its done() and before_tick() calls; shut it down."""
    calls = {'done': 0, 'before': 0}

    def done() -> None:
        calls['done'] += 1

    def before() -> None:
        calls['before'] += 1

    ticker = Ticker(engine, Pacer(DT, rtf, catch_up), done, before, engine.clock)
    try:
        yield ticker, calls
    finally:
        ticker.shutdown()


def anchored(ticker: Ticker) -> Ticker:
    """Run the first tick (it anchors the pacer); return the ticker."""
    ticker.start()
    ticker.finish()
    return ticker


@pytest.fixture
def ticker(clock: FakeClock) -> Iterator[tuple[Ticker, Any, FakeEngine]]:
    engine = FakeEngine(clock)
    with ticking(engine) as (ticker, calls):
        yield ticker, calls, engine


def test_the_first_start_runs_one_tick_on_the_worker(ticker: Any) -> None:
    tick, calls, engine = ticker
    assert tick.collect() is None and not tick.busy
    assert tick.start()
    assert tick.busy
    results = tick.finish()
    assert [r for r, _ in results] == [0] and all(s == 0.0 for _, s in results)
    assert calls == {'done': 1, 'before': 1}
    assert engine.threads and all(name.startswith('sim_tick') for name in engine.threads)
    assert not tick.start()  # the next tick is not due before its period has passed


def test_the_ticks_due_run_in_one_job_and_are_collected(ticker: Any) -> None:
    tick, calls, engine = ticker
    anchored(tick)
    engine.clock.now += 5 * DT  # five periods later: five ticks are due
    assert tick.start()
    while (results := tick.collect()) is None:
        pass
    assert [r for r, _ in results] == [1, 2, 3, 4, 5]
    assert calls['done'] == 2 and not tick.busy


def test_a_job_stops_after_one_period_of_work(clock: FakeClock) -> None:
    with ticking(FakeEngine(clock, cost=0.75 * DT)) as (tick, _):
        anchored(tick)
        clock.now += 10 * DT
        tick.start()
        results = tick.finish()
        # ticks of 0.75 periods: the second ends past the job's deadline of one period
        assert len(results) == 2
        assert all(seconds == pytest.approx(0.75 * DT) for _, seconds in results)


def test_shutdown_stops_the_tick_under_way_and_keeps_the_ticks_before(
        clock: FakeClock) -> None:
    engine = FakeEngine(clock, block_at=3)
    with ticking(engine) as (tick, calls):
        anchored(tick)
        clock.now += 10 * DT
        assert tick.start()
        assert engine.blocked.wait(60.0)  # the job is inside its third tick (index 3)
        with concurrent.futures.ThreadPoolExecutor(1) as pool:
            shutdown = pool.submit(tick.shutdown)  # asks the engine to stop: tick dropped
            try:
                results = shutdown.result(60.0)
            finally:
                engine.stop.set()  # never leave the worker blocked, even when this failed
        assert [r for r, _ in results] == [1, 2]
        assert calls['done'] == 2


def test_a_limit_caps_the_ticks_of_a_job(ticker: Any) -> None:
    tick, _, engine = ticker
    anchored(tick)
    engine.clock.now += 10 * DT
    tick.start(limit=3)
    assert len(tick.finish()) == 3
    assert not tick.start(limit=0)


def test_lag_beyond_catch_up_is_given_up_and_shown_in_the_window(clock: FakeClock) -> None:
    with ticking(FakeEngine(clock), catch_up=0.1) as (tick, _):
        anchored(tick)
        clock.now += 1.0
        tick.start()
        assert len(tick.finish()) == round(0.1 / DT)  # catch_up worth of ticks, no more
        assert tick.window.given_up == pytest.approx(1.0 - 0.1, abs=DT)
        assert tick.window.lag_max == pytest.approx(0.1)
        tick.new_window()
        assert tick.window.given_up == 0.0


def test_as_fast_as_possible_one_tick_a_job_and_the_fast_timer(clock: FakeClock) -> None:
    with ticking(FakeEngine(clock), rtf=0.0) as (tick, _):
        assert tick.timer_period == FAST_TIMER_PERIOD
        for k in range(3):
            assert tick.start()
            assert [r for r, _ in tick.finish()] == [k]
    with ticking(FakeEngine(clock), rtf=2.0) as (paced, _):
        assert paced.timer_period == pytest.approx(DT / 2.0)


def test_restart_anchors_the_pacer_again(ticker: Any) -> None:
    tick, _, engine = ticker
    anchored(tick)
    engine.clock.now += 0.4  # paused for 0.4 s: resuming does not make it up
    tick.restart()
    tick.start()
    assert len(tick.finish()) == 1


def test_a_failed_tick_is_raised_by_finish_and_done_is_still_called(clock: FakeClock) -> None:
    with ticking(FakeEngine(clock, fail_at=0)) as (tick, calls):
        tick.start()
        with pytest.raises(RuntimeError, match='the tick failed'):
            tick.finish()
        assert calls['done'] == 1 and not tick.busy
    assert tick.finish() == []  # nothing running after the shutdown


def test_done_is_called_when_the_ticks_can_be_collected(clock: FakeClock) -> None:
    # the node collects when woken: a wake-up before the job's result is set would leave
    # the job uncollected, and the node would never start another
    engine = FakeEngine(clock)
    seen: list[Any] = []
    woken = threading.Event()
    tick: Ticker

    def done() -> None:
        seen.append(tick.collect())
        woken.set()

    tick = Ticker(engine, Pacer(DT, 1.0, 0.5), done, clock=clock)
    try:
        for _ in range(20):
            woken.clear()
            clock.now += DT
            assert tick.start()
            assert woken.wait(10.0)
        assert all(results is not None and len(results) >= 1 for results in seen)
        assert not tick.busy
    finally:
        tick.shutdown()
