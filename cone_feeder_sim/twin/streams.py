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
A twin's streams from an MCAP recording: a PointCloud2 topic's detections, a JointState's speeds.

A recording of ``sim_node`` (or of a camera and an encoder, recorded by rosbag2 in MCAP) is
read as the headless twin's input: each PointCloud2 message of the detections topic is one
frame at its header's stamp (fields x, y and optionally mass), each JointState message of
the cone topic one speed of the joint ``cone``, each PointCloud2 message of the exits topic
the exits measured in it (fields channel and optionally exit_time, else at the header's
stamp, and mass, a load cell's step). Topics default to ``/detections`` (else
``/particle_states``, what sim_node records), ``/cone_state`` and ``/exit_events``. Each
message is decoded and checked as twin_node decodes and checks it, and one it would refuse
is refused whole, its line kept for the run's log: a node's recording run again takes what
the node took.
"""

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .frames import cone_speed, detection_frame, measured_exits
from ..errors import ConeFeederError, TwinError
from ..formats.cdr import decode
from ..formats.mcap_reader import open_recording
from ..formats.messages import stamp_seconds
from ..formats.pointcloud import cloud_points

__all__ = ['mcap_cone', 'mcap_detections', 'mcap_exits']

#: The detections topics tried in turn when none is named.
DETECTION_TOPICS = ('/detections', '/particle_states')


def _recording(path: Path, topic: str | None, defaults: tuple[str, ...], type_name: str) -> tuple:
    try:
        recording = open_recording(path)
    except ConeFeederError as exc:
        raise TwinError(f'{path}: {exc}') from None
    kinds = {name: t.type_name for name, t in recording.topics.items()}
    chosen = topic or next((name for name in defaults if name in kinds), None)
    if chosen is None or kinds.get(chosen) != type_name:
        offered = ', '.join(f'{name} ({kind})' for name, kind in sorted(kinds.items()))
        raise TwinError(f'{path}: no {type_name} topic {chosen or " or ".join(defaults)} '
                        f'(it has {offered or "no topics"})')
    return recording, chosen


def _checked(recording: Any, chosen: str, width: int,
             rows_of: Callable[[float, dict[str, Any]], Any]) -> tuple[np.ndarray, list]:
    """
    Return rows_of(stamp (s), message) over a topic's messages, sorted by t, and the refused.

    rows_of gives a message's rows (of width columns, the first t). A message that does not
    decode, or that rows_of refuses (TwinError: a check of twin_node's), is refused whole:
    (t (s), why) each, t its stamp or, where it does not decode, its log time, why the line
    twin_node logs.
    """
    rows = [np.zeros((0, width))]
    refused = []
    for message in recording.messages({chosen}):
        t = message.log_time_ns / 1e9
        try:
            decoded = decode(message.type_name, message.data, strict=False)
            t = stamp_seconds(decoded['header']['stamp'])
            rows.append(np.asarray(rows_of(t, decoded), dtype=float).reshape(-1, width))
        except (ConeFeederError, ValueError) as exc:  # the node's line, as it logs it
            refused.append((t, str(exc)))
    table = np.concatenate(rows)
    return table[np.argsort(table[:, 0], kind='stable')], refused


def mcap_detections(path: Path, topic: str | None = None) -> tuple[np.ndarray, list]:
    """
    Return the detections (k, 5), sorted by t, and the messages refused (see _checked).

    Columns: t (s), x, y (m), mass (kg), track_id (NaN: not given). Each message is checked
    as twin_node checks a frame (:func:`.frames.detection_frame`: x and y fields, at most
    MAX_DETECTIONS points, finite values), its frame_id aside (a twin file names none).
    """
    recording, chosen = _recording(path, topic, DETECTION_TOPICS, 'sensor_msgs/msg/PointCloud2')

    def rows_of(t: float, cloud: dict[str, Any]) -> np.ndarray:
        found = detection_frame(t, cloud_points(cloud))
        k = len(found.xy)
        return np.column_stack([np.full(k, t), found.xy, *(
            np.full(k, np.nan) if column is None else column
            for column in (found.masses, found.track_ids))])

    return _checked(recording, chosen, 5, rows_of)


def mcap_cone(path: Path, topic: str | None = None,
              joint: str = 'cone') -> tuple[np.ndarray, list]:
    """
    Return the cone's measured speeds (j, 2): t (s), omega (rad/s), sorted, and refusals.

    A message without the joint, or without a finite velocity of it, is refused, as
    twin_node refuses it (:func:`.frames.cone_speed`; see _checked).
    """
    recording, chosen = _recording(path, topic, ('/cone_state',), 'sensor_msgs/msg/JointState')
    return _checked(recording, chosen, 2, lambda t, state: [
        t, cone_speed(t, list(state['name']), list(state['velocity']), joint)])


def mcap_exits(path: Path, channels: int, topic: str | None = None) -> tuple[np.ndarray, list]:
    """
    Return the measured exits (e, 3), sorted by t, and the messages refused (see _checked).

    Columns: t (s), channel (1-based), mass (kg; NaN: not weighed). channels: the layout's
    count. A message is checked as twin_node checks it (:func:`.frames.measured_exits`):
    one with an exit that is not one is refused whole, so that a node's recording run
    again takes the exits the node took.
    """
    recording, chosen = _recording(path, topic, ('/exit_events',), 'sensor_msgs/msg/PointCloud2')
    return _checked(recording, chosen, 3, lambda t, cloud: measured_exits(
        t, cloud_points(cloud), channels))
