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
The live view's messages, in the Foxglove SDK's own schemas (needs ``foxglove-sdk``).

:class:`SceneBuilder` turns a :class:`~cone_feeder_sim.view.snapshot.Snapshot` into one
foxglove.SceneUpdate: the static entity (the cone as a cylinder narrowed to its apex, the
channel sectors as a ring outside the rim, odd and even channels in two colours, their
boundaries and numbers, built once), the mark that turns with the
cone, every piece as a sphere of its outer radius s0 coloured by product, and a line
between every two pieces that touch. All in the frame ``feeder``, lengths in metres.
"""

import math
from typing import Any

from foxglove.messages import (
    Color, CylinderPrimitive, LinePrimitive, LinePrimitiveLineType, Log, LogLevel, Point3,
    Pose, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive, TextPrimitive, Timestamp,
    TriangleListPrimitive, Vector3)
import numpy as np

from .frame import PALETTE
from .snapshot import Event, Snapshot
from .topics import FRAME
from ..formats.messages import (
    channel_mass_message, channel_sectors, cone_state_message, header, hopper_weights_message,
    SECTOR_OUTER, SECTOR_SHADES, stamp)
from ..formats.runlog import to_jsonable
from ..physics.params import ModelParams

__all__ = ['SceneBuilder', 'log_message', 'series_messages', 'timestamp']

_UPRIGHT = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
_CONE = Color(r=0.7, g=0.72, b=0.75, a=0.8)
_BOUNDARY = Color(r=0.35, g=0.35, b=0.35, a=1.0)
_MARK = Color(r=0.1, g=0.1, b=0.1, a=1.0)
_CONTACT = Color(r=0.0, g=0.0, b=0.0, a=1.0)
#: Piece colours by product index (cycled): the top view's palette.
_PIECES = tuple(Color(r=r / 255.0, g=g / 255.0, b=b / 255.0, a=1.0) for r, g, b in PALETTE)


def timestamp(t: float) -> Timestamp:
    """Return t (s) as a Foxglove Timestamp, rounded to the nanosecond as the MCAP stamps."""
    value = stamp(t)
    return Timestamp(sec=value['sec'], nsec=value['nanosec'])


def _pose(x: float, y: float, z: float) -> Pose:
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=_UPRIGHT)


class SceneBuilder:
    """The SceneUpdate of a snapshot, with the static entity of the model built once."""

    def __init__(self, model: ModelParams) -> None:
        """Build the cone, the channel boundaries and their numbers."""
        self._model = model
        r, h = model.r, model.h
        cone = CylinderPrimitive(pose=_pose(0.0, 0.0, 0.5 * h),
                                 size=Vector3(x=2.0 * r, y=2.0 * r, z=h),
                                 bottom_scale=1.0, top_scale=0.0, color=_CONE)
        sectors = channel_sectors(model)
        points = [Point3(x=radius * math.cos(sector.start), y=radius * math.sin(sector.start),
                         z=0.0)
                  for sector in sectors for radius in (r, SECTOR_OUTER * r)]
        texts = [TextPrimitive(pose=_pose(*sector.label), billboard=True, font_size=0.03,
                               scale_invariant=False, color=_MARK, text=str(sector.channel))
                 for sector in sectors]
        rings = []  # odd and even channels, one primitive each
        for red, green, blue, alpha in SECTOR_SHADES:
            ring = np.concatenate([sector.ring for sector in sectors
                                   if sector.shade == (red, green, blue, alpha)])
            rings.append(TriangleListPrimitive(
                pose=_pose(0, 0, 0), color=Color(r=red, g=green, b=blue, a=alpha),
                points=[Point3(x=x, y=y, z=z) for x, y, z in ring.tolist()]))
        boundaries = LinePrimitive(type=LinePrimitiveLineType.LineList, pose=_pose(0, 0, 0),
                                   thickness=0.003, scale_invariant=False, points=points,
                                   color=_BOUNDARY)
        self._static = (cone, boundaries, texts, rings)

    def update(self, snapshot: Snapshot) -> SceneUpdate:
        """Return the scene at the snapshot: static entity, mark, pieces, contacts."""
        model = self._model
        when = timestamp(snapshot.t)
        cone, boundaries, texts, rings = self._static
        c, s = math.cos(snapshot.angle), math.sin(snapshot.angle)
        mark = LinePrimitive(type=LinePrimitiveLineType.LineStrip, pose=_pose(0, 0, 0),
                             thickness=0.004, scale_invariant=False, color=_MARK,
                             points=[Point3(x=0.0, y=0.0, z=model.h + 0.002),
                                     Point3(x=model.r * c, y=model.r * s, z=0.002)])
        feeder = SceneEntity(timestamp=when, frame_id=FRAME, id='feeder', cylinders=[cone],
                             lines=[boundaries, mark], texts=texts, triangles=rings)
        spheres = [SpherePrimitive(pose=_pose(x, y, z), size=Vector3(x=d, y=d, z=d),
                                   color=_PIECES[kind % len(_PIECES)])
                   for (x, y, z), d, kind in zip(snapshot.positions.tolist(),
                                                 (2.0 * snapshot.radii).tolist(),
                                                 snapshot.kinds.tolist())]
        pieces = SceneEntity(timestamp=when, frame_id=FRAME, id='pieces', spheres=spheres)
        ends = snapshot.positions[snapshot.contacts.reshape(-1)].tolist()
        contacts = SceneEntity(
            timestamp=when, frame_id=FRAME, id='contacts',
            lines=[LinePrimitive(type=LinePrimitiveLineType.LineList, pose=_pose(0, 0, 0),
                                 thickness=0.003, scale_invariant=False, color=_CONTACT,
                                 points=[Point3(x=x, y=y, z=z) for x, y, z in ends])]
            if ends else [])
        return SceneUpdate(entities=[feeder, pieces, contacts])


def series_messages(snapshot: Snapshot) -> dict[str, dict[str, Any]]:
    """Return the JSON messages of the time series, by view topic key (the node's fields)."""
    messages = {
        'cone_state': cone_state_message(header(snapshot.t, FRAME), snapshot.angle,
                                         snapshot.omega),
        'channel_mass': channel_mass_message(snapshot.channel_mass)}
    if snapshot.hoppers is not None:
        messages['hopper_weights'] = hopper_weights_message(snapshot.hoppers)
    return {key: to_jsonable(message) for key, message in messages.items()}


def log_message(event: Event) -> Log:
    """Return the foxglove.Log line of an exit or a pack."""
    return Log(timestamp=timestamp(event.t), level=LogLevel.Info, message=event.text,
               name=f'cone_feeder_sim/{event.kind}', file='', line=0)
