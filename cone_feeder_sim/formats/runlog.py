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
* :class:`RunRecorder`: the node's recorder. Messages are queued by the node's thread and
  written by a background thread (chunks compressed off the timer's path), flushed at least
  every :data:`FLUSH_INTERVAL_S` of wall-clock time;
* :class:`ScenarioRecorder`: the headless runner's recorder (same topics and schemas).
"""

from collections.abc import Iterable, Mapping
import dataclasses
import datetime
import json
import math
import os
from pathlib import Path
import queue
import threading
import time
from typing import Any

import numpy as np

from .mcap_writer import DEFAULT_CHUNK_SIZE, McapRecorder
from .messages import (
    channel_mass_message, cone_state_message, exits_message, header, MarkerBuilder, MarkerSchedule,
    particles_message, stamp_ns, states_message)
from .topics import MessageRecord, QosProfile, RUNNER_TOPICS, TOPICS
from .. import __version__
from ..errors import ConeFeederError, RecordingError
from ..feeder.engine import (
    DriveParams, EngineConfig, EngineInput, FeedParams, Reconfigure, ResetRequest, RotationCommand,
    SpawnRequest)
from ..feeder.scenario import Scenario
from ..physics.params import (
    CHANNEL_KEYS, MODEL_KEYS, ModelParams, P_M, PRODUCT_LIMITS, ProductParams, SolverParams)
from ..physics.simulation import Failure, Simulator, StepResult

__all__ = [
    'DEFAULT_RECORD_PATH',
    'END_METADATA_NAME',
    'FORMAT_VERSION',
    'INPUT_EVENTS',
    'failure_event',
    'METADATA_NAME',
    'RunRecorder',
    'ScenarioRecorder',
    'engine_config_json',
    'engine_input_from_event',
    'event_text',
    'expand_record_path',
    'input_event',
    'model_parameter_values',
    'parameter_text',
]

#: Name of the metadata record that describes a run.
METADATA_NAME = 'cone_feeder_sim'
#: Name of the metadata record written when a recording is closed (absent after a crash).
END_METADATA_NAME = 'cone_feeder_sim.end'
#: Version of the layout described here (metadata key ``format``).
FORMAT_VERSION = '1'
#: Default of the node's ``record_path``: strftime fields are filled in at the start.
DEFAULT_RECORD_PATH = 'runs/sim_node_%Y%m%dT%H%M%S.mcap'
#: Events that are engine inputs (re-simulation applies them again).
INPUT_EVENTS = ('rotation', 'spawn', 'reset', 'reconfigure')
#: Wall-clock seconds after which written data are in a finished chunk handed to the OS.
FLUSH_INTERVAL_S = 0.5
#: How often (wall-clock s) the writer thread wakes up when nothing arrives.
_POLL_S = 0.1
#: Token that only wakes the writer thread.
_WAKE = object()
#: Queued bytes beyond which the node waits for the writer (nothing is dropped).
MAX_BACKLOG_BYTES = 256 * 1024 * 1024


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
    has such fields and the file exists already, ``_2``, ``_3``... is appended to the stem
    so that runs started in the same second do not overwrite each other.
    """
    now = now if now is not None else datetime.datetime.now()
    path = Path(now.strftime(template)) if '%' in template else Path(template)
    if '%' in template:
        stem, suffix, n = path.stem, path.suffix, 2
        while path.exists():
            path = path.with_name(f'{stem}_{n}{suffix}')
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


# --------------------------------------------------------------------------- the node's recorder


def _make_parent(path: Path) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise RecordingError(
            f'cannot create the directory {str(path.parent)!r} for the recording {str(path)!r}: '
            f'{err.strerror or err}') from err


class RunRecorder:
    """
    The MCAP recorder of a live node: cheap to call from the timer, written by a thread.

    ``topics``: (resolved topic, type name, QoS) of every channel, registered at the start
    so that every topic is in the file even when nothing was sent on it. ``metadata``:
    records written at the start. :meth:`write` only queues the bytes; the writer thread
    writes them and finishes a chunk at least every ``flush_interval_s`` (wall clock), so a
    SIGKILL loses about that much. When the writer falls :data:`MAX_BACKLOG_BYTES` behind,
    :meth:`write` waits (the simulation slows down; nothing is dropped). A write error
    stops the recording (:attr:`error`); the caller keeps running. Thread-safe.
    """

    def __init__(self, path: str | os.PathLike, topics: Iterable[tuple[str, str, QosProfile]],
                 metadata: Mapping[str, Mapping[str, str]], *,
                 flush_interval_s: float = FLUSH_INTERVAL_S, compression: str = 'zstd',
                 chunk_size: int = DEFAULT_CHUNK_SIZE,
                 max_backlog_bytes: int = MAX_BACKLOG_BYTES) -> None:
        """Create the file (and missing directories), write schemas, channels, metadata."""
        path = Path(path)
        _make_parent(path)
        self._recorder = McapRecorder(path, flush_interval_s=flush_interval_s,
                                      compression=compression, chunk_size=chunk_size)
        try:
            for topic, type_name, qos in topics:
                self._recorder.add_topic(topic, type_name, qos)
            for name, data in metadata.items():
                self._recorder.add_metadata(name, data)
            self._recorder.flush()
        except BaseException:
            self._recorder.close()
            raise
        # The caller's thread takes no lock that the writer thread needs: the only channel
        # is a SimpleQueue (put is atomic and safe to interrupt), and each byte counter has
        # one writer. A signal (SIGINT, SIGTERM) raised in the caller's thread while it held
        # a lock, including the one inside threading.Event, can leave that lock held (the
        # exception can land between acquiring it and entering the with block), and close()
        # would then wait forever for a writer that can never take it.
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._queued_bytes = 0  # written only by the producer
        self._done_bytes = 0  # written only by the writer thread
        self._max_backlog = max_backlog_bytes
        self._closed = False
        self._written = 0
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name='mcap_writer', daemon=True)
        self._thread.start()

    @property
    def path(self) -> Path:
        """Return the path of the file."""
        return self._recorder.path

    @property
    def error(self) -> BaseException | None:
        """Return the error that stopped the recording, if any."""
        return self._error

    @property
    def message_count(self) -> int:
        """Return the number of messages written to the file so far."""
        return self._written

    @property
    def closed(self) -> bool:
        """Tell whether :meth:`close` has run."""
        return self._closed

    def write(self, topic: str, type_name: str, data: bytes, log_time_ns: int) -> None:
        """Queue a serialized message for the file; log and publish time = log_time_ns."""
        if self._closed or self._error is not None:
            return
        while (self._queued_bytes - self._done_bytes > self._max_backlog
               and self._error is None and self._thread.is_alive()):
            time.sleep(_POLL_S / 20)
        self._queued_bytes += len(data)
        self._queue.put((topic, type_name, data, log_time_ns))

    def hook(self, record: MessageRecord) -> None:
        """Queue a message of the node (its message hook); log time = its simulation time."""
        self.write(record.topic, record.type_name, record.data, record.stamp_ns)

    def maybe_flush(self) -> None:
        """Wake the writer so that a due flush happens even when no message arrives."""
        self._queue.put(_WAKE)

    def _next_batch(self) -> tuple[list[tuple[str, str, bytes, int]], bool]:
        """Return what is queued (waiting up to a poll period for it) and whether to stop."""
        batch: list[tuple[str, str, bytes, int]] = []
        stop = False
        try:
            item = self._queue.get(timeout=_POLL_S)
        except queue.Empty:
            return batch, stop
        while True:
            if item is None:
                stop = True
            elif item is not _WAKE:
                batch.append(item)
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                return batch, stop

    def _run(self) -> None:
        while True:
            batch, stop = self._next_batch()
            if self._error is None:
                try:
                    for topic, type_name, data, log_time in batch:
                        self._recorder.write_serialized(topic, type_name, data, log_time)
                        self._written += 1
                        self._done_bytes += len(data)
                    self._recorder.maybe_flush()
                except Exception as exc:  # noqa: B902 - kept and reported by the caller
                    self._error = exc
            else:
                self._done_bytes += sum(len(item[2]) for item in batch)
            if stop:
                return

    def close(self, end_metadata: Mapping[str, str] | None = None) -> None:
        """Write what is queued, the end metadata, summary and footer; idempotent."""
        if self._closed:
            return
        self._closed = True
        self._queue.put(None)
        self._thread.join()
        try:
            if end_metadata is not None and self._error is None:
                self._recorder.add_metadata(END_METADATA_NAME, {
                    **end_metadata, 'messages': str(self._written)})
        finally:
            self._recorder.close()


