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

Both the ROS 2 node (:mod:`cone_feeder_sim.ros.sim_node`) and the headless runner's MCAP output
(``cone-feeder-sim run ... --mcap``) build their messages here, so a live run and a batch
run carry the same messages (topics and QoS: :mod:`cone_feeder_sim.formats.topics`; point
layouts: :mod:`cone_feeder_sim.formats.pointcloud`). Messages are plain mappings that
:mod:`cone_feeder_sim.formats.cdr` encodes; arrays are numpy arrays.
"""

from dataclasses import dataclass
import math
from typing import Any, TYPE_CHECKING

import numpy as np

from .cdr import CdrCodec, CdrError, default_codec
from .pointcloud import EXIT_DTYPE, PACK_DTYPE, point_fields, STATE_DTYPE
from ..physics.params import ModelParams
from ..physics.simulation import ExitEvents
from ..weigher.machine import Pack

if TYPE_CHECKING:
    from ..feeder.engine import TickResult

__all__ = [
    'pose_array_positions',
    'ChannelSector',
    'channel_sectors',
    'MarkerBuilder',
    'MarkerSchedule',
    'channel_mass_message',
    'clock_message',
    'cloud_message',
    'cone_state_message',
    'exits_message',
    'header',
    'hopper_weights_message',
    'packs_message',
    'particles_message',
    'stamp',
    'stamp_ns',
    'stamp_seconds',
    'states_message',
    'TickMessages',
    'TickView',
]

# --------------------------------------------------------------------------- messages


def stamp(t: float) -> dict[str, int]:
    """Return a builtin_interfaces/Time mapping of t (s), rounded to the nanosecond."""
    ns = int(round(t * 1e9))
    sec, nanosec = divmod(ns, 1_000_000_000)
    return {'sec': sec, 'nanosec': nanosec}


def stamp_ns(t: float) -> int:
    """Return t (s) in integer nanoseconds, rounded as :func:`stamp` rounds."""
    return int(round(t * 1e9))


def stamp_seconds(value: dict[str, int]) -> float:
    """Return a builtin_interfaces/Time mapping (sec, nanosec) in seconds."""
    return value['sec'] + value['nanosec'] * 1e-9


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


def cloud_message(head: dict[str, Any], points: np.ndarray) -> dict[str, Any]:
    """Return a sensor_msgs/PointCloud2 of a structured array of points (one row)."""
    step = points.dtype.itemsize
    return {'header': head, 'height': 1, 'width': points.shape[0],
            'fields': point_fields(points.dtype), 'is_bigendian': False,
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
    return cloud_message(head, points)


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
    return cloud_message(head, rows)


def packs_message(head: dict[str, Any], packs: tuple[Pack, ...]) -> dict[str, Any]:
    """Return the pack_events PointCloud2 (layout :data:`PACK_DTYPE`)."""
    rows = np.zeros(len(packs), dtype=PACK_DTYPE)
    for i, pack in enumerate(packs):
        rows[i] = (pack.t, pack.mass, pack.measured, pack.giveaway, pack.index,
                   sum(1 << (h - 1) for h in pack.heads))
    return cloud_message(head, rows)


def hopper_weights_message(readings: np.ndarray) -> dict[str, Any]:
    """Return the std_msgs/Float64MultiArray of the weigh hoppers' readings (kg; 0: none)."""
    count = readings.shape[0]
    return {'layout': {'dim': [{'label': 'head', 'size': count, 'stride': count}],
                       'data_offset': 0},
            'data': readings}


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


#: CDR encapsulation headers (little and big endian, XCDR1 and XCDR2 plain).
_LITTLE_ENDIAN = (b'\x00\x01', b'\x00\x07')
_BIG_ENDIAN = (b'\x00\x00', b'\x00\x06')
#: float64 per geometry_msgs/Pose: position x, y, z, orientation x, y, z, w.
_POSE_FLOATS = 7


