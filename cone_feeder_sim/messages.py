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
The simulator's topics and messages, built without rclpy.

Both the ROS 2 node (:mod:`cone_feeder_sim.sim_node`) and the headless runner's MCAP output
(``cone-feeder-sim run ... --mcap``) build their messages here, so a live run and a batch
run carry the same topics, types, QoS and point layouts. Messages are plain mappings that
:mod:`cone_feeder_sim.cdr` encodes; arrays are numpy arrays.

:data:`TOPICS` lists every topic with its type and offered QoS (as
:class:`~cone_feeder_sim.recording.QosProfile`, which the node converts to rclpy's profile
and the recorder writes into the channel metadata).
"""

from collections.abc import Mapping
from dataclasses import dataclass
import math
from typing import Any

import numpy as np

from .cdr import CdrCodec, default_codec
from .params import ModelParams
from .recording import QosProfile
from .simulation import ExitEvents

__all__ = [
    'COMMAND_QOS',
    'CLOCK_QOS',
    'EVENTS_QOS',
    'EXIT_DATATYPES',
    'EXIT_DTYPE',
    'MarkerBuilder',
    'MarkerSchedule',
    'MessageRecord',
    'LATCHED_QOS',
    'RUNNER_TOPICS',
    'STATE_QOS',
    'STATE_DATATYPES',
    'STATE_DTYPE',
    'TOPICS',
    'TopicSpec',
    'channel_mass_message',
    'clock_message',
    'cone_state_message',
    'exits_message',
    'header',
    'particles_message',
    'point_fields',
    'stamp',
    'stamp_ns',
    'states_message',
]

# --------------------------------------------------------------------------- topics


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
    TopicSpec('markers', 'visualization_msgs/msg/MarkerArray', 'out', LATCHED_QOS),
    TopicSpec('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', 'out', STATE_QOS),
    TopicSpec('/clock', 'rosgraph_msgs/msg/Clock', 'out', CLOCK_QOS),
    TopicSpec('~/events', 'std_msgs/msg/String', 'out', EVENTS_QOS),
    TopicSpec('rotation_cmd', 'std_msgs/msg/Float64', 'in', COMMAND_QOS),
    TopicSpec('spawn', 'geometry_msgs/msg/PoseArray', 'in', COMMAND_QOS),
)}

#: The topics the headless runner writes (a scenario has no inputs and no wall clock).
RUNNER_TOPICS = ('particles', 'particle_states', 'exit_events', 'channel_mass', 'cone_state',
                 'markers')

# --------------------------------------------------------------------------- point layouts

# sensor_msgs/PointField datatypes
UINT32 = 6
FLOAT32 = 7
FLOAT64 = 8

STATE_DTYPE = np.dtype({
    'names': ['x', 'y', 'z', 'vx', 'vy', 'vz', 'id', 'mass'],
    'formats': ['<f4'] * 6 + ['<u4', '<f4'],
    'offsets': [0, 4, 8, 12, 16, 20, 24, 28],
    'itemsize': 32})
STATE_DATATYPES = [FLOAT32] * 6 + [UINT32, FLOAT32]

EXIT_DTYPE = np.dtype({
    'names': ['x', 'y', 'z', 'vx', 'vy', 'vz', 'exit_time', 'angle', 'mass', 'id', 'channel'],
    'formats': ['<f8'] * 9 + ['<u4', '<u4'],
    'offsets': [0, 8, 16, 24, 32, 40, 48, 56, 64, 72, 76],
    'itemsize': 80})
EXIT_DATATYPES = [FLOAT64] * 9 + [UINT32, UINT32]


def point_fields(dtype: np.dtype, datatypes: list[int]) -> list[dict[str, Any]]:
    """Return the sensor_msgs/PointField list describing a structured dtype."""
    return [{'name': name, 'offset': dtype.fields[name][1], 'datatype': datatype, 'count': 1}
            for name, datatype in zip(dtype.names, datatypes)]


# --------------------------------------------------------------------------- messages


def stamp(t: float) -> dict[str, int]:
    """Return a builtin_interfaces/Time mapping of t (s), rounded to the nanosecond."""
    ns = int(round(t * 1e9))
    sec, nanosec = divmod(ns, 1_000_000_000)
    return {'sec': sec, 'nanosec': nanosec}


def stamp_ns(t: float) -> int:
    """Return t (s) in integer nanoseconds, rounded as :func:`stamp` rounds."""
    return int(round(t * 1e9))


def header(t: float, frame_id: str) -> dict[str, Any]:
    """Return a std_msgs/Header mapping stamped with t (s)."""
    return {'stamp': stamp(t), 'frame_id': frame_id}


def clock_message(t: float) -> dict[str, Any]:
    """Return a rosgraph_msgs/Clock mapping of t (s)."""
    return {'clock': stamp(t)}


def particles_message(head: dict[str, Any], positions: np.ndarray) -> dict[str, Any]:
    """Return a geometry_msgs/PoseArray of positions (N, 3) with identity orientations."""
    n = positions.shape[0]
    poses = np.zeros((n, 7))
    poses[:, 0:3] = positions
    poses[:, 6] = 1.0
    return {'header': head, 'poses': poses}


def _cloud(head: dict[str, Any], points: np.ndarray, datatypes: list[int]) -> dict[str, Any]:
    step = points.dtype.itemsize
    return {'header': head, 'height': 1, 'width': points.shape[0],
            'fields': point_fields(points.dtype, datatypes), 'is_bigendian': False,
            'point_step': step, 'row_step': step * points.shape[0], 'data': points,
            'is_dense': True}


def states_message(head: dict[str, Any], ids: np.ndarray, positions: np.ndarray,
                   velocities: np.ndarray, masses: np.ndarray) -> dict[str, Any]:
    """Return the particle_states PointCloud2 (layout :data:`STATE_DTYPE`)."""
    points = np.zeros(ids.shape[0], dtype=STATE_DTYPE)
    for i, name in enumerate(('x', 'y', 'z')):
        points[name] = positions[:, i]
        points['v' + name] = velocities[:, i]
    points['id'] = ids & 0xFFFFFFFF
    points['mass'] = masses
    return _cloud(head, points, STATE_DATATYPES)


def exits_message(head: dict[str, Any], exits: ExitEvents) -> dict[str, Any]:
    """Return the exit_events PointCloud2 (layout :data:`EXIT_DTYPE`)."""
    rows = np.zeros(len(exits), dtype=EXIT_DTYPE)
    for i, name in enumerate(('x', 'y', 'z')):
        rows[name] = exits.position[:, i]
        rows['v' + name] = exits.velocity[:, i]
    rows['exit_time'] = exits.t
    rows['angle'] = np.arctan2(exits.position[:, 1], exits.position[:, 0])
    rows['mass'] = exits.mass
    rows['id'] = exits.ids & 0xFFFFFFFF
    rows['channel'] = exits.channel
    return _cloud(head, rows, EXIT_DATATYPES)


def channel_mass_message(channel_mass: np.ndarray) -> dict[str, Any]:
    """Return the std_msgs/Float64MultiArray of the cumulative mass per channel (kg)."""
    count = channel_mass.shape[0]
    return {'layout': {'dim': [{'label': 'channel', 'size': count, 'stride': count}],
                       'data_offset': 0},
            'data': channel_mass}


def cone_state_message(head: dict[str, Any], angle: float, omega: float) -> dict[str, Any]:
    """Return the sensor_msgs/JointState of the cone: angle (rad) and omega (rad/s)."""
    return {'header': head, 'name': ['cone'], 'position': np.array([angle]),
            'velocity': np.array([omega]), 'effort': np.zeros(0)}


# --------------------------------------------------------------------------- markers


def _color(r: float, g: float, b: float, a: float = 1.0) -> dict[str, float]:
    return {'r': r, 'g': g, 'b': b, 'a': a}


class MarkerSchedule:
    """
    When to publish markers: ``rate`` messages per simulated second, and on a reset.

    After a reset the next tick publishes markers as well (:meth:`restart`).
    """

    def __init__(self, rate: float) -> None:
        """Start with no markers published yet."""
        self.rate = float(rate)
        self._last_t = -math.inf

    def due(self, t: float, reset: bool = False) -> bool:
        """Tell whether markers are due at simulation time t (s); if so, count them sent."""
        if self.rate > 0.0 and (t - self._last_t >= 1.0 / self.rate - 1e-9 * t or reset):
            self._last_t = t
            return True
        return False

    def restart(self) -> None:
        """Make the next call of :meth:`due` true (after a reset)."""
        self._last_t = -math.inf


class MarkerBuilder:
    """The visualization_msgs/MarkerArray of the scene: static cone and channels, pieces."""

    def __init__(self, model: ModelParams, frame_id: str, codec: CdrCodec | None = None
                 ) -> None:
        """Build the static markers of the model once."""
        self._model = model
        self._frame = frame_id
        self._codec = codec if codec is not None else default_codec()
        self.static = self._build_static()

    def _marker(self, ns: str, marker_id: int, marker_type: int, **fields: Any
                ) -> dict[str, Any]:
        marker = self._codec.default_message('visualization_msgs/msg/Marker')
        marker['header'] = {'stamp': {'sec': 0, 'nanosec': 0}, 'frame_id': self._frame}
        marker['ns'] = ns
        marker['id'] = marker_id
        marker['type'] = marker_type
        marker['pose']['orientation']['w'] = 1.0
        marker['scale'] = {'x': 1.0, 'y': 1.0, 'z': 1.0}
        marker['color'] = _color(1.0, 1.0, 1.0)
        marker.update(fields)
        return marker

    def _build_static(self) -> list[dict[str, Any]]:
        """Return the cone surface, the channel sectors and their labels."""
        model = self._model
        r, h = model.r, model.h
        segments = 96
        angles = np.linspace(0.0, 2.0 * math.pi, segments + 1)
        tri = np.zeros((segments * 3, 3))
        tri[0::3] = (0.0, 0.0, h)
        tri[1::3, 0] = r * np.cos(angles[:-1])
        tri[1::3, 1] = r * np.sin(angles[:-1])
        tri[2::3, 0] = r * np.cos(angles[1:])
        tri[2::3, 1] = r * np.sin(angles[1:])
        markers = [self._marker('cone', 0, 11, points=tri,  # TRIANGLE_LIST
                                color=_color(0.7, 0.72, 0.75, 0.8))]
        channels = model.channels
        ring = []
        colors = []
        labels = []
        sub = 8
        for channel in range(1, channels.count + 1):
            start, end = (math.radians(a) for a in channels.sector_edges(channel))
            edge = np.linspace(start, end, sub + 1)
            shade = (0.25, 0.55, 0.85, 0.9) if channel % 2 else (0.95, 0.75, 0.2, 0.9)
            for a0, a1 in zip(edge[:-1], edge[1:]):
                inner0 = (r * math.cos(a0), r * math.sin(a0), 0.0)
                inner1 = (r * math.cos(a1), r * math.sin(a1), 0.0)
                outer0 = (1.15 * r * math.cos(a0), 1.15 * r * math.sin(a0), 0.0)
                outer1 = (1.15 * r * math.cos(a1), 1.15 * r * math.sin(a1), 0.0)
                ring += [inner0, outer0, outer1, inner0, outer1, inner1]
                colors += [shade] * 6
            mid = 0.5 * (start + end)
            labels.append(self._marker(
                'channel_labels', channel, 9,  # TEXT_VIEW_FACING
                pose={'position': {'x': 1.25 * r * math.cos(mid), 'y': 1.25 * r * math.sin(mid),
                                   'z': 0.01},
                      'orientation': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}},
                scale={'x': 0.0, 'y': 0.0, 'z': 0.03}, text=str(channel)))
        markers.append(self._marker('channels', 0, 11, points=np.array(ring),
                                    colors=np.array(colors, dtype=np.float32)))
        return markers + labels

    def dynamic(self, head: dict[str, Any], angle: float, positions: np.ndarray
                ) -> list[dict[str, Any]]:
        """Return the pieces and a line that turns with the cone."""
        model = self._model
        c, s = math.cos(angle), math.sin(angle)
        line = np.array([[0.0, 0.0, model.h + 0.002], [model.r * c, model.r * s, 0.002]])
        marker_line = self._marker('cone_angle', 0, 5, header=head,  # LINE_LIST
                                   points=line, scale={'x': 0.004, 'y': 0.0, 'z': 0.0},
                                   color=_color(0.1, 0.1, 0.1))
        size = 2.0 * model.product.s0
        if positions.shape[0]:
            pieces = self._marker('pieces', 0, 7, header=head,  # SPHERE_LIST
                                  points=positions,
                                  scale={'x': size, 'y': size, 'z': size},
                                  color=_color(0.85, 0.25, 0.25))
        else:
            pieces = self._marker('pieces', 0, 7, header=head, action=2)  # DELETE
        return [marker_line, pieces]

    def message(self, head: dict[str, Any], angle: float, positions: np.ndarray
                ) -> dict[str, Any]:
        """Return the whole scene: static markers, pieces and the cone angle line."""
        return {'markers': self.static + self.dynamic(head, angle, positions)}
