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
Tests of the CDR encoder/decoder against hand-computed bytes, rosbags and rclpy.

rosbags (``rosbags.typesys``) is an independent pure-Python CDR implementation;
rclpy (when importable) is the real rmw_fastrtps serializer.
"""

import array
import copy
import importlib
import types
from typing import Any

from cone_feeder_sim.formats.cdr import (
    CdrCodec, CdrError, decode, default_codec, default_message, encode)
from cone_feeder_sim.formats.msgtypes import MessageRegistry, registry_from_schema
from msg_compare import normalize
import numpy as np
import pytest
from rosbags.typesys import get_types_from_msg, get_typestore
from rosbags.typesys.stores import Stores

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def header(frame_id: str, sec: int = 1_700_000_000, nanosec: int = 123_456_789) -> dict:
    return {'stamp': {'sec': sec, 'nanosec': nanosec}, 'frame_id': frame_id}


def pose(x: float, w: float = 1.0) -> dict:
    return {
        'position': {'x': x, 'y': -x, 'z': 0.25},
        'orientation': {'x': 0.0, 'y': 0.5, 'z': -0.5, 'w': w},
    }


def marker(**overrides: Any) -> dict:
    result = default_message('visualization_msgs/msg/Marker')
    result.update(overrides)
    return result


def sample_messages() -> dict:
    """Return non-trivial messages of every type the package records."""
    rng = np.random.default_rng(7)
    cloud = rng.integers(0, 256, size=4 * 16, dtype=np.uint8)
    return {
        'std_msgs/msg/Float64': {'data': -1.5e300},
        'std_msgs/msg/Float64MultiArray': {
            'layout': {
                'dim': [
                    {'label': 'hö', 'size': 2, 'stride': 6},
                    {'label': 'width', 'size': 3, 'stride': 3},
                ],
                'data_offset': 1,
            },
            'data': np.array([0.5, -2.0, 3.25, 1e-300, np.inf, -0.0]),
        },
        'std_msgs/msg/Header': header('odd'),
        'std_msgs/msg/String': {'data': 'Grüße, 世界 🚀'},
        'builtin_interfaces/msg/Time': {'sec': -2_147_483_648, 'nanosec': 4_294_967_295},
        'rosgraph_msgs/msg/Clock': {'clock': {'sec': 12, 'nanosec': 500_000_000}},
        'geometry_msgs/msg/PoseArray': {
            'header': header('c'),
            'poses': [pose(1.0), pose(-2.5, 0.0), pose(1e9)],
        },
        'geometry_msgs/msg/PoseStamped': {'header': header('cone'), 'pose': pose(0.125)},
        'sensor_msgs/msg/PointCloud2': {
            'header': header('cone_frame'),
            'height': 1,
            'width': 4,
            'fields': [
                {'name': 'x', 'offset': 0, 'datatype': 7, 'count': 1},
                {'name': 'y', 'offset': 4, 'datatype': 7, 'count': 1},
                {'name': 'z', 'offset': 8, 'datatype': 7, 'count': 1},
                {'name': 'intensity', 'offset': 12, 'datatype': 7, 'count': 1},
            ],
            'is_bigendian': False,
            'point_step': 16,
            'row_step': 64,
            'data': cloud.tobytes(),
            'is_dense': True,
        },
        'sensor_msgs/msg/JointState': {
            'header': header('abc'),
            'name': ['cone', 'gelenk_ä', ''],
            'position': np.array([1.0, 2.0, 3.0]),
            'velocity': [],
            'effort': [0.5, -0.5, 7.0],
        },
        'visualization_msgs/msg/MarkerArray': {
            'markers': [
                marker(
                    header=header('w'), ns='pieces', id=3, type=8, action=0,
                    pose=pose(0.5), scale={'x': 0.01, 'y': 0.01, 'z': 0.01},
                    color={'r': 1.0, 'g': 0.5, 'b': 0.25, 'a': 1.0},
                    lifetime={'sec': 0, 'nanosec': 200_000_000}, frame_locked=True,
                    points=[{'x': 1.0, 'y': 2.0, 'z': 3.0}, {'x': -1.0, 'y': 0.0, 'z': 9.5}],
                    colors=[{'r': 0.0, 'g': 1.0, 'b': 0.0, 'a': 0.5}],
                    text='Fleisch 🥩', mesh_resource='package://x/y.stl',
                    uv_coordinates=[{'u': 0.25, 'v': 0.75}],
                    mesh_file={'filename': 'a.obj', 'data': b'v 0 0 0\n'},
                    mesh_use_embedded_materials=True,
                ),
                marker(ns='', action=3),
            ],
        },
        'diagnostic_msgs/msg/DiagnosticArray': {
            'header': header('diag'),
            'status': [
                {
                    'level': 1, 'name': 'integrator', 'message': 'step größe ok',
                    'hardware_id': 'sim',
                    'values': [{'key': 'dt', 'value': '1e-4'}, {'key': 'n', 'value': '17'}],
                },
                {'level': 2, 'name': 'x', 'message': '', 'hardware_id': '', 'values': []},
            ],
        },
    }


SAMPLES = sample_messages()
TYPES = sorted(SAMPLES)


def rclpy_class(type_name: str) -> Any:
    package, _, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.msg'), name)


def test_header_bytes_by_hand() -> None:
    data = encode('std_msgs/msg/Header', header('ab', sec=1, nanosec=2))
    assert data == bytes.fromhex('00010000' '01000000' '02000000' '03000000' '616200')


def test_joint_state_alignment_by_hand() -> None:
    message = {
        'header': header('abc', sec=0, nanosec=0), 'name': ['j'], 'position': [1.0],
        'velocity': [], 'effort': [],
    }
    expected = (
        '00010000'             # encapsulation header
        '00000000' '00000000'  # stamp
        '04000000' '61626300'  # frame_id 'abc' + NUL (offset 8..16)
        '01000000'             # name count (offset 16)
        '02000000' '6a00'      # 'j' + NUL (offset 20..26)
        '0000'                 # pad to 4
        '01000000'             # position count (offset 28)
        '000000000000f03f'     # 1.0 (offset 32, already 8-aligned)
        '00000000'             # velocity count: empty, no padding after it
        '00000000'             # effort count, last field: nothing after it
    )
    assert encode('sensor_msgs/msg/JointState', message) == bytes.fromhex(expected)


def test_double_after_odd_string_is_padded() -> None:
    data = encode('std_msgs/msg/Float64MultiArray', {
        'layout': {'dim': [{'label': 'abcde', 'size': 1, 'stride': 1}], 'data_offset': 0},
        'data': [2.0],
    })
    # label ends at offset 14; size, stride and data_offset take 14..28 after 2 bytes of
    # padding, the count 28..32 and the double starts at 32.
    assert data[4:].index(bytes.fromhex('0000000000000040')) == 32
    assert len(data) == 4 + 40


@pytest.mark.parametrize('type_name', TYPES)
def test_round_trip(type_name: str) -> None:
    message = SAMPLES[type_name]
    data = encode(type_name, message)
    decoded = decode(type_name, data)
    assert normalize(decoded) == normalize(message)
    assert encode(type_name, decoded) == data


@pytest.mark.parametrize('type_name', TYPES)
def test_rosbags_reads_our_bytes_and_writes_the_same(type_name: str) -> None:
    message = SAMPLES[type_name]
    data = encode(type_name, message)
    theirs = TYPESTORE.deserialize_cdr(data, type_name)
    assert normalize(theirs) == normalize(message)
    assert TYPESTORE.serialize_cdr(theirs, type_name) == data


@pytest.mark.parametrize('type_name', TYPES)
def test_we_read_rosbags_bytes(type_name: str) -> None:
    theirs = TYPESTORE.deserialize_cdr(encode(type_name, SAMPLES[type_name]), type_name)
    data = bytes(TYPESTORE.serialize_cdr(theirs, type_name))
    assert normalize(decode(type_name, data)) == normalize(theirs)


@pytest.mark.parametrize('type_name', TYPES)
def test_default_messages_encode_like_rosbags(type_name: str) -> None:
    data = encode(type_name, default_message(type_name))
    theirs = TYPESTORE.deserialize_cdr(data, type_name)
    assert TYPESTORE.serialize_cdr(theirs, type_name) == data


@pytest.mark.parametrize('type_name', TYPES)
def test_rclpy_agrees(type_name: str) -> None:
    serialization = pytest.importorskip('rclpy.serialization')
    data = encode(type_name, SAMPLES[type_name])
    rclpy_message = serialization.deserialize_message(data, rclpy_class(type_name))
    # rclpy parsed every field as we meant it: encoding its object gives our bytes.
    assert encode(type_name, rclpy_message) == data
    theirs = serialization.serialize_message(rclpy_message)
    # rmw appends a few junk bytes past the payload for some types (its size estimate
    # counts padding for empty sequences) and leaves padding uninitialised; everything
    # else must be identical, and the values must decode the same.
    assert len(data) <= len(theirs) <= len(data) + 16
    differing = [index for index in range(len(data)) if data[index] != theirs[index]]
    assert all(data[index] == 0 for index in differing)
    assert normalize(decode(type_name, theirs, strict=False)) == normalize(
        decode(type_name, data))


def test_rclpy_objects_encode_like_dicts() -> None:
    msg = pytest.importorskip('sensor_msgs.msg')
    std = pytest.importorskip('std_msgs.msg')
    state = msg.JointState()
    state.header = std.Header(frame_id='abc')
    state.header.stamp.sec = 1_700_000_000
    state.header.stamp.nanosec = 123_456_789
    state.name = ['cone', 'gelenk_ä', '']
    state.position = [1.0, 2.0, 3.0]
    state.effort = [0.5, -0.5, 7.0]
    expected = encode('sensor_msgs/msg/JointState', SAMPLES['sensor_msgs/msg/JointState'])
    assert encode('sensor_msgs/msg/JointState', state) == expected


def test_attribute_objects_encode_like_dicts() -> None:
    def to_namespace(value: Any) -> Any:
        if isinstance(value, dict):
            return types.SimpleNamespace(**{k: to_namespace(v) for k, v in value.items()})
        if isinstance(value, list):
            return [to_namespace(item) for item in value]
        return value

    for type_name in ('visualization_msgs/msg/MarkerArray', 'diagnostic_msgs/msg/DiagnosticArray'):
        message = SAMPLES[type_name]
        assert encode(type_name, to_namespace(message)) == encode(type_name, message)


def test_byte_fields_accept_int_and_bytes() -> None:
    message = copy.deepcopy(SAMPLES['diagnostic_msgs/msg/DiagnosticArray'])
    expected = encode('diagnostic_msgs/msg/DiagnosticArray', message)
    message['status'][0]['level'] = b'\x01'
    assert encode('diagnostic_msgs/msg/DiagnosticArray', message) == expected
    message['status'][0]['level'] = b'\x01\x02'
    with pytest.raises(CdrError, match='length 1'):
        encode('diagnostic_msgs/msg/DiagnosticArray', message)


@pytest.mark.parametrize('data', [
    lambda raw: raw,
    bytearray,
    memoryview,
    lambda raw: np.frombuffer(raw, dtype=np.uint8),
    lambda raw: np.frombuffer(raw, dtype=np.dtype([('x', '<f4'), ('y', '<f4'),
                                                   ('z', '<f4'), ('i', '<f4')])),
    lambda raw: array.array('B', raw),
    list,
])
def test_uint8_sequence_fast_paths(data: Any) -> None:
    message = dict(SAMPLES['sensor_msgs/msg/PointCloud2'])
    expected = encode('sensor_msgs/msg/PointCloud2', message)
    message['data'] = data(message['data'])
    assert encode('sensor_msgs/msg/PointCloud2', message) == expected


def test_uint8_sequence_rejects_float_arrays_with_a_hint() -> None:
    message = dict(SAMPLES['sensor_msgs/msg/PointCloud2'])
    message['data'] = np.zeros((4, 4), dtype=np.float32)
    with pytest.raises(CdrError, match='view'):
        encode('sensor_msgs/msg/PointCloud2', message)


@pytest.mark.parametrize('data', [
    lambda values: values.tolist(),
    tuple,
    lambda values: values.astype(np.float32),
    lambda values: array.array('d', values.tolist()),
    lambda values: values.reshape(2, 3),
    lambda values: np.repeat(values, 2)[::2],
])
def test_float64_sequence_inputs(data: Any) -> None:
    values = np.array([0.5, -2.0, 3.25, 1.0, 8.0, -0.0])
    message = copy.deepcopy(SAMPLES['std_msgs/msg/Float64MultiArray'])
    message['data'] = values
    expected = encode('std_msgs/msg/Float64MultiArray', message)
    message['data'] = data(values)
    assert encode('std_msgs/msg/Float64MultiArray', message) == expected


def test_numeric_sequences_refuse_lossy_conversions() -> None:
    message = copy.deepcopy(SAMPLES['sensor_msgs/msg/PointCloud2'])
    message['height'] = 2 ** 32
    with pytest.raises(CdrError, match='PointCloud2'):
        encode('sensor_msgs/msg/PointCloud2', message)
    codec = CdrCodec(registry_from_schema(
        'test_msgs/msg/Ints', 'int32[] values\nuint16[3] fixed\n'))
    with pytest.raises(CdrError, match='cannot write a float64 array as int32'):
        codec.encode('test_msgs/msg/Ints', {'values': np.array([1.5]), 'fixed': [1, 2, 3]})
    with pytest.raises(CdrError, match='out of range'):
        codec.encode('test_msgs/msg/Ints', {
            'values': np.array([2 ** 40], dtype=np.int64), 'fixed': [1, 2, 3]})
    ok = codec.encode('test_msgs/msg/Ints', {
        'values': np.array([7, -7], dtype=np.int64), 'fixed': np.array([1, 2, 3])})
    assert codec.decode('test_msgs/msg/Ints', ok)['values'].tolist() == [7, -7]


def test_pose_arrays_from_numpy() -> None:
    poses = SAMPLES['geometry_msgs/msg/PoseArray']['poses']
    rows = np.array([
        [p['position']['x'], p['position']['y'], p['position']['z'], p['orientation']['x'],
         p['orientation']['y'], p['orientation']['z'], p['orientation']['w']] for p in poses])
    expected = encode('geometry_msgs/msg/PoseArray', SAMPLES['geometry_msgs/msg/PoseArray'])
    message = {'header': SAMPLES['geometry_msgs/msg/PoseArray']['header'], 'poses': rows}
    assert encode('geometry_msgs/msg/PoseArray', message) == expected
    structured = np.zeros(len(poses), dtype=[(name, '<f8') for name in 'xyzabcw'])
    for column, name in enumerate('xyzabcw'):
        structured[name] = rows[:, column]
    message['poses'] = structured
    assert encode('geometry_msgs/msg/PoseArray', message) == expected
    message['poses'] = rows[:, :6]
    with pytest.raises(CdrError, match=r'shape \(n, 7\)'):
        encode('geometry_msgs/msg/PoseArray', message)
    message['poses'] = np.zeros((0, 7))
    empty = {'header': message['header'], 'poses': []}
    assert encode('geometry_msgs/msg/PoseArray', message) == encode(
        'geometry_msgs/msg/PoseArray', empty)


def test_marker_points_and_colors_from_numpy() -> None:
    expected_message = SAMPLES['visualization_msgs/msg/MarkerArray']
    expected = encode('visualization_msgs/msg/MarkerArray', expected_message)
    message = copy.deepcopy(expected_message)
    message['markers'][0]['points'] = np.array([[1.0, 2.0, 3.0], [-1.0, 0.0, 9.5]])
    message['markers'][0]['colors'] = np.array([[0.0, 1.0, 0.0, 0.5]], dtype=np.float32)
    message['markers'][0]['uv_coordinates'] = np.array([[0.25, 0.75]])
    assert encode('visualization_msgs/msg/MarkerArray', message) == expected


def test_numpy_rejected_for_mixed_structs() -> None:
    message = copy.deepcopy(SAMPLES['diagnostic_msgs/msg/DiagnosticArray'])
    message['status'][0]['values'] = np.zeros((1, 2))
    with pytest.raises(CdrError, match='list of mappings'):
        encode('diagnostic_msgs/msg/DiagnosticArray', message)


def test_fixed_arrays() -> None:
    covariance = np.arange(36, dtype=np.float64).reshape(6, 6)
    message = default_message('geometry_msgs/msg/PoseWithCovariance')
    message['covariance'] = covariance
    data = encode('geometry_msgs/msg/PoseWithCovariance', message)
    decoded = decode('geometry_msgs/msg/PoseWithCovariance', data)
    assert decoded['covariance'].tolist() == covariance.ravel().tolist()
    theirs = TYPESTORE.deserialize_cdr(data, 'geometry_msgs/msg/PoseWithCovariance')
    assert theirs.covariance.tolist() == covariance.ravel().tolist()
    message['covariance'] = covariance[:5]
    with pytest.raises(CdrError, match='exactly 36'):
        encode('geometry_msgs/msg/PoseWithCovariance', message)


ALIGNMENT_MSG = """
# Exercises every alignment situation.
bool flag
int64 big
string odd
float64[] empty_doubles
uint8 small
float64[2] pair
string<=5 bounded_text
int16[<=3] shorts
Inner[] inners
Inner[2] inner_pair
string[<=2] words
char[3] letters
byte[] raw
int8 last
"""

INNER_MSG = """
uint8 tag
float64 value
string label
"""


def alignment_codec() -> CdrCodec:
    return CdrCodec(MessageRegistry(alignment_typestore(), 'the alignment test types'))


def alignment_typestore() -> Any:
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(INNER_MSG, 'test_msgs/msg/Inner'))
    store.register(get_types_from_msg(ALIGNMENT_MSG, 'test_msgs/msg/Alignment'))
    return store


def alignment_message(**overrides: Any) -> dict:
    message = {
        'flag': True, 'big': -(2 ** 62), 'odd': 'abc', 'empty_doubles': [], 'small': 255,
        'pair': [1.5, -2.5], 'bounded_text': 'fünf', 'shorts': [-1, 2],
        'inners': [{'tag': 1, 'value': 0.5, 'label': 'x'}, {'tag': 2, 'value': 1.5, 'label': ''}],
        'inner_pair': [{'tag': 3, 'value': 2.5, 'label': 'yz'}] * 2,
        'words': ['a', 'bc'], 'letters': [65, 66, 67], 'raw': b'\x00\x7f', 'last': -128,
    }
    message.update(overrides)
    return message


@pytest.mark.parametrize('overrides', [
    {},
    {'odd': '', 'inners': [], 'words': [], 'raw': b''},
    {'odd': 'abcdefg', 'empty_doubles': [3.0], 'shorts': []},
])
def test_alignment_against_rosbags(overrides: dict) -> None:
    codec = alignment_codec()
    store = alignment_typestore()
    message = alignment_message(**overrides)
    data = codec.encode('test_msgs/msg/Alignment', message)
    theirs = store.deserialize_cdr(data, 'test_msgs/msg/Alignment')
    assert normalize(theirs) == normalize(message)
    assert store.serialize_cdr(theirs, 'test_msgs/msg/Alignment') == data
    assert normalize(codec.decode('test_msgs/msg/Alignment', data)) == normalize(message)


@pytest.mark.parametrize('overrides, match', [
    ({'bounded_text': 'sechs!'}, 'bound 5'),
    ({'shorts': [1, 2, 3, 4]}, 'bound 3'),
    ({'words': ['a', 'b', 'c']}, 'bound 2'),
    ({'inner_pair': []}, 'exactly 2'),
    ({'pair': [1.0]}, 'exactly 2'),
    ({'odd': 5}, 'needs str'),
    ({'big': 2 ** 63}, 'out of range'),
])
def test_invalid_values_raise_cdr_error(overrides: dict, match: str) -> None:
    codec = alignment_codec()
    with pytest.raises(CdrError, match=match) as info:
        codec.encode('test_msgs/msg/Alignment', alignment_message(**overrides))
    assert 'test_msgs/msg/Alignment' in str(info.value)


def test_missing_field_names_type_and_field() -> None:
    message = dict(SAMPLES['std_msgs/msg/Header'])
    del message['frame_id']
    with pytest.raises(CdrError, match=r'std_msgs/msg/Header.*frame_id'):
        encode('std_msgs/msg/Header', message)
    with pytest.raises(CdrError, match=r'std_msgs/msg/Header.*frame_id'):
        encode('std_msgs/msg/Header', types.SimpleNamespace(stamp=message['stamp']))


def test_unknown_type_is_a_cdr_error() -> None:
    with pytest.raises(CdrError, match='no_such_pkg/msg/Nothing'):
        encode('no_such_pkg/msg/Nothing', {})


def test_empty_message_is_one_byte() -> None:
    codec = CdrCodec(registry_from_schema('test_msgs/msg/Empty', '# nothing here\n'))
    data = codec.encode('test_msgs/msg/Empty', {})
    assert data == b'\x00\x01\x00\x00\x00'
    assert codec.decode('test_msgs/msg/Empty', data) == {}
    std = TYPESTORE.serialize_cdr(TYPESTORE.types['std_msgs/msg/Empty'](), 'std_msgs/msg/Empty')
    assert encode('std_msgs/msg/Empty', {}) == std


def test_decoder_is_strict_about_framing() -> None:
    data = encode('std_msgs/msg/String', {'data': 'abc'})
    with pytest.raises(CdrError, match='1 bytes after the last field'):
        decode('std_msgs/msg/String', data + b'\x00')
    assert decode('std_msgs/msg/String', data + b'\x00', strict=False) == {'data': 'abc'}
    with pytest.raises(CdrError, match='runs past the end'):
        decode('std_msgs/msg/String', data[:-1])
    with pytest.raises(CdrError, match='not little-endian'):
        decode('std_msgs/msg/String', b'\x00\x00' + data[2:])
    with pytest.raises(CdrError, match='NUL'):
        decode('std_msgs/msg/String', data[:-1] + b'x')
    with pytest.raises(CdrError, match='Float64'):
        decode('std_msgs/msg/Float64', data[:8])


def test_decoded_types() -> None:
    cloud = decode('sensor_msgs/msg/PointCloud2', encode(
        'sensor_msgs/msg/PointCloud2', SAMPLES['sensor_msgs/msg/PointCloud2']))
    assert isinstance(cloud['data'], bytes)
    assert isinstance(cloud['is_dense'], bool)
    state = decode('sensor_msgs/msg/JointState', encode(
        'sensor_msgs/msg/JointState', SAMPLES['sensor_msgs/msg/JointState']))
    assert state['position'].dtype == np.float64
    assert state['velocity'].shape == (0,)
    assert state['name'] == ['cone', 'gelenk_ä', '']


def test_encoders_are_cached_per_type() -> None:
    codec = default_codec()
    assert codec.encoder('std_msgs/Header') is codec.encoder('std_msgs/msg/Header')
    assert codec.struct_decoder('std_msgs/msg/Header') is codec.struct_decoder('std_msgs/Header')
    fresh = CdrCodec()
    assert fresh.encoder('std_msgs/msg/Header') is not codec.encoder('std_msgs/msg/Header')
