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
Tests of cone_feeder_sim.formats.pointcloud: the point layouts and the cloud parser.

The expected layouts are written out here from the documented ones (doc/sim_node.md), not
taken from the module.
"""

from cone_feeder_sim.errors import MessageError
from cone_feeder_sim.formats.pointcloud import (
    cloud_points, DETECTION_DTYPE, EXIT_DTYPE, point_dtype, point_fields, STATE_DTYPE,
    TWIN_PIECE_DTYPE)
import numpy as np
from point_layouts import EXIT_FIELDS, FLOAT32, FLOAT64, STATE_FIELDS, UINT32
import pytest


def field_dicts(fields: list[tuple[str, int, int]]) -> list[dict]:
    return [{'name': n, 'offset': o, 'datatype': d, 'count': 1} for n, o, d in fields]


def test_layouts_are_the_documented_ones() -> None:
    assert list(point_fields(STATE_DTYPE)) == field_dicts(STATE_FIELDS)
    assert list(point_fields(EXIT_DTYPE)) == field_dicts(EXIT_FIELDS)
    assert (STATE_DTYPE.itemsize, EXIT_DTYPE.itemsize) == (32, 80)
    # the twin's: twin/pieces (44 bytes) and camera_node's detections (16 bytes)
    assert list(point_fields(TWIN_PIECE_DTYPE)) == field_dicts(
        [('x', 0, FLOAT32), ('y', 4, FLOAT32), ('z', 8, FLOAT32), ('id', 12, UINT32),
         ('mass', 16, FLOAT32), ('sigma_x', 20, FLOAT32), ('sigma_y', 24, FLOAT32),
         ('channel', 28, UINT32), ('probability', 32, FLOAT32), ('time_to_exit', 36, FLOAT32),
         ('track_id', 40, UINT32)])
    assert list(point_fields(DETECTION_DTYPE)) == field_dicts(
        [('x', 0, FLOAT32), ('y', 4, FLOAT32), ('z', 8, FLOAT32), ('track_id', 12, UINT32)])
    assert (TWIN_PIECE_DTYPE.itemsize, DETECTION_DTYPE.itemsize) == (44, 16)


def test_point_dtype_reads_the_fields_back() -> None:
    assert point_dtype(field_dicts(STATE_FIELDS), 32) == STATE_DTYPE
    assert point_dtype(field_dicts(EXIT_FIELDS), 80) == EXIT_DTYPE
    big = point_dtype([{'name': 'v', 'offset': 0, 'datatype': FLOAT64, 'count': 1}], 8, True)
    assert big['v'] == np.dtype('>f8')
    with pytest.raises(MessageError, match='does not fit'):
        point_dtype([{'name': 'v', 'offset': 4, 'datatype': FLOAT64, 'count': 1}], 8)
    with pytest.raises(MessageError, match='unknown datatype'):
        point_dtype([{'name': 'v', 'offset': 0, 'datatype': 9, 'count': 1}], 8)


def test_cloud_points_handles_rows_with_padding() -> None:
    points = np.zeros(4, dtype=STATE_DTYPE)
    points['id'] = [7, 8, 9, 10]
    points['x'] = np.arange(4.0)
    message = {'height': 1, 'width': 4, 'fields': field_dicts(STATE_FIELDS),
               'is_bigendian': False, 'point_step': 32, 'row_step': 128, 'data': points,
               'is_dense': True}
    np.testing.assert_array_equal(cloud_points(message), points)
    raw = points.tobytes()
    padded = raw[:64] + b'\xff' * 8 + raw[64:] + b'\xff' * 8  # 2 rows of 2, row_step 72
    message.update(height=2, width=2, row_step=72, data=padded)
    np.testing.assert_array_equal(cloud_points(message), points)
    message.update(data=padded[:100])
    with pytest.raises(MessageError, match='do not fit'):
        cloud_points(message)
