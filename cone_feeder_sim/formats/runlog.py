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
Run logs: what a recording of the simulator holds besides the messages, and its writers.

A run log is one MCAP file in the ROS 2 layout written by
:class:`~cone_feeder_sim.formats.mcap_writer.McapRecorder` (schemas ``ros2msg``, messages ``cdr``,
``offered_qos_profiles``, log time = simulation time in ns). This module adds

* the metadata record :data:`METADATA_NAME` (``cone_feeder_sim``): every parameter as a
  string (``model.cone_diameter``, ``feed.seed``, ...), the package version, the seed and
  what re-simulation needs (``parameters_json`` with typed values, ``engine_config``,
  ``topics``); and :data:`END_METADATA_NAME` written when the file is closed;
* the **events** of a run: one JSON object per ``std_msgs/String`` message on the node's
  ``~/events`` topic. Inputs the engine applied (``rotation``, ``spawn``, ``reset``,
  ``reconfigure``) carry the index of the tick that applied them and everything needed to
  apply them again (:func:`input_event`, :func:`engine_input_from_event`); ``parameters``,
  ``pause``, ``resume`` and ``step`` record what happened at the node;
* the node's recorder is :class:`~cone_feeder_sim.formats.run_recorder.RunRecorder` (a
  writer thread, split files, a free-space guard);
* :class:`ScenarioRecorder`: the headless runner's recorder (same topics and schemas).
"""

from collections.abc import Iterable, Mapping
import dataclasses
import datetime
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .mcap_writer import McapRecorder
from .messages import stamp_ns, TickMessages, TickView
from .run_recorder import END_METADATA_NAME, make_parent_dir
from .topics import RUNNER_TOPICS, TOPICS
from .. import __version__
from ..errors import ConeFeederError
from ..feeder.engine import (
    ChannelFeed, DriveParams, EngineConfig, EngineInput, FeedParams, Reconfigure, ResetRequest,
    RotationCommand, SpawnRequest)
from ..feeder.scenario import Scenario
from ..physics.params import (
    CHANNEL_KEYS, INTERACTION_KEYS, MODEL_KEYS, ModelParams, P_M, PRODUCT_LIMITS,
    ProductParams, SolverParams)
from ..physics.simulation import Failure, Simulator, StepResult
from ..weigher.machine import Pack, Weigher

__all__ = [
    'DEFAULT_RECORD_PATH',
    'END_METADATA_NAME',
    'FORMAT_VERSION',
    'INPUT_EVENTS',
    'failure_event',
    'METADATA_NAME',
    'ScenarioRecorder',
    'engine_config_json',
    'engine_input_from_event',
    'event_text',
    'expand_record_path',
    'input_event',
    'interaction_values',
    'model_parameter_values',
    'parameter_text',
    'run_metadata',
]

#: Name of the metadata record that describes a run.
METADATA_NAME = 'cone_feeder_sim'
#: Version of the layout described here (metadata key ``format``).
FORMAT_VERSION = '1'
#: Default of the node's ``record_path``: strftime fields are filled in at the start.
DEFAULT_RECORD_PATH = 'runs/sim_node_%Y%m%dT%H%M%S.mcap'
#: Events that are engine inputs (re-simulation applies them again).
INPUT_EVENTS = ('rotation', 'spawn', 'reset', 'reconfigure', 'channel_feed')


# --------------------------------------------------------------------------- metadata


def parameter_text(value: Any) -> str:
    """
    Return a parameter value as the metadata string.

    Strings as they are, booleans ``true``/``false``, integers in decimal, floats as
    Python's shortest round-trip repr (``0.45``), arrays as JSON lists, unset ``[]``.
    """
    if value is None:
        return '[]'
    if isinstance(value, str):
        return value
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    return json.dumps(to_jsonable(list(value)))


def to_jsonable(value: Any) -> Any:
    """Return value with dataclasses, tuples and numpy values turned into JSON types."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, (str, type(None))):
        return value
    return [to_jsonable(v) for v in value]


def model_parameter_values(model: ModelParams) -> dict[str, Any]:
    """Return the ``model.<key>`` parameter values of a model (keys of table2.yaml)."""
    values: dict[str, Any] = {}
    for key in PRODUCT_LIMITS:
        values[f'model.{key}'] = float(getattr(model.product, key))
    for key in MODEL_KEYS:
        value = getattr(model, key)
        values[f'model.{key}'] = value if isinstance(value, str) else float(value)
    for key, attribute in CHANNEL_KEYS.items():
        value = getattr(model.channels, attribute)
        values[f'model.{key}'] = (int(value) if key == 'channel_count' else
                                  float(value) if key == 'channel_boundary' else value)
    return values


def interaction_values(model: ModelParams) -> dict[str, Any]:
    """Return the ``interactions.<key>`` values (contact between pieces), as the node's."""
    return {f'interactions.{key}': getattr(model.interactions, key)
            for key in INTERACTION_KEYS}


def solver_parameter_values(solver: SolverParams) -> dict[str, Any]:
    """Return the ``solver.<key>`` values of the integrator settings."""
    return {f'solver.{f.name}': getattr(solver, f.name) for f in dataclasses.fields(solver)}


