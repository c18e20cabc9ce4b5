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
The simulator's topics: names, types, directions and QoS, as one table.

Profiles are :class:`QosProfile` values in rosbag2's vocabulary (what an MCAP recording
stores in its channel metadata); :mod:`cone_feeder_sim.ros.qos` turns them into rclpy's.
Both the ROS 2 node and the headless runner's MCAP output use this table, so a recording
looks the same whichever wrote it.
"""

import collections.abc
from collections.abc import Mapping
import dataclasses
from dataclasses import dataclass
from typing import Any

import yaml

from ..errors import ConeFeederError, RecordingError

#: rmw's "infinite" duration (INT64_MAX ns) as rosbag2 writes it.
_INFINITE_SEC = 9223372036
_INFINITE_NSEC = 854775807

_HISTORY = ('system_default', 'keep_last', 'keep_all', 'unknown')
_RELIABILITY = ('system_default', 'reliable', 'best_effort', 'unknown', 'best_available')
_DURABILITY = ('system_default', 'transient_local', 'volatile', 'unknown', 'best_available')
_LIVELINESS = (
    'system_default', 'automatic', 'manual_by_node', 'manual_by_topic', 'unknown',
    'best_available')


@dataclasses.dataclass(frozen=True)
class QosProfile:
    """
    The offered QoS of a topic, as rosbag2 stores it in channel metadata.

    Enumerations use rosbag2's lower-case names (``keep_last``, ``reliable``,
    ``transient_local``...). Durations are in nanoseconds; ``None`` means
    infinite (rmw's default).
    """

    history: str = 'keep_last'
    depth: int = 10
    reliability: str = 'reliable'
    durability: str = 'volatile'
    deadline_ns: int | None = None
    lifespan_ns: int | None = None
    liveliness: str = 'automatic'
    liveliness_lease_duration_ns: int | None = None
    avoid_ros_namespace_conventions: bool = False

    def __post_init__(self) -> None:
        """Validate the enumerations, depth and durations."""
        for name, allowed in (
            ('history', _HISTORY), ('reliability', _RELIABILITY),
            ('durability', _DURABILITY), ('liveliness', _LIVELINESS)
        ):
            value = getattr(self, name)
            if value not in allowed:
                raise RecordingError(
                    f'QoS {name} must be one of {", ".join(allowed)}, got {value!r}')
        if not isinstance(self.depth, int) or self.depth < 0:
            raise RecordingError(f'QoS depth must be a non-negative int, got {self.depth!r}')
        for name in ('deadline_ns', 'lifespan_ns', 'liveliness_lease_duration_ns'):
            value = getattr(self, name)
            if value is not None and (not isinstance(value, int) or value < 0):
                raise RecordingError(f'QoS {name} must be None or an int >= 0, got {value!r}')

    @classmethod
    def from_value(cls, value: 'QosLike') -> 'QosProfile':
        """Return a profile from a profile, a mapping of field overrides or None (defaults)."""
        if value is None:
            return cls()
        if isinstance(value, QosProfile):
            return value
        if isinstance(value, collections.abc.Mapping):
            known = {field.name for field in dataclasses.fields(cls)}
            unknown = sorted(set(value) - known)
            if unknown:
                raise RecordingError(
                    f'unknown QoS keys {unknown}; known: {", ".join(sorted(known))}')
            return dataclasses.replace(cls(), **dict(value))
        raise RecordingError(f'cannot make a QoS profile from {type(value).__name__}')

    def to_yaml(self) -> str:
        """Return the ``offered_qos_profiles`` YAML text (a one-element list)."""
        def duration(name: str, value: int | None) -> str:
            if value is None:
                sec, nsec = _INFINITE_SEC, _INFINITE_NSEC
            else:
                sec, nsec = divmod(value, 1_000_000_000)
            return f'  {name}:\n    sec: {sec}\n    nsec: {nsec}\n'

        return (
            f'- history: {self.history}\n'
            f'  depth: {self.depth}\n'
            f'  reliability: {self.reliability}\n'
            f'  durability: {self.durability}\n'
            + duration('deadline', self.deadline_ns)
            + duration('lifespan', self.lifespan_ns)
            + f'  liveliness: {self.liveliness}\n'
            + duration('liveliness_lease_duration', self.liveliness_lease_duration_ns)
            + '  avoid_ros_namespace_conventions: '
            + ('true' if self.avoid_ros_namespace_conventions else 'false'))


#: What :class:`McapRecorder` accepts as the QoS of a topic (None: the defaults).
QosLike = QosProfile | collections.abc.Mapping[str, Any] | None


def qos_from_yaml(text: str) -> QosProfile | None:
    """
    Return the first profile of an ``offered_qos_profiles`` YAML text, None if unusable.

    Only history, depth, reliability and durability are taken (what a republisher needs).
    """
    try:
        profiles = yaml.safe_load(text) if text else None
    except yaml.YAMLError:
        return None
    if not isinstance(profiles, list) or not profiles or not isinstance(profiles[0], dict):
        return None
    first = profiles[0]
    fields: dict[str, Any] = {}
    for key in ('history', 'reliability', 'durability'):
        if isinstance(first.get(key), str):
            fields[key] = first[key]
    if isinstance(first.get('depth'), int) and not isinstance(first.get('depth'), bool):
        fields['depth'] = first['depth']
    try:
        return QosProfile(**fields)
    except ConeFeederError:
        return None


@dataclass(frozen=True)
class MessageRecord:
    """
    One message as it went over the wire.

    direction: 'out' (published) or 'in' (received); topic: the fully resolved name;
    type_name: 'pkg/msg/Type'; data: the serialized CDR bytes (with encapsulation header);
    stamp_ns: simulation time (ns) of the message (received: the engine time on arrival);
    wall_ns: system time (ns) when it was published or received.
    """

    direction: str
    topic: str
    type_name: str
    data: bytes
    stamp_ns: int
    wall_ns: int


STATE_QOS = QosProfile(history='keep_last', depth=10, reliability='reliable',
                       durability='volatile')
EVENTS_QOS = QosProfile(history='keep_last', depth=1000, reliability='reliable',
                        durability='volatile')
LATCHED_QOS = QosProfile(history='keep_last', depth=1, reliability='reliable',
                         durability='transient_local')
CLOCK_QOS = QosProfile(history='keep_last', depth=1, reliability='reliable',
                       durability='volatile')
#: A camera's stream: the newest frames matter, a lost one is not sent again.
SENSOR_QOS = QosProfile(history='keep_last', depth=10, reliability='best_effort',
                        durability='volatile')
COMMAND_QOS = QosProfile(history='keep_last', depth=10, reliability='reliable',
                         durability='volatile')


@dataclass(frozen=True)
class TopicSpec:
    """A topic of the simulator: name as the node uses it, type, direction and QoS."""

    name: str
    type_name: str
    direction: str
    qos: QosProfile


#: Every topic of the simulator. Names are relative (namespaces apply), ``~/`` is private to
#: the node, ``/`` is absolute. ``direction``: 'out' published, 'in' subscribed.
TOPICS: Mapping[str, TopicSpec] = {spec.name: spec for spec in (
    TopicSpec('particles', 'geometry_msgs/msg/PoseArray', 'out', STATE_QOS),
    TopicSpec('particle_states', 'sensor_msgs/msg/PointCloud2', 'out', STATE_QOS),
    TopicSpec('exit_events', 'sensor_msgs/msg/PointCloud2', 'out', EVENTS_QOS),
    TopicSpec('channel_mass', 'std_msgs/msg/Float64MultiArray', 'out', LATCHED_QOS),
    TopicSpec('cone_state', 'sensor_msgs/msg/JointState', 'out', STATE_QOS),
    TopicSpec('hopper_weights', 'std_msgs/msg/Float64MultiArray', 'out', LATCHED_QOS),
    TopicSpec('pack_events', 'sensor_msgs/msg/PointCloud2', 'out', EVENTS_QOS),
    TopicSpec('markers', 'visualization_msgs/msg/MarkerArray', 'out', LATCHED_QOS),
    TopicSpec('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', 'out', STATE_QOS),
    TopicSpec('/clock', 'rosgraph_msgs/msg/Clock', 'out', CLOCK_QOS),
    TopicSpec('~/events', 'std_msgs/msg/String', 'out', EVENTS_QOS),
    TopicSpec('rotation_cmd', 'std_msgs/msg/Float64', 'in', COMMAND_QOS),
    TopicSpec('spawn', 'geometry_msgs/msg/PoseArray', 'in', COMMAND_QOS),
    TopicSpec('channel_feed', 'std_msgs/msg/Float64MultiArray', 'in', COMMAND_QOS),
)}

#: Every topic of ``twin_node``: the camera's detections, the cone's measured speed (the
#: plant's ``cone_state``) and the channels' measured exits (the plant's ``exit_events``) in,
#: the twin's estimates out.
TWIN_TOPICS: Mapping[str, TopicSpec] = {spec.name: spec for spec in (
    TopicSpec('detections', 'sensor_msgs/msg/PointCloud2', 'in', SENSOR_QOS),
    TopicSpec('cone_state', 'sensor_msgs/msg/JointState', 'in', STATE_QOS),
    TopicSpec('exit_events', 'sensor_msgs/msg/PointCloud2', 'in', EVENTS_QOS),
    TopicSpec('twin/pieces', 'sensor_msgs/msg/PointCloud2', 'out', STATE_QOS),
    TopicSpec('twin/channel_forecast', 'std_msgs/msg/Float64MultiArray', 'out', STATE_QOS),
    TopicSpec('twin/parameters', 'std_msgs/msg/Float64MultiArray', 'out', STATE_QOS),
    TopicSpec('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', 'out', STATE_QOS),
)}

#: Every topic of ``camera_node``: the plant's true pieces in (sim_node's ``particle_states``),
#: the camera's detections out (twin_node's ``detections``).
CAMERA_TOPICS: Mapping[str, TopicSpec] = {spec.name: spec for spec in (
    TopicSpec('particle_states', 'sensor_msgs/msg/PointCloud2', 'in', STATE_QOS),
    TopicSpec('detections', 'sensor_msgs/msg/PointCloud2', 'out', SENSOR_QOS),
)}

#: The topics the headless runner writes (a scenario has no inputs and no wall clock).
RUNNER_TOPICS = ('particles', 'particle_states', 'exit_events', 'channel_mass', 'cone_state',
                 'markers')