def pose_array_positions(data: bytes) -> tuple[str, np.ndarray]:
    """
    Return the frame_id and the positions (M, 3) (m) of a serialized PoseArray.

    Reads the CDR bytes directly with numpy (no per-pose Python objects), so a message of a
    million poses takes milliseconds; orientations are not read. Raises CdrError for
    bytes that are not a complete PoseArray.
    """
    view = memoryview(data)
    if len(view) < 16:
        raise CdrError(f'a PoseArray needs at least 16 bytes, got {len(view)}')
    kind = bytes(view[:2])
    if kind not in _LITTLE_ENDIAN + _BIG_ENDIAN:
        raise CdrError(f'unknown CDR encapsulation {kind.hex()}')
    order = '<' if kind in _LITTLE_ENDIAN else '>'
    body = view[4:]
    (length,) = np.frombuffer(body, dtype=f'{order}u4', count=1, offset=8)
    pos = 12 + int(length)
    if length == 0 or pos > len(body):
        raise CdrError(f'PoseArray frame_id of {int(length)} bytes does not fit in the message')
    frame_id = bytes(body[12:pos - 1]).decode('utf-8', errors='replace')
    pos = (pos + 3) & ~3
    if pos + 4 > len(body):
        raise CdrError('PoseArray ends before its pose count')
    (count,) = np.frombuffer(body, dtype=f'{order}u4', count=1, offset=pos)
    if count == 0:
        return frame_id, np.zeros((0, 3))
    pos = (pos + 4 + 7) & ~7
    need = pos + int(count) * _POSE_FLOATS * 8
    if need > len(body):
        raise CdrError(f'PoseArray says {int(count)} poses but holds {len(body) - pos} bytes '
                       'for them')
    poses = np.frombuffer(body, dtype=f'{order}f8', count=int(count) * _POSE_FLOATS,
                          offset=pos).reshape(-1, _POSE_FLOATS)
    return frame_id, poses[:, :3].astype(np.float64)


def _color(r: float, g: float, b: float, a: float = 1.0) -> dict[str, float]:
    return {'r': r, 'g': g, 'b': b, 'a': a}


#: The channel sectors drawn outside the rim: ring from the rim to OUTER * r, numbers at
#: LABEL * r; odd and even channels' colours (RGBA).
SECTOR_OUTER = 1.15
SECTOR_LABEL = 1.25
SECTOR_SHADES = ((0.25, 0.55, 0.85, 0.9), (0.95, 0.75, 0.2, 0.9))


@dataclass(frozen=True)
class ChannelSector:
    """
    One channel's sector as the viewers draw it (the node's markers, the live view).

    channel (1-based); start (rad) its first edge; ring (parts * 6, 3) m the triangles of the
    ring outside the rim; label (3,) m where its number goes; shade (RGBA) its colour.
    """

    channel: int
    start: float
    ring: np.ndarray
    label: tuple[float, float, float]
    shade: tuple[float, float, float, float]


def channel_sectors(model: ModelParams, parts: int = 8) -> list[ChannelSector]:
    """Return the sector of every channel, in channel order, each ring cut into parts."""
    r = model.r
    sectors = []
    for channel in range(1, model.channels.count + 1):
        start, end = (math.radians(a) for a in model.channels.sector_edges(channel))
        edge = np.linspace(start, end, parts + 1)
        ring = []
        for a0, a1 in zip(edge[:-1], edge[1:]):
            inner0 = (r * math.cos(a0), r * math.sin(a0), 0.0)
            inner1 = (r * math.cos(a1), r * math.sin(a1), 0.0)
            outer0 = (SECTOR_OUTER * r * math.cos(a0), SECTOR_OUTER * r * math.sin(a0), 0.0)
            outer1 = (SECTOR_OUTER * r * math.cos(a1), SECTOR_OUTER * r * math.sin(a1), 0.0)
            ring += [inner0, outer0, outer1, inner0, outer1, inner1]
        mid = 0.5 * (start + end)
        sectors.append(ChannelSector(
            channel=channel, start=start, ring=np.array(ring),
            label=(SECTOR_LABEL * r * math.cos(mid), SECTOR_LABEL * r * math.sin(mid), 0.01),
            shade=SECTOR_SHADES[0 if channel % 2 else 1]))
    return sectors


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
        sectors = channel_sectors(model)
        labels = [self._marker(
            'channel_labels', sector.channel, 9,  # TEXT_VIEW_FACING
            pose={'position': dict(zip('xyz', sector.label)),
                  'orientation': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}},
            scale={'x': 0.0, 'y': 0.0, 'z': 0.03}, text=str(sector.channel))
            for sector in sectors]
        ring = np.concatenate([sector.ring for sector in sectors])
        colors = np.array([sector.shade for sector in sectors
                           for _ in range(sector.ring.shape[0])], dtype=np.float32)
        markers.append(self._marker('channels', 0, 11, points=ring, colors=colors))
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


