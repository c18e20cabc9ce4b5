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
One headless run written to files: the events CSV as it goes, the packs CSV, an MCAP file.

:func:`run_to_files` is what ``cone-feeder-sim run`` does once the scenario is loaded, and
what every job of a sweep does, so that a sweep's job and the ``run`` of its scenario file
give the same files, bit for bit.
"""

from collections.abc import Callable, Sequence
import contextlib
from dataclasses import dataclass
from pathlib import Path

from .events_csv import EventsCsvWriter
from .packs_csv import write_packs_csv
from .runlog import ScenarioRecorder
from ..feeder.runner import Progress, run_scenario, RunResult, scenario_weigher
from ..feeder.scenario import Scenario
from ..physics.simulation import Simulator, StepResult
from ..weigher.machine import Weigher


@dataclass(frozen=True)
class RunFiles:
    """What a run wrote: the run's result, the event rows and the packs written (or None)."""

    result: RunResult
    events: int
    packs: int | None


def run_to_files(scenario: Scenario, events: str | Path, *, packs: str | Path | None = None,
                 mcap: str | Path | None = None, source: str = '',
                 progress: Sequence[Progress] = (),
                 stop: Callable[[], bool] | None = None,
                 weigher: Weigher | None = None) -> RunFiles:
    """
    Run a validated scenario, appending its exits to the events CSV as they happen.

    packs: the packs CSV, written at the end (the scenario needs a weigher); mcap: an MCAP
    recording of the run (source: the scenario's file name in its metadata); progress:
    callbacks after every output interval, after the events are written; stop: the
    runner's stop predicate (the files then hold the run so far); weigher: the machine to
    drive when the scenario has one (default: a new one; a progress callback may watch it).
    """
    with contextlib.ExitStack() as outputs:
        weigher = scenario_weigher(scenario, weigher)
        callbacks: list[Progress] = []
        if mcap is not None:
            callbacks.append(outputs.enter_context(contextlib.closing(ScenarioRecorder(
                str(mcap), scenario, source, weigher=weigher))))
        writer = outputs.enter_context(EventsCsvWriter(events))
        callbacks.extend(progress)

        def on_interval(t: float, sim: Simulator, step: StepResult) -> None:
            writer.write(step.exits)
            for callback in callbacks:
                callback(t, sim, step)

        result = run_scenario(scenario, on_interval, stop=stop, weigher=weigher)
    packed = write_packs_csv(packs, result.packs) if packs is not None else None
    return RunFiles(result=result, events=writer.rows, packs=packed)