def engine_config_json(config: EngineConfig) -> str:
    """Return the whole engine configuration as JSON (floats round-trip exactly)."""
    return json.dumps(to_jsonable(config), sort_keys=True)


def expand_record_path(template: str, now: datetime.datetime | None = None) -> Path:
    """
    Return the recording path for a ``record_path`` value.

    strftime fields (``%Y%m%dT%H%M%S``) are filled in with the local time; when the template
    has such fields and the file exists already, ``-2``, ``-3``... is appended to the stem
    so that runs started in the same second do not collide (``_2`` would name the second
    file of a split run). An explicit name is kept as it is: the recorder refuses to
    overwrite an existing file.
    """
    now = now if now is not None else datetime.datetime.now()
    path = Path(now.strftime(template)) if '%' in template else Path(template)
    if '%' in template:
        stem, suffix, n = path.stem, path.suffix, 2
        while path.exists():
            path = path.with_name(f'{stem}-{n}{suffix}')
            n += 1
    return path


# --------------------------------------------------------------------------- events


def input_event(tick: int, t: float, item: EngineInput) -> dict[str, Any]:
    """Return the event of an engine input applied at the start of tick ``tick`` (time t)."""
    event: dict[str, Any] = {'tick': int(tick), 't': float(t)}
    if isinstance(item, RotationCommand):
        event.update(event='rotation', omega=float(item.omega))
    elif isinstance(item, SpawnRequest):
        event.update(event='spawn', positions=to_jsonable(item.positions),
                     velocities=to_jsonable(item.velocities),
                     products=to_jsonable(item.products))
    elif isinstance(item, ResetRequest):
        event.update(event='reset')
    elif isinstance(item, Reconfigure):
        event.update(event='reconfigure', drive=to_jsonable(item.drive),
                     feed=to_jsonable(item.feed))
    elif isinstance(item, ChannelFeed):
        event.update(event='channel_feed', amplitude=list(item.amplitude))
    else:
        raise ConeFeederError(f'unknown engine input {item!r}')
    return event


def failure_event(tick: int, failure: Failure) -> dict[str, Any]:
    """
    Return the event of a piece removed by a failed integration during tick ``tick``.

    Non-finite coordinates (a state that blew up) are written as null.
    """
    def finite(values: Iterable[float]) -> list[float | None]:
        return [float(v) if math.isfinite(v) else None for v in values]

    return {'event': 'failure', 'tick': int(tick), 't': float(failure.t),
            'id': int(failure.particle_id), 'reason': failure.reason,
            'position': finite(failure.position), 'velocity': finite(failure.velocity),
            'mass': float(failure.mass)}


def event_text(event: Mapping[str, Any]) -> str:
    """Return the JSON text of an event (the data of a ``~/events`` message)."""
    return json.dumps(to_jsonable(event), separators=(',', ':'), allow_nan=False)


def engine_input_from_event(event: Mapping[str, Any]) -> EngineInput:
    """Return the engine input an input event describes (inverse of :func:`input_event`)."""
    kind = event.get('event')
    try:
        if kind == 'rotation':
            return RotationCommand(float(event['omega']))
        if kind == 'spawn':
            velocities = event.get('velocities')
            products = event.get('products')
            return SpawnRequest(
                np.array(event['positions'], dtype=np.float64).reshape(-1, 3),
                None if velocities is None else np.array(velocities, dtype=np.float64
                                                         ).reshape(-1, 3),
                None if products is None else tuple(ProductParams(**p) for p in products))
        if kind == 'reset':
            return ResetRequest()
        if kind == 'channel_feed':
            return ChannelFeed(tuple(float(v) for v in event['amplitude']))
        if kind == 'reconfigure':
            drive = event.get('drive')
            feed = event.get('feed')
            if drive is not None:
                drive = DriveParams(**{**drive, 'pattern': tuple(
                    tuple(segment) for segment in drive['pattern'])})
            if feed is not None:
                feed = FeedParams(**{**feed, 'd_values': tuple(feed['d_values'])})
            return Reconfigure(drive=drive, feed=feed)
    except (KeyError, TypeError, ValueError) as exc:
        raise ConeFeederError(f'malformed {kind} event {dict(event)!r}: {exc!r}') from exc
    raise ConeFeederError(f'event {kind!r} is not an engine input')


# --------------------------------------------------------------------------- the runner's recorder


def run_metadata(values: Mapping[str, Any], source: str, topics: Mapping[str, str],
                 input_topics: Iterable[str], **fields: str) -> dict[str, str]:
    """
    Return the ``cone_feeder_sim`` metadata of a run: the one layout of node and runner.

    values: the run's parameters by name (each also a key of its own, as
    :func:`parameter_text`, and all of them in ``parameters_json``); source: what made the
    run (``sim_node``, ``cone-feeder-sim run``); topics: table name -> recorded topic;
    input_topics: the recorded topics that were inputs of the run; fields: further keys
    (the node's engine configuration, the runner's scenario), written last.
    """
    data = {name: parameter_text(value) for name, value in values.items()}
    data.update({
        'format': FORMAT_VERSION,
        'version': __version__,
        'source': source,
        'parameters_json': json.dumps(to_jsonable(dict(values))),
        'topics': json.dumps(dict(topics)),
        'input_topics': json.dumps(sorted(input_topics)),
        'created': datetime.datetime.now().astimezone().isoformat(timespec='seconds'),
    })
    data.update(fields)
    return data


