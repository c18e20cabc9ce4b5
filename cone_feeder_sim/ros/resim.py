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
Re-simulation of a ``sim_node`` recording: its parameters and the inputs applied at each tick.

``sim_node -p replay_commands:=RUN.mcap`` declares the recorded parameters and submits the
recorded inputs at the same ticks, which reproduces the run exactly.
"""

from dataclasses import dataclass
import json
from pathlib import Path
from typing import Any

from ..errors import RecordingError
from ..feeder.engine import FeederEngine
from ..formats.cdr import CdrError, default_codec
from ..formats.mcap_reader import (
    open_recording, parse_run_source, RecordedMessage, RunSource)
from ..formats.runlog import (
    END_METADATA_NAME, engine_input_from_event, FORMAT_VERSION, INPUT_EVENTS, METADATA_NAME)
from ..physics.params import InteractionParams

__all__ = ['load_resim_plan', 'recorded_parameter', 'ResimPlan', 'Resimulation']


@dataclass(frozen=True)
class ResimPlan:
    """
    What re-simulating a sim_node recording needs.

    parameters: the recorded parameter values (typed); engine_config: the recorded JSON of
    the engine configuration (for a consistency check); events: recorded ``~/events``
    by tick index, in order; ticks: the number of ticks the recorded run made (re-simulation
    stops there); problem: why the recording is incomplete (None if complete).
    """

    path: Path
    parameters: dict[str, Any]
    engine_config: str
    events: dict[int, list[dict[str, Any]]]
    ticks: int
    problem: str | None


def load_resim_plan(source: RunSource) -> ResimPlan:
    """
    Read a sim_node recording for re-simulation; raise RecordingError if it cannot be.

    ``source``: the first file of the run (its split parts come along), a directory, a list
    of files, or a text of comma-separated files.
    """
    if isinstance(source, str):
        source = parse_run_source(source)
    recording = open_recording(source)
    meta = recording.metadata.get(METADATA_NAME)
    where = str(recording.path)
    if meta is None or 'parameters_json' not in meta:
        raise RecordingError(f'{where!r} has no {METADATA_NAME!r} metadata with parameters: '
                             'not a recording of sim_node')
    if meta.get('source') != 'sim_node':
        raise RecordingError(f'{where!r} was written by {meta.get("source")!r}, not sim_node: '
                             'only sim_node recordings can be re-simulated')
    if meta.get('format') != FORMAT_VERSION:
        raise RecordingError(f'{where!r} has format {meta.get("format")!r}; this version '
                             f'reads format {FORMAT_VERSION}')
    try:
        parameters = json.loads(meta['parameters_json'])
        topics = json.loads(meta['topics'])
        dt_ns = 1e9 / float(parameters['update_rate'])
    except (KeyError, TypeError, ValueError) as err:
        raise RecordingError(f'{where!r}: unreadable {METADATA_NAME} metadata: {err!r}') from err
    if made_with_the_stiff_pair_law(parameters):
        raise RecordingError(
            f'{where!r} was recorded with contact between pieces under the pair law before '
            'soft contact (no interactions.restitution): this version cannot re-simulate it '
            'exactly; replay_node still plays it back (doc/model.md, "Why the pair law '
            'changed")')
    events_topic = topics.get('~/events')
    states_topic = topics.get('particle_states')
    end = recording.metadata.get(END_METADATA_NAME, {})
    ticks = None
    if 'ticks' in end:
        ticks = int(end['ticks'])
    events: dict[int, list[dict[str, Any]]] = {}
    last_state = None
    wanted = {events_topic} if ticks is not None else {events_topic, states_topic}
    for message in recording.messages({t for t in wanted if t}):
        if message.topic == states_topic:
            last_state = message.log_time_ns
            continue
        event = _event(message, where)
        events.setdefault(int(event['tick']), []).append(event)
    if ticks is None:
        ticks = 0 if last_state is None else int(round(last_state / dt_ns))
    events = {k: v for k, v in events.items() if k < ticks}
    return ResimPlan(recording.path, parameters, meta.get('engine_config', ''), events, ticks,
                     recording.problem)


class Resimulation:
    """
    A re-simulation under way: the plan, whether it still runs, what each tick gets.

    It runs from the node's start until the recorded number of ticks is done
    (:meth:`finish`); meanwhile live inputs are refused and the recorded ones submitted.
    """

    def __init__(self, plan: ResimPlan) -> None:
        """Start re-simulating ``plan``."""
        self.plan = plan
        self.active = True

    def notes(self, engine_config: str) -> list[tuple[str, str]]:
        """Return the log lines (level, text) of the start, given the engine's config JSON."""
        plan = self.plan
        notes = []
        if plan.engine_config and plan.engine_config != engine_config:
            notes.append(('warning', f'the engine configuration built from the parameters of '
                          f'{plan.path} differs from the recorded one (recorded by another '
                          'version?): the re-simulation may differ'))
        if plan.problem:
            notes.append(('warning', f'{plan.path} is incomplete ({plan.problem}): '
                          f're-simulating its {plan.ticks} readable ticks'))
        count = sum(len(v) for v in plan.events.values())
        notes.append(('info', f're-simulating {plan.path}: {plan.ticks} ticks, {count} recorded '
                      'events; parameters, initial pieces and inputs come from the recording'))
        return notes

    def remaining(self, tick_index: int) -> int:
        """Return how many recorded ticks are left after ``tick_index`` ticks."""
        return self.plan.ticks - tick_index

    def due_to_end(self, tick_index: int) -> bool:
        """Tell whether it still runs though ``tick_index`` ticks made every recorded one."""
        return self.active and tick_index >= self.plan.ticks

    def submit_inputs(self, engine: FeederEngine) -> None:
        """Submit the recorded inputs of the engine's next tick (on the ticking thread)."""
        if self.active:
            for event in self.plan.events.get(engine.tick_index, ()):
                if event.get('event') in INPUT_EVENTS:
                    engine.submit(engine_input_from_event(event))

    def marker_rates(self, index: int) -> list[tuple[int, float]]:
        """Return the recorded marker rate changes of tick ``index`` as (index, rate)."""
        return [(index, float(event['values']['markers.rate']))
                for event in self.plan.events.get(index, ())
                if event.get('event') == 'parameters'
                and 'markers.rate' in event.get('values', {})]

    def finish(self, t: float) -> str:
        """End the re-simulation at simulation time t (s); return the log line."""
        self.active = False
        return (f're-simulation of {self.plan.path} done after {self.plan.ticks} ticks (t = '
                f'{t:.6f} s); paused: resume with ~/pause false to go on live')


