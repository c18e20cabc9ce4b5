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
Running a scenario headless: the loop over output intervals, with progress callbacks.

The loop is shared by the command line and the tests. It advances a
:class:`~cone_feeder_sim.physics.simulation.Simulator` interval by interval (output_interval of the
scenario), collects the exit events and failures, and reports every finished interval to the
progress callback (its exits included, so that they can be written as they happen). A stop
predicate, asked before every interval, ends the run early between two intervals.
"""

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .feed import draw_feed
from .scenario import check_output_count, Scenario
from ..physics.simulation import ExitEvents, Failure, SimParams, Simulator, StepResult
from ..physics.stop import StopFlag
from ..weigher.machine import Pack, Weigher


@dataclass
class RunResult:
    """
    Everything a run produced: exits (one row per piece that left), failures, stats.

    end_time (s) is the simulation time the run reached; stopped is True when the stop
    predicate ended it before the scenario's end. With a weigher in the scenario, packs
    are the packs it made (the run goes on to the scenario's duration, also after the last
    piece left the cone) and weigher is the machine at the end (balance, statistics).
    pieces: how many pieces were placed on the cone (the scenario's and the feed's).
    """

    exits: list[ExitEvents] = field(default_factory=list)
    failures: list[Failure] = field(default_factory=list)
    accepted_steps: int = 0
    rejected_steps: int = 0
    remaining_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    end_time: float = 0.0
    stopped: bool = False
    packs: list[Pack] = field(default_factory=list)
    weigher: Weigher | None = None
    pieces: int = 0

    def exit_table(self) -> dict[str, np.ndarray]:
        """Return all exits as columns (ids, t, angle_deg, channel, position, velocity, mass)."""
        names = ('ids', 't', 'angle_deg', 'channel', 'position', 'velocity', 'mass')
        if not self.exits:
            return {n: getattr(ExitEvents.none(), n) for n in names}
        return {n: np.concatenate([getattr(e, n) for e in self.exits]) for n in names}


Progress = Callable[[float, Simulator, StepResult], None]


def start_simulator(scenario: Scenario, stop: StopFlag | None = None) -> Simulator:
    """Return a simulator at t = 0 with the scenario's pieces on the cone (ids 0 .. P - 1)."""
    sim = Simulator(SimParams(model=scenario.model, solver=scenario.solver), scenario.rotation,
                    stop=stop)
    for spec in scenario.particles:
        sim.add([spec.position], None if spec.velocity is None else [spec.velocity],
                [spec.product])
    return sim


def scenario_weigher(scenario: Scenario, weigher: Weigher | None = None) -> Weigher | None:
    """Return the machine a run drives: None without a weigher section, else weigher or new."""
    if scenario.weigher is None:
        return None
    return weigher if weigher is not None else Weigher(scenario.weigher,
                                                       scenario.model.channels.count)


def run_scenario(scenario: Scenario, progress: Progress | None = None, *,
                 stop: Callable[[], bool] | None = None,
                 weigher: Weigher | None = None) -> RunResult:
    """
    Run a validated scenario to its end, or until stop() says so.

    Without a weigher and without a feed the run also ends when every piece has left the
    cone. With a feed, the pieces that arrive during an interval (Poisson(rate * interval),
    :func:`~cone_feeder_sim.feeder.feed.draw_feed`) are dropped at its start; their ids
    continue after the scenario's pieces.

    Particle ids are the 0-based indices of the pieces in the scenario. progress, if given,
    is called after every output interval with the simulated time at its end, the simulator
    and the interval's StepResult (its exits and failures). stop, if given, is asked before
    every interval; when it returns True the run ends there (result.stopped). A stop that is
    a :class:`~cone_feeder_sim.physics.stop.StopFlag` is also read inside the interval, by
    the kernels between two steps: once set, the interval under way is dropped and the run
    ends at the one before (the exits reported are those of the finished intervals).
    weigher: the machine to drive when the scenario has one (default: a new one), so that
    a progress callback can record it as it goes. Raises
    ScenarioError before anything runs when the scenario asks for more than MAX_OUTPUTS
    output intervals.
    """
    check_output_count(scenario.duration, scenario.output_interval)
    sim = start_simulator(scenario, stop if isinstance(stop, StopFlag) else None)
    feed = scenario.feed if scenario.feed is not None and scenario.feed.rate > 0.0 else None
    rng = np.random.default_rng(scenario.feed_seed)
    result = RunResult(pieces=len(scenario.particles))
    weigher = scenario_weigher(scenario, weigher)
    k = 0
    while sim.t < scenario.duration and (sim.state.count or weigher is not None
                                         or feed is not None):
        if stop is not None and stop():
            result.stopped = True
            break
        k += 1
        t1 = min(scenario.duration, k * scenario.output_interval)
        if feed is not None:
            drop = draw_feed(rng, feed, scenario.model, t1 - sim.t,
                             feed.max_pieces - sim.state.count)
            if drop is not None:
                sim.add(drop.positions, np.zeros_like(drop.positions), drop.products)
                result.pieces += len(drop.products)
        step = sim.advance_to(t1)
        if step.stopped:
            result.stopped = True
            break
        result.accepted_steps += step.stats.accepted
        result.rejected_steps += step.stats.rejected
        if len(step.exits):
            result.exits.append(step.exits)
        if weigher is not None:
            weigher.receive(step.exits.channel, step.exits.mass, step.exits.t)
            result.packs.extend(weigher.advance(t1))
        result.failures.extend(step.failures)
        if progress is not None:
            progress(t1, sim, step)
    result.remaining_ids = sim.state.ids.copy()
    result.end_time = sim.t
    result.weigher = weigher
    return result
