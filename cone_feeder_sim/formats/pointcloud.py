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
sensor_msgs/PointCloud2 layouts: the simulator's point types and the one cloud parser.

:data:`POINT_FIELD_TYPES` is the PointField datatype table; the simulator's layouts
(:data:`STATE_DTYPE` of ``particle_states``, :data:`EXIT_DTYPE` of ``exit_events``) are numpy
dtypes, and their PointField lists are derived from them. :func:`cloud_points` reads any
cloud (decoded mapping or rclpy message) back into a structured array.
"""

from collections.abc import Mapping, Sequence
import functools
from typing import Any

import numpy as np

from ..errors import MessageError

__all__ = ['DETECTION_DTYPE', 'EXIT_DTYPE', 'NO_TRACK', 'PACK_DTYPE', 'POINT_FIELD_TYPES',
           'STATE_DTYPE', 'TWIN_PIECE_DTYPE', 'cloud_points', 'point_dtype', 'point_fields']

#: sensor_msgs/PointField datatypes -> numpy type codes (without byte order).
POINT_FIELD_TYPES = {1: 'i1', 2: 'u1', 3: 'i2', 4: 'u2', 5: 'i4', 6: 'u4', 7: 'f4', 8: 'f8'}
_DATATYPE_OF_CODE = {code: datatype for datatype, code in POINT_FIELD_TYPES.items()}

#: ``particle_states`` points: position (m), velocity (m/s), id, mass (kg); 32 bytes.
STATE_DTYPE = np.dtype({
    'names': ['x', 'y', 'z', 'vx', 'vy', 'vz', 'id', 'mass'],
    'formats': ['<f4'] * 6 + ['<u4', '<f4'],
    'offsets': [0, 4, 8, 12, 16, 20, 24, 28],
    'itemsize': 32})

#: ``exit_events`` points: position (m) and velocity (m/s) at the rim, exit_time (s),
#: angle (rad, atan2(y, x) in (-pi, pi]), mass (kg), id, channel (1-based); 80 bytes.
EXIT_DTYPE = np.dtype({
    'names': ['x', 'y', 'z', 'vx', 'vy', 'vz', 'exit_time', 'angle', 'mass', 'id', 'channel'],
    'formats': ['<f8'] * 9 + ['<u4', '<u4'],
    'offsets': [0, 8, 16, 24, 32, 40, 48, 56, 64, 72, 76],
    'itemsize': 80})


#: ``detections`` points as ``camera_node`` publishes them (twin_node's input; a camera's may
#: have fewer or more fields): position (m), track_id; 16 bytes.
DETECTION_DTYPE = np.dtype({
    'names': ['x', 'y', 'z', 'track_id'],
    'formats': ['<f4', '<f4', '<f4', '<u4'],
    'offsets': [0, 4, 8, 12],
    'itemsize': 16})


#: ``twin/pieces`` points: the twin's estimate of each piece: position (m; z on the cone's
#: surface), id, mass (kg), sigma_x, sigma_y (m, the members' spread), the most likely
#: channel (0: it stays on the cone over the longest horizon), its probability and the
#: expected time to the exit (s from the stamp; NaN where no member lets it leave), the
#: camera's track id last associated with it (:data:`NO_TRACK`: none given); 44 bytes.
TWIN_PIECE_DTYPE = np.dtype({
    'names': ['x', 'y', 'z', 'id', 'mass', 'sigma_x', 'sigma_y', 'channel', 'probability',
              'time_to_exit', 'track_id'],
    'formats': ['<f4'] * 3 + ['<u4'] + ['<f4'] * 3 + ['<u4'] + ['<f4'] * 2 + ['<u4'],
    'offsets': [0, 4, 8, 12, 16, 20, 24, 28, 32, 36, 40],
    'itemsize': 44})
#: ``twin/pieces``' track_id of a piece no frame gave a track id for.
NO_TRACK = 0xFFFFFFFF

#: ``pack_events`` points: t (s, discharge time), mass (kg, true), measured (kg, the load
#: cells' sum), giveaway (kg), pack (index from 1), heads (bit h-1 set: head h discharged);
#: 40 bytes.
PACK_DTYPE = np.dtype({
    'names': ['t', 'mass', 'measured', 'giveaway', 'pack', 'heads'],
    'formats': ['<f8'] * 4 + ['<u4', '<u4'],
    'offsets': [0, 8, 16, 24, 32, 36],
    'itemsize': 40})


@functools.cache
def point_fields(dtype: np.dtype) -> tuple[dict[str, Any], ...]:
    """Return the PointField list of a little-endian structured dtype (shared: do not modify)."""
    fields = []
    for name in dtype.names:
        field_dtype, offset = dtype.fields[name][:2]
        code = field_dtype.base.str.lstrip('<>|=')
        fields.append({'name': name, 'offset': offset, 'datatype': _DATATYPE_OF_CODE[code],
                       'count': max(1, field_dtype.shape[0] if field_dtype.shape else 1)})
    return tuple(fields)


@functools.lru_cache(maxsize=64)
def _cached_point_dtype(
    fields: tuple[tuple[str, int, int, int], ...], point_step: int, big_endian: bool
) -> np.dtype:
    order = '>' if big_endian else '<'
    names, formats, offsets = [], [], []
    for name, offset, datatype, count in fields:
        code = POINT_FIELD_TYPES.get(datatype)
        if code is None:
            raise MessageError(f'point field {name!r} has unknown datatype {datatype}')
        if name in names:
            raise MessageError(f'point field {name!r} appears twice')
        size = np.dtype(code).itemsize * max(count, 1)
        if offset < 0 or offset + size > point_step:
            raise MessageError(
                f'point field {name!r} (offset {offset}, {size} bytes) does not fit in '
                f'point_step {point_step}')
        names.append(name)
        formats.append((order + code, (count,)) if count > 1 else order + code)
        offsets.append(offset)
    return np.dtype({'names': names, 'formats': formats, 'offsets': offsets,
                     'itemsize': point_step})


def point_dtype(
    fields: Sequence[Mapping[str, Any]], point_step: int,
    big_endian: bool = False
) -> np.dtype:
    """
    Return the structured dtype of PointCloud2 points from its ``fields``.

    ``fields`` are sensor_msgs/PointField mappings (``name``, ``offset``,
    ``datatype``, ``count``); the dtype's itemsize is ``point_step``.
    """
    key = tuple((str(f['name']), int(f['offset']), int(f['datatype']), int(f['count']))
                for f in fields)
    return _cached_point_dtype(key, int(point_step), bool(big_endian))


def cloud_points(cloud: Any) -> np.ndarray:
    """
    Return the points of a PointCloud2 as a structured array, shape (n,).

    ``cloud`` is a decoded message (a mapping, as the CDR codec returns it) or an rclpy
    ``sensor_msgs.msg.PointCloud2``. ``n = width * height``; rows are concatenated. The
    array is a read-only view of ``data`` when the rows are contiguous.
    """
    get = cloud.__getitem__ if isinstance(cloud, Mapping) else functools.partial(getattr, cloud)
    fields = [field if isinstance(field, Mapping) else
              {key: getattr(field, key) for key in ('name', 'offset', 'datatype', 'count')}
              for field in get('fields')]
    dtype = point_dtype(fields, get('point_step'), get('is_bigendian'))
    width, height = int(get('width')), int(get('height'))
    row_step = int(get('row_step'))
    raw = get('data')
    if isinstance(raw, np.ndarray):  # an encodable message rather than a decoded one
        data = np.ascontiguousarray(raw).reshape(-1).view(np.uint8)
    elif isinstance(raw, (bytes, bytearray, memoryview)):
        data = np.frombuffer(raw, dtype=np.uint8)
    else:  # rclpy's array('B') or a list of ints
        data = np.frombuffer(bytes(raw), dtype=np.uint8)
    count = width * height
    if count == 0:
        return np.zeros(0, dtype=dtype)
    row_bytes = width * dtype.itemsize
    if height == 1 or row_step == row_bytes:
        needed = (height - 1) * row_step + row_bytes
        if data.nbytes < needed:
            raise MessageError(f'PointCloud2 data has {data.nbytes} bytes, {needed} needed')
        return np.frombuffer(data, dtype=dtype, count=count)
    if row_step < row_bytes or data.nbytes < (height - 1) * row_step + row_bytes:
        raise MessageError(
            f'PointCloud2 rows do not fit: row_step {row_step}, {data.nbytes} bytes of data')
    return np.concatenate([
        np.frombuffer(data, dtype=dtype, count=width, offset=row * row_step)
        for row in range(height)])
