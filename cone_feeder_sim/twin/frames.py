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
What the twin accepts as a frame of detections and as a cone speed: the checks, written once.

Both the headless twin (:mod:`.run`) and ``twin_node`` pass their inputs through these
functions; a refused input raises :class:`~..errors.TwinError` with one line that names the
problem, and the caller logs it and goes on.
"""

from dataclasses import dataclass
import math

import numpy as np

from ..errors import TwinError
from ..formats.pointcloud import NO_TRACK

__all__ = ['cone_speed', 'DetectionFrame', 'detection_frame', 'MAX_DETECTIONS',
           'MAX_FUTURE', 'measured_exits', 'not_ahead']

#: The most detections a frame may hold; a larger frame is refused.
MAX_DETECTIONS = 10_000
#: How far (s) a stamp may be ahead of the newest input's stamp plus the wall time since.
MAX_FUTURE = 1.0


@dataclass(frozen=True)
class DetectionFrame:
    """
    One accepted frame: t (s); xy (k, 2) positions in the feeder frame (m).

    masses: (k,) kg (NaN: not given) or None (none given): the product's mean mass;
    track_ids: (k,) uint32 (NO_TRACK: not given) or None (none given).
    """

    t: float
    xy: np.ndarray
    masses: np.ndarray | None
    track_ids: np.ndarray | None


def detection_frame(t: float, points: np.ndarray, frame_id: str = 'feeder',
                    expected_frame: str = 'feeder',
                    latest: float | None = None) -> DetectionFrame:
    """
    Check a frame of detections and return it; raise TwinError naming what is wrong.

    points: a structured array with fields x, y (m) and optionally z, track_id, mass (a
    PointCloud2's points, or the rows of a CSV frame); frame_id: the frame it is in;
    latest: the newest stamp accepted so far plus the wall time since (s), None: no check
    of a stamp from the future.
    """
    names = points.dtype.names or ()
    if frame_id != expected_frame:
        raise TwinError(f'frame at t = {t:.4f} s refused: frame_id {frame_id!r}, not '
                        f'{expected_frame!r}')
    if not math.isfinite(t):
        raise TwinError(f'frame refused: its stamp {t} is not finite')
    not_ahead('frame', t, latest)
    if 'x' not in names or 'y' not in names:
        raise TwinError(f'frame at t = {t:.4f} s refused: no x and y fields (it has '
                        f'{", ".join(names) or "none"})')
    if len(points) > MAX_DETECTIONS:
        raise TwinError(f'frame at t = {t:.4f} s refused: {len(points)} detections, more than '
                        f'{MAX_DETECTIONS}')
    xy = np.column_stack([points['x'], points['y']]).astype(float)
    if not np.isfinite(xy).all():
        raise TwinError(f'frame at t = {t:.4f} s refused: a detection is not finite')
    masses = None
    if 'mass' in names:
        masses = np.asarray(points['mass'], dtype=float)
        given = ~np.isnan(masses)  # NaN: not given, the product's mean mass
        if not given.any():
            masses = None
        elif not (np.isfinite(masses[given]).all() and (masses[given] > 0.0).all()):
            raise TwinError(f'frame at t = {t:.4f} s refused: a mass that is not a positive '
                            f'number')
    track_ids = _track_ids(points['track_id']) if 'track_id' in names else None
    return DetectionFrame(t=float(t), xy=xy, masses=masses, track_ids=track_ids)


def _track_ids(values: np.ndarray) -> np.ndarray | None:
    """
    Return a frame's track ids as uint32, NO_TRACK where a value is not one; None: none is.

    A track id is an integer in [0, NO_TRACK); NaN (a CSV's empty cell), a fraction or a
    value out of that range is no track id (the detection is taken, without one).
    """
    values = np.asarray(values)
    if values.dtype.kind in 'ui':
        wide = values.astype(np.int64)
        valid = (wide >= 0) & (wide < NO_TRACK)
    else:
        wide = np.asarray(values, dtype=float)
        valid = np.isfinite(wide) & (wide >= 0.0) & (wide < NO_TRACK) & (wide == np.floor(wide))
    if not valid.any():
        return None
    ids = np.full(len(wide), NO_TRACK, dtype=np.uint32)
    ids[valid] = wide[valid]
    return ids


def not_ahead(what: str, t: float, latest: float | None) -> None:
    """
    Raise TwinError if an input's stamp t (s) is from the future.

    latest: the newest stamp accepted so far plus the wall time since (s), None: no check.
    """
    if latest is not None and t > latest + MAX_FUTURE:
        raise TwinError(f'{what} at t = {t:.4f} s refused: a stamp from the future '
                        f'({t - latest:.3f} s ahead of the newest input)')


def measured_exits(t: float, points: np.ndarray,
                   channels: int) -> list[tuple[float, int, float]]:
    """
    Check a message of measured exits and return them: (t (s), channel, mass (kg)) each.

    points: a structured array with a field channel (1-based), optionally exit_time (s;
    else each exit is at the stamp t) and mass (kg, a load cell's step; NaN or no field:
    not weighed), as sim_node's ``exit_events`` (a channel's sensors may send fewer
    fields); channels: the layout's count. Raises TwinError naming what is wrong; the
    message is then taken whole or not at all.
    """
    names = points.dtype.names or ()
    if 'channel' not in names:
        raise TwinError(f'exits at t = {t:.4f} s refused: no channel field (it has '
                        f'{", ".join(names) or "none"})')
    if len(points) > MAX_DETECTIONS:
        raise TwinError(f'exits at t = {t:.4f} s refused: {len(points)} exits, more than '
                        f'{MAX_DETECTIONS}')
    times = (np.asarray(points['exit_time'], dtype=float) if 'exit_time' in names
             else np.full(len(points), float(t)))
    channel = np.asarray(points['channel'], dtype=float)
    mass = (np.asarray(points['mass'], dtype=float) if 'mass' in names
            else np.full(len(points), np.nan))
    if not (np.isfinite(times).all() and np.isfinite(t)):
        raise TwinError(f'exits at t = {t:.4f} s refused: a time that is not finite')
    if not np.all((channel == np.floor(channel)) & (channel >= 1) & (channel <= channels)):
        raise TwinError(f'exits at t = {t:.4f} s refused: a channel not in 1..{channels}')
    weighed = ~np.isnan(mass)
    if not (np.isfinite(mass[weighed]).all() and (mass[weighed] > 0.0).all()):
        raise TwinError(f'exits at t = {t:.4f} s refused: a mass that is not a positive '
                        f'number (kg; NaN: not weighed)')
    return sorted(zip(times.tolist(), channel.astype(int).tolist(), mass.tolist()))


def cone_speed(t: float, names: list[str], velocities: list[float],
               joint: str = 'cone') -> float:
    """Return the joint's speed (rad/s) from a JointState's names and velocities."""
    if joint not in names:
        raise TwinError(f'cone speed at t = {t:.4f} s refused: no joint {joint!r} (joints: '
                        f'{", ".join(map(repr, names)) or "none"})')
    k = names.index(joint)
    if k >= len(velocities) or not math.isfinite(velocities[k]):
        raise TwinError(f'cone speed at t = {t:.4f} s refused: joint {joint!r} has no finite '
                        f'velocity')
    return float(velocities[k])
