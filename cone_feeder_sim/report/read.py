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
Reading a recorded run for the report: :func:`read_run` turns an MCAP file into arrays.

It streams the file (ROS 2 profile, CDR messages) with
:class:`~cone_feeder_sim.formats.mcap_reader.RecordStream` (mcap's non-seeking reader), so a file
cut off by a crash still yields everything before the damage, and turns the topics
``particle_states``, ``exit_events``, ``cone_state`` and ``channel_mass`` (matched by the
last part of the topic name and by type) into numpy arrays in a :class:`RunData`. Times are
log times (simulation time) in seconds.

Trajectories are thinned so that big runs stay fast: at most ``max_trajectories`` pieces are
kept (ids divisible by a power of two, so the choice is spread over the run) and at most
``max_trajectory_points`` points (every ``2**k``-th ``particle_states`` message). Piece
counts, omega(t), exits and channel masses are always complete.

The channel layout and the cone radius come from the metadata record ``cone_feeder_sim``
(string values of ``model.cone_diameter``, ``model.channel_count``,
``model.channel_boundary``, ``model.channel_numbering``); missing or invalid values fall back
to :class:`~cone_feeder_sim.physics.params.ModelParams` defaults, with a note on the figure.
Drawing is :mod:`cone_feeder_sim.report.draw`.
"""

import collections.abc
import dataclasses
import os
import pathlib
import struct
from typing import Any

from mcap.exceptions import EndOfFile, InvalidMagic
from mcap.records import Channel, Header, Message, Metadata, Schema
import numpy as np
import yaml

from ..errors import MessageError, ParameterError, ReportError
from ..formats.cdr import CdrCodec, CdrError, default_codec
from ..formats.mcap_reader import RecordStream
from ..formats.msgtypes import MessageDefinitionError, normalize_type_name, registry_from_schema
from ..formats.pointcloud import cloud_points
from ..formats.runlog import METADATA_NAME
from ..formats.topics import TOPICS
from ..physics.params import ChannelLayout, model_params_from_mapping, ModelParams
from ..physics.simulation import ExitEvents

__all__ = [
    'DEFAULT_MAX_TRAJECTORIES',
    'DEFAULT_MAX_TRAJECTORY_POINTS',
    'ChannelTotals',
    'HopperSeries',
    'Packs',
    'ReportError',
    'RunData',
    'TimeSeries',
    'Trajectories',
    'check_channel_mass',
    'exits_per_channel',
    'layout_from_metadata',
    'read_run',
]

#: Metadata keys of the channel layout and cone size, by parameter-file key.
METADATA_KEYS = {
    'cone_diameter': 'model.cone_diameter',
    'channel_count': 'model.channel_count',
    'channel_boundary': 'model.channel_boundary',
    'channel_numbering': 'model.channel_numbering',
}
DEFAULT_MAX_TRAJECTORIES = 60
DEFAULT_MAX_TRAJECTORY_POINTS = 400_000

#: Topic roles: last part of the topic name -> message type.
TOPIC_TYPES = {role: TOPICS[role].type_name
               for role in ('particle_states', 'exit_events', 'cone_state', 'channel_mass',
                            'pack_events', 'hopper_weights')}
#: Roles a run has only with the weigher (no note when they are missing).
WEIGHER_ROLES = ('pack_events', 'hopper_weights')


# --------------------------------------------------------------------------- data


@dataclasses.dataclass(frozen=True)
class TimeSeries:
    """Values over simulation time: ``t`` (s) and ``value``, both shape (n,), sorted by t."""

    t: np.ndarray
    value: np.ndarray

    def __len__(self) -> int:
        """Return the number of samples."""
        return int(self.t.shape[0])


@dataclasses.dataclass(frozen=True)
class Packs:
    """The weigher's packs: discharge time ``t`` (s), ``mass`` and ``giveaway`` (kg), (P,)."""

    t: np.ndarray
    mass: np.ndarray
    giveaway: np.ndarray


@dataclasses.dataclass(frozen=True)
class HopperSeries:
    """Weigh hopper readings over time: ``t`` (K,) s and ``weight`` (K, heads) kg."""

    t: np.ndarray
    weight: np.ndarray


@dataclasses.dataclass(frozen=True)
class Trajectories:
    """
    Positions of the kept pieces from the kept ``particle_states`` messages.

    One row per point: ``t`` (s, log time), ``ids`` (int64), ``x``, ``y`` (m), in
    reading order. Kept were the messages whose index (0-based, over all
    ``particle_states`` messages) is divisible by ``message_stride`` and the
    pieces whose id is divisible by ``id_stride``; ``pieces_seen`` counts the
    distinct ids of all messages.
    """

    t: np.ndarray
    ids: np.ndarray
    x: np.ndarray
    y: np.ndarray
    message_stride: int = 1
    id_stride: int = 1
    pieces_seen: int = 0

    @property
    def pieces_kept(self) -> int:
        """Return the number of distinct ids kept."""
        return int(np.unique(self.ids).shape[0])

    def by_id(self) -> dict[int, np.ndarray]:
        """Return ``{id: (n, 3) array of t, x, y}`` sorted by id, each sorted by time."""
        if self.ids.shape[0] == 0:
            return {}
        order = np.lexsort((self.t, self.ids))
        ids = self.ids[order]
        rows = np.column_stack((self.t[order], self.x[order], self.y[order]))
        unique, starts = np.unique(ids, return_index=True)
        return {int(key): part for key, part in zip(unique, np.split(rows, starts[1:]))}


@dataclasses.dataclass(frozen=True)
class ChannelTotals:
    """Exits per channel: ``count`` (int64) and ``mass`` (kg), index 0 = channel 1."""

    count: np.ndarray
    mass: np.ndarray


@dataclasses.dataclass(frozen=True)
class RunData:
    """
    What a report shows, read from one MCAP file.

    ``layout`` and ``cone_radius`` (m) come from the metadata when
    ``layout_from_metadata`` is true, else from :class:`ModelParams` defaults.
    ``last_frame`` is the time (s) and the (n, 2) positions (m) of the last
    ``particle_states`` message, or None. ``packs`` and ``hoppers`` are the weigher's
    ``pack_events`` and ``hopper_weights`` (None in a run without the weigher).
    ``omega`` is the cone's angular velocity (rad/s) per ``cone_state``
    message; ``pieces`` the number of points per ``particle_states`` message;
    ``channel_mass`` the data of the last ``channel_mass`` message (kg, index 0
    = channel 1) at ``channel_mass_time`` (s), or None. ``topics`` maps each
    role found to its topic. ``truncated`` describes why reading stopped
    early (None for a complete file). ``notes`` are shown on the figure.
    """

    path: pathlib.Path
    layout: ChannelLayout
    cone_radius: float
    layout_from_metadata: bool
    metadata: dict[str, str]
    trajectories: Trajectories
    exits: ExitEvents
    exit_log_time: np.ndarray
    omega: TimeSeries
    pieces: TimeSeries
    channel_mass: np.ndarray | None
    channel_mass_time: float | None
    topics: dict[str, str]
    message_count: int
    truncated: str | None
    notes: tuple[str, ...]
    last_frame: tuple[float, np.ndarray] | None = None
    packs: 'Packs | None' = None
    hoppers: 'HopperSeries | None' = None

    def piece_radius(self) -> float:
        """Return the pieces' outer radius s0 (m): the metadata's, else the default."""
        try:
            value = float(_metadata_value(self.metadata['model.s0']))
        except (KeyError, TypeError, ValueError):
            return ModelParams().product.s0
        return value if value > 0.0 else ModelParams().product.s0

    def contact(self) -> str | None:
        """Return the contact setting recorded ('on, pull-off ...' or 'off'), or None."""
        enabled = self.metadata.get('interactions.enabled')
        if enabled is None:
            return None
        if str(enabled).lower() not in ('true', '1'):
            return 'off'
        get = self.metadata.get
        if 'interactions.restitution' not in self.metadata:
            return (f"on (pull-off {get('interactions.pull_off', '?')} N, max island "
                    f"{get('interactions.max_island', '?')}; the pair law before soft contact)")
        return (f"on (restitution {get('interactions.restitution')}, friction "
                f"{get('interactions.friction', '?')}, pull-off "
                f"{get('interactions.pull_off', '?')} N, {get('interactions.coupling', '?')})")

    def exit_totals(self) -> ChannelTotals:
        """Return exits per channel over the layout's channels (more if exits name more)."""
        return exits_per_channel(self.exits, self.layout.count)

    def time_span(self) -> tuple[float, float] | None:
        """Return the first and last log time (s) of the data shown, or None without data."""
        times = [series.t for series in (self.omega, self.pieces) if len(series)]
        if len(self.exits):
            times.append(self.exit_log_time)
        if not times:
            return None
        return (min(float(t[0]) for t in times), max(float(t[-1]) for t in times))


# --------------------------------------------------------------------------- decoding


def _schema_codec(schema: Schema) -> CdrCodec:
    """Return a codec for the definitions of the file's schema, or the default codec."""
    if schema.encoding != 'ros2msg':
        return default_codec()
    try:
        codec = CdrCodec(registry_from_schema(schema.name, schema.data.decode('utf-8')))
        codec.struct_decoder(schema.name)  # resolves every dependency now
        return codec
    except (MessageDefinitionError, CdrError, UnicodeDecodeError):
        return default_codec()


def _topic_role(topic: str, namespace: str | None) -> str | None:
    """Return the role (key of :data:`TOPIC_TYPES`) of a recorded topic name, if any."""
    base = topic.rstrip('/').rpartition('/')[2]
    if base not in TOPIC_TYPES:
        return None
    if namespace is not None:
        expected = '/' + '/'.join(p for p in namespace.split('/') + [base] if p)
        if '/' + topic.strip('/') != expected:
            return None
    return base


# --------------------------------------------------------------------------- metadata


def _metadata_value(text: str) -> Any:
    """Return a metadata string as a number or string (YAML scalar rules)."""
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        return text
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


def layout_from_metadata(
    metadata: collections.abc.Mapping[str, str] | None
) -> tuple[ChannelLayout, float, bool, list[str]]:
    """
    Return the channel layout, the cone radius (m), whether they came from metadata, notes.

    ``metadata`` is the ``cone_feeder_sim`` record (None when absent). Keys
    missing from it keep the :class:`ModelParams` defaults; invalid values make
    every value fall back to the defaults. Notes say what was assumed.
    """
    defaults = ModelParams()
    if metadata is None:
        return defaults.channels, defaults.r, False, [
            f'no {METADATA_NAME!r} metadata record: cone radius and channel layout are the '
            'ModelParams() defaults']
    found = {key: _metadata_value(metadata[name]) for key, name in METADATA_KEYS.items()
             if name in metadata}
    notes = []
    missing = [name for name in METADATA_KEYS.values() if name not in metadata]
    if missing:
        notes.append(f'metadata lacks {", ".join(missing)}: defaults used for those')
    if isinstance(found.get('channel_count'), float) and found['channel_count'].is_integer():
        found['channel_count'] = int(found['channel_count'])
    try:
        model = model_params_from_mapping(found, defaults)
    except ParameterError as err:
        return defaults.channels, defaults.r, False, [
            f'invalid metadata ({err}): cone radius and channel layout are the ModelParams() '
            'defaults']
    return model.channels, model.r, not missing, notes


# --------------------------------------------------------------------------- reading


class _TrajectoryCollector:
    """Keep a bounded, evenly thinned sample of the piece positions while streaming."""

    def __init__(self, max_ids: int, max_points: int) -> None:
        """Keep at most ``max_ids`` pieces and ``max_points`` points."""
        self.max_ids = max(1, int(max_ids))
        self.max_points = max(1, int(max_points))
        self.message_stride = 1
        self.id_stride = 1
        self.messages = 0
        self.pieces_seen = 0
        self._previous = np.zeros(0, dtype=np.int64)
        self._kept_ids: set[int] = set()
        self._chunks: list[tuple[int, float, np.ndarray, np.ndarray, np.ndarray]] = []
        self._points = 0

    def add(self, t: float, ids: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
        """Take the pieces of one ``particle_states`` message."""
        index = self.messages
        self.messages += 1
        ids = ids.astype(np.int64)
        new = np.setdiff1d(ids, self._previous, assume_unique=True)
        self._previous = np.sort(ids)
        self.pieces_seen += int(new.shape[0])
        kept_new = new[new % self.id_stride == 0]
        if kept_new.shape[0]:
            self._kept_ids.update(kept_new.tolist())
            while len(self._kept_ids) > self.max_ids:
                self._thin_ids()
        if index % self.message_stride:
            return
        mask = ids % self.id_stride == 0
        chunk = (index, t, ids[mask], x[mask].astype(np.float32), y[mask].astype(np.float32))
        self._chunks.append(chunk)
        self._points += int(chunk[2].shape[0])
        while self._points > self.max_points and len(self._chunks) > 1:
            self._thin_messages()

    def _thin_ids(self) -> None:
        self.id_stride *= 2
        stride = self.id_stride
        self._kept_ids = {key for key in self._kept_ids if key % stride == 0}
        chunks = []
        for index, t, ids, x, y in self._chunks:
            mask = ids % stride == 0
            chunks.append((index, t, ids[mask], x[mask], y[mask]))
        self._chunks = chunks
        self._points = sum(chunk[2].shape[0] for chunk in chunks)

    def _thin_messages(self) -> None:
        self.message_stride *= 2
        self._chunks = [c for c in self._chunks if c[0] % self.message_stride == 0]
        self._points = sum(chunk[2].shape[0] for chunk in self._chunks)

    def result(self) -> Trajectories:
        """Return the kept points."""
        chunks = self._chunks
        if not chunks:
            empty = np.zeros(0)
            return Trajectories(empty, np.zeros(0, dtype=np.int64), empty, empty,
                                self.message_stride, self.id_stride, self.pieces_seen)
        sizes = [chunk[2].shape[0] for chunk in chunks]
        return Trajectories(
            t=np.repeat(np.array([chunk[1] for chunk in chunks]), sizes),
            ids=np.concatenate([chunk[2] for chunk in chunks]),
            x=np.concatenate([chunk[3] for chunk in chunks]).astype(np.float64),
            y=np.concatenate([chunk[4] for chunk in chunks]).astype(np.float64),
            message_stride=self.message_stride, id_stride=self.id_stride,
            pieces_seen=self.pieces_seen)


def _require(points: np.ndarray, names: tuple[str, ...], topic: str) -> None:
    missing = [name for name in names if name not in (points.dtype.names or ())]
    if missing:
        raise ReportError(f'{topic} points lack the field(s) {", ".join(missing)}')


class _RunReader:
    """Accumulate the report's arrays from the records of one file."""

    def __init__(self, namespace: str | None, max_trajectories: int,
                 max_trajectory_points: int) -> None:
        """Prepare empty accumulators; see :func:`read_run` for the arguments."""
        self.namespace = namespace
        self.codecs: dict[int, CdrCodec] = {}
        self.channels: dict[int, tuple[str, str, CdrCodec]] = {}
        self.topics: dict[str, str] = {}
        self.ignored_topics: dict[str, set[str]] = {}
        self.metadata: dict[str, str] | None = None
        self.trajectories = _TrajectoryCollector(max_trajectories, max_trajectory_points)
        self.pieces_t: list[float] = []
        self.pieces_n: list[int] = []
        self.last_frame: tuple[float, np.ndarray] | None = None
        self.pack_parts: list[np.ndarray] = []
        self.hopper_t: list[float] = []
        self.hopper_rows: list[np.ndarray] = []
        self.omega_t: list[float] = []
        self.omega: list[float] = []
        self.exit_parts: list[tuple[float, np.ndarray]] = []
        self.channel_mass: np.ndarray | None = None
        self.channel_mass_time: float | None = None
        self.message_count = 0
        self.failures: dict[str, tuple[int, str]] = {}

    def take(self, record: Any, stream: RecordStream) -> None:
        """Take one record of ``stream`` (which knows the schemas read so far)."""
        if isinstance(record, Message):
            self.message_count += 1
            channel = self.channels.get(record.channel_id)
            if channel is not None:
                self._message(channel, record)
        elif isinstance(record, Channel):
            self._channel(record, stream.schemas.get(record.schema_id))
        elif isinstance(record, Metadata) and record.name == METADATA_NAME:
            self.metadata = {**(self.metadata or {}), **dict(record.metadata)}

    def _channel(self, record: Channel, schema: Schema | None) -> None:
        if record.id in self.channels:
            return
        role = _topic_role(record.topic, self.namespace)
        if role is None or schema is None or record.message_encoding != 'cdr':
            return
        try:
            type_name = normalize_type_name(schema.name)
        except MessageDefinitionError:
            return
        if type_name != TOPIC_TYPES[role]:
            return
        if role in self.topics and self.topics[role] != record.topic:
            self.ignored_topics.setdefault(role, set()).add(record.topic)
            return
        if record.schema_id not in self.codecs:
            self.codecs[record.schema_id] = _schema_codec(schema)
        self.topics[role] = record.topic
        self.channels[record.id] = (role, type_name, self.codecs[record.schema_id])

    def _message(self, channel: tuple[str, str, CdrCodec], record: Message) -> None:
        role, type_name, codec = channel
        t = record.log_time * 1e-9
        try:
            message = codec.decode(type_name, record.data, strict=False)
            if role == 'particle_states':
                self._particle_states(t, message)
            elif role == 'exit_events':
                self._exit_events(t, message)
            elif role == 'cone_state':
                self._cone_state(t, message)
            elif role == 'pack_events':
                points = cloud_points(message)
                _require(points, ('t', 'mass', 'giveaway'), 'pack_events')
                self.pack_parts.append(points)
            elif role == 'hopper_weights':
                self.hopper_t.append(t)
                self.hopper_rows.append(np.asarray(message['data'], dtype=np.float64).copy())
            else:
                self.channel_mass = np.asarray(message['data'], dtype=np.float64).copy()
                self.channel_mass_time = t
        except (CdrError, MessageError, ReportError, ValueError, KeyError, TypeError) as err:
            count, first = self.failures.get(role, (0, str(err)))
            self.failures[role] = (count + 1, first)

    def _particle_states(self, t: float, message: dict[str, Any]) -> None:
        points = cloud_points(message)
        _require(points, ('x', 'y', 'id'), 'particle_states')
        self.pieces_t.append(t)
        self.pieces_n.append(int(points.shape[0]))
        self.last_frame = (t, np.column_stack([points['x'], points['y']]).astype(np.float64))
        self.trajectories.add(t, points['id'], points['x'], points['y'])

    def _exit_events(self, t: float, message: dict[str, Any]) -> None:
        points = cloud_points(message)
        _require(points, ('x', 'y', 'mass'), 'exit_events')
        if points.shape[0]:
            self.exit_parts.append((t, points))

    def _cone_state(self, t: float, message: dict[str, Any]) -> None:
        velocity = np.asarray(message['velocity'], dtype=np.float64)
        names = list(message['name'])
        index = names.index('cone') if 'cone' in names else 0
        if velocity.shape[0] <= index:
            raise ReportError('cone_state has no velocity of the cone')
        self.omega_t.append(t)
        self.omega.append(float(velocity[index]))

    def exits(self, layout: ChannelLayout) -> tuple[ExitEvents, np.ndarray]:
        """
        Return the exits read, sorted by log time, and their log times (s).

        Fields a recording lacks are filled in: ``exit_time`` with the log time, ``id``
        with -1, ``z`` and velocities with NaN, ``mass`` with 0 and ``channel`` from the
        angle and the layout.
        """
        def column(name: str, dtype: type, default: Any = None) -> np.ndarray:
            parts = []
            for t, points in self.exit_parts:
                if name in (points.dtype.names or ()):
                    parts.append(points[name].astype(dtype))
                elif default is None:
                    parts.append(np.full(points.shape[0], t, dtype=dtype))
                else:
                    parts.append(np.full(points.shape[0], default, dtype=dtype))
            return np.concatenate(parts) if parts else np.zeros(0, dtype=dtype)

        log_time = np.concatenate([np.full(p.shape[0], t) for t, p in self.exit_parts]) if (
            self.exit_parts) else np.zeros(0)
        position = np.column_stack([column('x', np.float64, 0.0), column('y', np.float64, 0.0),
                                    column('z', np.float64, np.nan)])
        velocity = np.column_stack([column(name, np.float64, np.nan)
                                    for name in ('vx', 'vy', 'vz')])
        angle_deg = np.degrees(np.arctan2(position[:, 1], position[:, 0])) % 360.0
        channel = column('channel', np.int64, 0)
        has_channel = np.concatenate([
            np.full(p.shape[0], 'channel' in (p.dtype.names or ())) for _, p in self.exit_parts
        ]) if self.exit_parts else np.zeros(0, dtype=bool)
        if not has_channel.all():
            channel = np.where(has_channel, channel, layout.channel_of(angle_deg))
        order = np.argsort(log_time, kind='stable')
        exits = ExitEvents(
            ids=column('id', np.int64, -1)[order], t=column('exit_time', np.float64)[order],
            angle_deg=angle_deg[order], channel=channel[order], position=position[order],
            velocity=velocity[order], mass=column('mass', np.float64, 0.0)[order])
        return exits, log_time[order]


def _series(t: list[float], value: list[Any], dtype: type) -> TimeSeries:
    times = np.asarray(t, dtype=np.float64)
    order = np.argsort(times, kind='stable')
    return TimeSeries(times[order], np.asarray(value, dtype=dtype)[order])


def _describe_error(err: BaseException) -> str:
    if isinstance(err, (EndOfFile, EOFError, struct.error)):
        return 'the file ends inside a record'
    text = str(err).strip()
    return f'{type(err).__name__}: {text}' if text else type(err).__name__


def read_run(
    path: str | os.PathLike, *, namespace: str | None = None,
    max_trajectories: int = DEFAULT_MAX_TRAJECTORIES,
    max_trajectory_points: int = DEFAULT_MAX_TRAJECTORY_POINTS,
) -> RunData:
    """
    Read the report's data from the MCAP file at ``path``.

    Topics are matched by their last name part (``/ns/particle_states`` is
    ``particle_states``) and type; ``namespace`` restricts them to one
    namespace, otherwise the first topic of each role is used. A file that is
    cut off or corrupt gives what was read before the damage (see
    ``RunData.truncated``); a file that is not MCAP raises :class:`ReportError`.
    """
    path = pathlib.Path(path)
    try:
        stream = open(path, 'rb')
    except OSError as err:
        raise ReportError(
            f'cannot read MCAP file {str(path)!r}: {err.strerror or err}') from err
    reader = _RunReader(namespace, max_trajectories, max_trajectory_points)
    with stream:
        readable = RecordStream(stream)
        records = iter(readable)
        header = next(records, None)
        if readable.error is not None:
            if isinstance(readable.error, InvalidMagic):
                reason = 'it does not start with the MCAP magic bytes'
            elif isinstance(readable.error, (EndOfFile, EOFError, struct.error)):
                reason = 'it is empty or too short'
            else:
                reason = _describe_error(readable.error)
            raise ReportError(f'{str(path)!r} is not an MCAP file ({reason})') from readable.error
        if not isinstance(header, Header):
            raise ReportError(f'{str(path)!r} is not an MCAP file (no header record)')
        for record in records:
            reader.take(record, readable)
    truncated = None if readable.error is None else _describe_error(readable.error)
    return _finish(path, reader, truncated)


def _finish(path: pathlib.Path, reader: _RunReader, truncated: str | None) -> RunData:
    layout, radius, from_metadata, notes = layout_from_metadata(reader.metadata)
    if truncated is not None:
        notes.insert(0, f'file incomplete or corrupt after {reader.message_count} messages '
                        f'({truncated}); showing what was readable')
    for role, (count, first) in sorted(reader.failures.items()):
        notes.append(f'{count} {role} message(s) could not be read (first: {first})')
    for role, topics in sorted(reader.ignored_topics.items()):
        notes.append(f'{role}: using {reader.topics[role]}, ignoring {", ".join(sorted(topics))}')
    for role in TOPIC_TYPES:
        if role not in reader.topics and role not in WEIGHER_ROLES:
            notes.append(f'no {role} topic ({TOPIC_TYPES[role]}) in the file')
    trajectories = reader.trajectories.result()
    exits, exit_log_time = reader.exits(layout)
    if trajectories.message_stride > 1 or trajectories.id_stride > 1:
        stride = trajectories.message_stride
        notes.append(
            f'trajectories thinned: {trajectories.pieces_kept} of {trajectories.pieces_seen} '
            f'pieces drawn (ids divisible by {trajectories.id_stride}), '
            + ('from every particle_states message' if stride == 1 else
               f'positions from 1 in {stride} particle_states messages'))
    return RunData(
        path=path, layout=layout, cone_radius=radius, layout_from_metadata=from_metadata,
        metadata=dict(reader.metadata or {}), trajectories=trajectories,
        exits=exits, exit_log_time=exit_log_time,
        omega=_series(reader.omega_t, reader.omega, np.float64),
        pieces=_series(reader.pieces_t, reader.pieces_n, np.int64),
        channel_mass=reader.channel_mass, channel_mass_time=reader.channel_mass_time,
        topics=dict(reader.topics), message_count=reader.message_count, truncated=truncated,
        notes=tuple(notes), last_frame=reader.last_frame, packs=_packs(reader),
        hoppers=_hoppers(reader))


def _packs(reader: '_RunReader') -> Packs | None:
    if not reader.pack_parts:
        return None
    points = np.concatenate(reader.pack_parts)
    return Packs(t=points['t'].astype(np.float64), mass=points['mass'].astype(np.float64),
                 giveaway=points['giveaway'].astype(np.float64))


def _hoppers(reader: '_RunReader') -> HopperSeries | None:
    rows = reader.hopper_rows
    if not rows or any(row.shape != rows[0].shape for row in rows):
        return None
    return HopperSeries(t=np.array(reader.hopper_t), weight=np.vstack(rows))


def exits_per_channel(exits: ExitEvents, channel_count: int) -> ChannelTotals:
    """
    Return the number and mass (kg) of exits per channel, index 0 = channel 1.

    The arrays have ``channel_count`` entries, more when an exit names a higher
    channel. Exits with channel 0 (unknown) are not counted.
    """
    channel = exits.channel.astype(np.int64)
    valid = channel >= 1
    size = max(int(channel_count), int(channel.max()) if channel.shape[0] else 0)
    count = np.bincount(channel[valid] - 1, minlength=size).astype(np.int64)
    mass = np.bincount(channel[valid] - 1, weights=exits.mass[valid], minlength=size)
    return ChannelTotals(count=count, mass=mass.astype(np.float64))


def check_channel_mass(run: RunData, totals: ChannelTotals) -> tuple[bool, float] | None:
    """Return whether the last ``channel_mass`` equals the exit sums and the largest |Δ| (kg)."""
    if run.channel_mass is None:
        return None
    size = max(run.channel_mass.shape[0], totals.mass.shape[0])
    recorded = np.zeros(size)
    recorded[:run.channel_mass.shape[0]] = run.channel_mass
    summed = np.zeros(size)
    summed[:totals.mass.shape[0]] = totals.mass
    delta = float(np.max(np.abs(recorded - summed))) if size else 0.0
    agree = bool(np.allclose(recorded, summed, rtol=1e-9, atol=1e-12))
    return agree, delta
