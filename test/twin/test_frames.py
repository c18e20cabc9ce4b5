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

"""Tests of cone_feeder_sim.twin.frames: a frame's track ids, measured exits."""

import math

from cone_feeder_sim.errors import TwinError
from cone_feeder_sim.formats.pointcloud import DETECTION_DTYPE, EXIT_DTYPE, NO_TRACK
from cone_feeder_sim.twin.estimator import Twin, TwinSettings
from cone_feeder_sim.twin.frames import detection_frame, measured_exits
import numpy as np
import pytest
from test_twin_live import PARAMS


def frame_of(track_ids: list, dtype: str) -> np.ndarray:
    points = np.zeros(len(track_ids), dtype=[('x', '<f8'), ('y', '<f8'), ('track_id', dtype)])
    points['x'] = 0.05 * np.arange(len(track_ids)) + 0.02
    points['track_id'] = track_ids
    return points


def test_what_is_not_a_track_id_is_none_and_the_detection_is_kept() -> None:
    # a CSV's empty cell (NaN), a fraction, a negative, one beyond uint32, infinity
    found = detection_frame(0.1, frame_of([7, np.nan, 2.5, -1, 2.0 ** 40, np.inf, 0], '<f8'))
    assert found.track_ids.dtype == np.uint32 and len(found.xy) == 7
    assert found.track_ids.tolist() == [7] + [NO_TRACK] * 5 + [0]
    assert detection_frame(0.1, frame_of([np.nan, np.nan], '<f8')).track_ids is None
    points = np.zeros(2, dtype=DETECTION_DTYPE)
    points['track_id'] = [3, NO_TRACK]  # camera_node's: a false detection has none
    assert detection_frame(0.1, points).track_ids.tolist() == [3, NO_TRACK]


def test_a_piece_keeps_its_last_track_id_and_none_is_not_one() -> None:
    twin = Twin(PARAMS, TwinSettings(members=4, sigma=0.001, confirm=1))
    first = detection_frame(1 / 30, frame_of([11, np.nan, 13], '<f8'))
    twin.update(first.t, first.xy, None, first.track_ids)
    assert twin.tracks == {0: 11, 2: 13}  # born with theirs; the second has none yet
    again = detection_frame(2 / 30, frame_of([np.nan, 12, 14], '<f8'))
    twin.update(again.t, again.xy, None, again.track_ids)
    assert twin.tracks == {0: 11, 1: 12, 2: 14}  # none keeps the last; a new one replaces it
    twin._drop([1])
    assert twin.tracks == {0: 11, 2: 14}


def test_measured_exits_are_read_from_sim_node_s_layout_or_a_sensor_s() -> None:
    points = np.zeros(2, dtype=EXIT_DTYPE)  # sim_node's exit_events: the exit_time field
    points['exit_time'], points['channel'] = [0.42, 0.31], [3, 14]
    points['mass'] = [0.05, 0.07]  # and the mass field: weighed
    assert measured_exits(0.5, points, 14) == [(0.31, 14, 0.07), (0.42, 3, 0.05)]
    sensor = np.zeros(1, dtype=[('channel', '<u1')])  # a sensor's: the stamp is the time
    sensor['channel'] = 7
    ((t, channel, mass),) = measured_exits(0.5, sensor, 14)
    assert (t, channel) == (0.5, 7) and math.isnan(mass)  # no mass field: not weighed


@pytest.mark.parametrize(('change', 'fragment'), [
    ({'channel': [3, 15]}, 'a channel not in 1..14'),
    ({'channel': [0, 2]}, 'a channel not in 1..14'),
    ({'channel': [2.5, 2]}, 'a channel not in 1..14'),
    ({'exit_time': [0.1, np.nan]}, 'a time that is not finite'),
    ({'mass': [0.05, 0.0]}, 'a mass that is not a positive number'),
    ({'mass': [-0.05, np.nan]}, 'a mass that is not a positive number'),
    ({'mass': [np.inf, 0.05]}, 'a mass that is not a positive number'),
])
def test_a_bad_message_of_exits_is_refused_whole(change: dict, fragment: str) -> None:
    points = np.zeros(2, dtype=[('exit_time', '<f8'), ('channel', '<f8'), ('mass', '<f8')])
    points['exit_time'], points['channel'], points['mass'] = [0.1, 0.2], [3, 4], [0.05, np.nan]
    for key, value in change.items():
        points[key] = value
    with pytest.raises(TwinError, match=fragment):
        measured_exits(0.5, points, 14)
    with pytest.raises(TwinError, match='no channel field'):
        measured_exits(0.5, np.zeros(1, dtype=[('exit_time', '<f8')]), 14)
    with pytest.raises(TwinError, match='10001 exits'):
        measured_exits(0.5, np.zeros(10_001, dtype=[('channel', '<u4')]), 14)