# --------------------------------------------------------------------------- the runner's recorder


def scenario_metadata(scenario: Scenario, source: str, topics: Mapping[str, str],
                      markers_rate: float, frame_id: str) -> dict[str, str]:
    """Return the ``cone_feeder_sim`` metadata of a headless run."""
    values: dict[str, Any] = dict(model_parameter_values(scenario.model))
    values.update(solver_parameter_values(scenario.solver))
    values.update({'frame_id': frame_id, 'markers.rate': markers_rate,
                   'duration': scenario.duration, 'output_interval': scenario.output_interval})
    data = {name: parameter_text(value) for name, value in values.items()}
    data.update({
        'format': FORMAT_VERSION,
        'version': __version__,
        'source': 'cone-feeder-sim run',
        'scenario': source,
        'rotation': json.dumps([[float(t), float(w)] for t, w in zip(
            scenario.rotation.times, scenario.rotation.omegas)]),
        'particles': json.dumps(to_jsonable(scenario.particles)),
        'parameters_json': json.dumps(to_jsonable(values)),
        'topics': json.dumps(dict(topics)),
        'input_topics': '[]',
        'seed': '',
        'created': datetime.datetime.now().astimezone().isoformat(timespec='seconds'),
    })
    return data


class ScenarioRecorder:
    """
    The headless runner's MCAP output: the node's topics, written after every interval.

    Use it as the runner's progress callback. Topics (absolute, as a node in the root
    namespace publishes them): particles, particle_states, exit_events (intervals with
    exits only), channel_mass (cumulative), cone_state and markers (``markers_rate`` per
    simulated second); log time and stamps = simulation time at the end of the interval.
    """

    def __init__(self, path: str | os.PathLike, scenario: Scenario, source: str = '', *,
                 frame_id: str = 'feeder', markers_rate: float = 10.0) -> None:
        """Create the file and write schemas, channels and the metadata."""
        self._names = {name: '/' + name for name in RUNNER_TOPICS}
        path = Path(path)
        _make_parent(path)
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
        self._frame = frame_id
        self._markers = MarkerBuilder(scenario.model, frame_id)
        self._schedule = MarkerSchedule(markers_rate)
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
        """Write the messages of the interval that ended at t (s)."""
        t_ns = stamp_ns(t)
        head = header(t, self._frame)
        q, qdot, _ = sim.world()
        state = sim.state
        self._write('particles', particles_message(head, q), t_ns)
        self._write('particle_states', states_message(
            head, state.ids, q, qdot, state.products[:, P_M]), t_ns)
        exits = step.exits
        if len(exits):
            np.add.at(self._channel_mass, exits.channel - 1, exits.mass)
            self._write('exit_events', exits_message(head, exits), t_ns)
            self._exits += len(exits)
        self._write('channel_mass', channel_mass_message(self._channel_mass.copy()), t_ns)
        self._write('cone_state', cone_state_message(head, state.angle, sim.omega()), t_ns)
        if self._schedule.due(t):
            self._write('markers', self._markers.message(head, state.angle, q), t_ns)
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