# --------------------------------------------------------------------------- a tick


@dataclass(frozen=True)
class TickView:
    """
    What a tick shows, for a caller without a TickResult (the headless runner).

    t (s) the end of the tick; ids (N,), positions (N, 3) (m), velocities (N, 3) (m/s),
    masses (N,) (kg) of the pieces at t, world frame; exits during the tick; channel_mass
    (channels,) cumulative kg; angle (rad) and omega (rad/s) of the cone; hoppers (heads,)
    kg or None without a weigher; packs made in the tick; reset: whether it began with one.
    """

    t: float
    ids: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    masses: np.ndarray
    exits: ExitEvents
    channel_mass: np.ndarray
    angle: float
    omega: float
    hoppers: np.ndarray | None = None
    packs: tuple[Pack, ...] = ()
    reset: bool = False


class TickMessages:
    """
    The messages of one tick, in the order they are published: one builder for all.

    The ROS node publishes them and the headless runner writes them to MCAP, so a live run
    and a batch run carry the same messages in the same order. Calling it with a tick
    returns ``(table topic, message)`` pairs: ``/clock`` (with ``clock``), particles,
    particle_states, exit_events (ticks with exits), channel_mass, cone_state,
    hopper_weights (with a weigher), pack_events (ticks with packs), markers (``schedule``:
    ``markers_rate`` per simulated second, on a reset and the tick after it).
    """

    def __init__(self, model: ModelParams, frame_id: str, markers_rate: float, *,
                 clock: bool = False, codec: CdrCodec | None = None) -> None:
        """Build the static markers once; no markers sent yet."""
        self.frame_id = frame_id
        self.clock = clock
        self.schedule = MarkerSchedule(markers_rate)
        self._markers = MarkerBuilder(model, frame_id, codec)

    def __call__(self, tick: 'TickView | TickResult') -> list[tuple[str, dict[str, Any]]]:
        """Return the tick's messages in publishing order (a TickResult has the same fields)."""
        head = header(tick.t, self.frame_id)
        out: list[tuple[str, dict[str, Any]]] = []
        if self.clock:
            out.append(('/clock', clock_message(tick.t)))
        out.append(('particles', particles_message(head, tick.positions)))
        out.append(('particle_states', states_message(
            head, tick.ids, tick.positions, tick.velocities, tick.masses)))
        if len(tick.exits):
            out.append(('exit_events', exits_message(head, tick.exits)))
        out.append(('channel_mass', channel_mass_message(tick.channel_mass)))
        out.append(('cone_state', cone_state_message(head, tick.angle, tick.omega)))
        if tick.hoppers is not None:
            out.append(('hopper_weights', hopper_weights_message(tick.hoppers)))
        if tick.packs:
            out.append(('pack_events', packs_message(head, tuple(tick.packs))))
        if self.schedule.due(tick.t, tick.reset):
            out.append(('markers', self._markers.message(head, tick.angle, tick.positions)))
        if tick.reset:
            self.schedule.restart()
        return out