#: Parameters that recordings made before they existed lack, with the value those runs had:
#: they were coupled exactly.
BEFORE_THEY_EXISTED: dict[str, Any] = {
    'interactions.coupling': 'exact',
    'interactions.coupling_tolerance': InteractionParams().coupling_tolerance}


def made_with_the_stiff_pair_law(parameters: dict[str, Any]) -> bool:
    """Return whether recorded node parameters had contact on under the old pair law."""
    return (bool(parameters.get('interactions.enabled'))
            and 'interactions.restitution' not in parameters)


def recorded_parameter(plan: ResimPlan, name: str) -> tuple[bool, Any]:
    """Return (found, value) of parameter ``name`` in a recording, old recordings included."""
    if name in plan.parameters:
        return True, plan.parameters[name]
    if name in BEFORE_THEY_EXISTED:
        return True, BEFORE_THEY_EXISTED[name]
    return False, None


def _event(message: RecordedMessage, where: str) -> dict[str, Any]:
    try:
        text = default_codec().decode('std_msgs/msg/String', message.data)['data']
        event = json.loads(text)
        if not isinstance(event, dict) or not isinstance(event.get('tick'), int):
            raise ValueError('not an event object with a tick')
    except (CdrError, ValueError) as err:
        raise RecordingError(f'{where!r}: unreadable event at log time '
                             f'{message.log_time_ns} ns: {err!r}') from err
    return event