def scenario_metadata(scenario: Scenario, source: str, topics: Mapping[str, str],
                      markers_rate: float, frame_id: str) -> dict[str, str]:
    """Return the ``cone_feeder_sim`` metadata of a headless run."""
    values: dict[str, Any] = dict(model_parameter_values(scenario.model))
    values.update(solver_parameter_values(scenario.solver))
    values.update(interaction_values(scenario.model))
    values['weigher.enabled'] = scenario.weigher is not None
    values['feed.enabled'] = scenario.feed is not None
    if scenario.feed is not None:
        values.update({f'feed.{f.name}': getattr(scenario.feed, f.name)
                       for f in dataclasses.fields(scenario.feed)})
        values['feed.seed'] = scenario.feed_seed
    if scenario.weigher is not None:
        values.update({f'weigher.{f.name}': getattr(scenario.weigher, f.name)
                       for f in dataclasses.fields(scenario.weigher)})
    values.update({'frame_id': frame_id, 'markers.rate': markers_rate,
                   'duration': scenario.duration, 'output_interval': scenario.output_interval})
    return run_metadata(
        values, 'cone-feeder-sim run', topics, (), scenario=source,
        rotation=json.dumps([[float(t), float(w)] for t, w in zip(
            scenario.rotation.times, scenario.rotation.omegas)]),
        particles=json.dumps(to_jsonable(scenario.particles)),
        seed=str(scenario.feed_seed) if scenario.feed is not None else '')


class ScenarioRecorder:
    """
    The headless runner's MCAP output: the node's topics, written after every interval.

    Use it as the runner's progress callback. Topics (absolute, as a node in the root
    namespace publishes them): particles, particle_states, exit_events (intervals with
    exits only), channel_mass (cumulative), cone_state and markers (``markers_rate`` per
    simulated second); with ``weigher`` (the machine the runner drives), hopper_weights and
    pack_events (intervals with packs only) too. Log time and stamps = simulation time at
    the end of the interval.
    """

    def __init__(self, path: str | os.PathLike, scenario: Scenario, source: str = '', *,
                 frame_id: str = 'feeder', markers_rate: float = 10.0,
                 weigher: Weigher | None = None) -> None:
        """Create the file and write schemas, channels and the metadata."""
        names = RUNNER_TOPICS + (('hopper_weights', 'pack_events') if weigher else ())
        self._names = {name: '/' + name for name in names}
        self._weigher = weigher
        self._packs_written = 0
        path = Path(path)
        make_parent_dir(path)
        self._recorder = McapRecorder(path)
        try:
            for name, topic in self._names.items():
                spec = TOPICS[name]
                self._recorder.add_topic(topic, spec.type_name, spec.qos)
            self._recorder.add_metadata(METADATA_NAME, scenario_metadata(
                scenario, source, self._names, markers_rate, frame_id))
        except BaseException:
            self._recorder.close()
            raise
        self._messages = TickMessages(scenario.model, frame_id, markers_rate)
        self._channel_mass = np.zeros(scenario.model.channels.count)
        self._intervals = 0
        self._exits = 0
        self._t = 0.0

    @property
    def path(self) -> Path:
        """Return the path of the file."""
        return self._recorder.path

    def _write(self, name: str, message: dict[str, Any], log_time: int) -> None:
        self._recorder.write(self._names[name], TOPICS[name].type_name, message, log_time)

    def __call__(self, t: float, sim: Simulator, step: StepResult) -> None:
        """Write the messages of the interval that ended at t (s), as the node orders them."""
        q, qdot, _ = sim.world()
        state = sim.state
        exits = step.exits
        if len(exits):
            np.add.at(self._channel_mass, exits.channel - 1, exits.mass)
            self._exits += len(exits)
        packs: tuple[Pack, ...] = ()
        hoppers = None
        if self._weigher is not None:
            hoppers = self._weigher.hopper_readings()
            packs = tuple(self._weigher.packs[self._packs_written:])
            self._packs_written += len(packs)
        interval = TickView(t, state.ids, q, qdot, state.products[:, P_M], exits,
                            self._channel_mass.copy(), state.angle, sim.omega(), hoppers, packs)
        t_ns = stamp_ns(t)
        for name, message in self._messages(interval):
            self._write(name, message, t_ns)
        self._intervals += 1
        self._t = t

    def close(self) -> None:
        """Write the end metadata, summary and footer; idempotent."""
        if self._recorder.closed:
            return
        try:
            self._recorder.add_metadata(END_METADATA_NAME, {
                'intervals': str(self._intervals), 'exits': str(self._exits),
                'end_time': repr(float(self._t)),
                'messages': str(self._recorder.message_count)})
        finally:
            self._recorder.close()
