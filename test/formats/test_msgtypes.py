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
Tests of message definitions from rosbags' type store and of ros2msg schema text.

Independent references: the ``.msg`` files of the ROS 2 Jazzy wheels in the
virtual environment (where installed), read the way rosbag2's
LocalMessageDefinitionSource reads them (re-stated below) and parsed by
rosidl_adapter (the parser ROS 2 builds messages with) or by rosbags' ``.msg``
parser, and hand-written expectations.
"""

import pathlib
import re
import sys

from cone_feeder_sim.errors import ConeFeederError
from cone_feeder_sim.formats.cdr import CdrCodec
from cone_feeder_sim.formats.msgtypes import (
    ArrayKind, default_registry, FieldSpec, MessageDefinitionError, normalize_type_name,
    registry_from_schema)
from msg_compare import normalize
import pytest
from rosbags.typesys import get_types_from_msg

#: Every type the package records or publishes, and a few with bounds and fixed arrays.
REQUIRED_TYPES = [
    'builtin_interfaces/msg/Duration',
    'builtin_interfaces/msg/Time',
    'diagnostic_msgs/msg/DiagnosticArray',
    'geometry_msgs/msg/PoseArray',
    'geometry_msgs/msg/PoseStamped',
    'geometry_msgs/msg/PoseWithCovariance',
    'rosgraph_msgs/msg/Clock',
    'sensor_msgs/msg/JointState',
    'sensor_msgs/msg/PointCloud2',
    'std_msgs/msg/Empty',
    'std_msgs/msg/Float64',
    'std_msgs/msg/Float64MultiArray',
    'std_msgs/msg/Header',
    'std_msgs/msg/String',
    'visualization_msgs/msg/MarkerArray',
]
EXTRA_TYPES = ['shape_msgs/msg/SolidPrimitive', 'rmw_dds_common/msg/NodeEntitiesInfo']
SEPARATOR = '=' * 80

# rosbag2's LocalMessageDefinitionSource finds dependencies with this expression.
ROSBAG2_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
ROSBAG2_PRIMITIVES = {
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string'}


def msg_file(type_name: str) -> pathlib.Path:
    """Return the installed .msg file of ``type_name``, skipping the test if there is none."""
    package, _, name = type_name.split('/')
    path = pathlib.Path(sys.prefix, 'share', package, 'msg', f'{name}.msg')
    if not path.is_file():
        pytest.skip(f'{path} is not installed')
    return path


def rosbag2_full_text(type_name: str) -> str:
    """Re-state the schema text rosbag2 writes, on the raw installed .msg files."""
    seen = set()

    def dependencies(text: str, package: str) -> list:
        found = set()
        for match in ROSBAG2_FIELD_TYPE.finditer(text):
            name = match.group(1)
            if name not in ROSBAG2_PRIMITIVES:
                found.add(name if '/' in name else f'{package}/{name}')
        return sorted(found)

    def append(name: str) -> str:
        package, _, short = name.partition('/')
        short = short.split('/')[-1]
        text = msg_file(f'{package}/msg/{short}').read_bytes().decode('utf-8')
        result = text
        for dependency in dependencies(text, package):
            if dependency not in seen:
                seen.add(dependency)
                result += f'\n{SEPARATOR}\nMSG: {dependency}\n' + append(dependency)
        return result

    return append(type_name)


def all_types() -> list:
    """Return the required and extra types with all their dependencies."""
    registry = default_registry()
    return sorted({
        name for root in REQUIRED_TYPES + EXTRA_TYPES for name in registry.resolve(root)})


@pytest.mark.parametrize('type_name', REQUIRED_TYPES)
def test_full_text_declares_what_rosbag2_writes(type_name: str) -> None:
    # Not byte for byte (no comments, defaults or blank lines; see the module doc of
    # msgtypes), but the same constants, fields and types for every definition.
    ours = get_types_from_msg(default_registry().full_text(type_name), type_name)
    theirs = get_types_from_msg(rosbag2_full_text(type_name), type_name)
    assert ours == theirs


@pytest.mark.parametrize('type_name', REQUIRED_TYPES)
def test_full_text_reads_back_into_the_same_definitions(type_name: str) -> None:
    registry = registry_from_schema(type_name, default_registry().full_text(type_name))
    assert registry.resolve(type_name) == default_registry().resolve(type_name)
    assert registry.full_text(type_name) == default_registry().full_text(type_name)


@pytest.mark.parametrize('type_name', REQUIRED_TYPES)
def test_schema_written_by_rosbag2_is_read(type_name: str) -> None:
    registry = registry_from_schema(type_name, rosbag2_full_text(type_name))
    assert registry.resolve(type_name) == default_registry().resolve(type_name)


def test_full_text_layout() -> None:
    assert default_registry().full_text('std_msgs/Float64') == 'float64 data\n'
    assert default_registry().full_text('std_msgs/msg/Empty') == ''
    assert default_registry().full_text('geometry_msgs/msg/PoseArray') == '\n'.join([
        'std_msgs/Header header',
        'geometry_msgs/Pose[] poses',
        SEPARATOR,
        'MSG: std_msgs/Header',
        'builtin_interfaces/Time stamp',
        'string frame_id',
        SEPARATOR,
        'MSG: builtin_interfaces/Time',
        'int32 sec',
        'uint32 nanosec',
        SEPARATOR,
        'MSG: geometry_msgs/Pose',
        'geometry_msgs/Point position',
        'geometry_msgs/Quaternion orientation',
        SEPARATOR,
        'MSG: geometry_msgs/Point',
        'float64 x',
        'float64 y',
        'float64 z',
        SEPARATOR,
        'MSG: geometry_msgs/Quaternion',
        'float64 x',
        'float64 y',
        'float64 z',
        'float64 w',
        '',
    ])


def test_full_text_lists_each_dependency_once() -> None:
    type_name = 'visualization_msgs/msg/MarkerArray'
    text = default_registry().full_text(type_name)
    main, *rest = text.split('\n' + SEPARATOR + '\n')
    assert main == 'visualization_msgs/Marker[] markers'
    names = [part.split('\n', 1)[0] for part in rest]
    assert names[0] == 'MSG: visualization_msgs/Marker'
    assert sorted(names) == sorted(
        'MSG: ' + name.replace('/msg/', '/')
        for name in default_registry().resolve(type_name) if name != type_name)
    marker = rest[0].split('\n')
    assert 'int32 SPHERE_LIST=7' in marker
    assert marker.index('int32 DELETEALL=3') < marker.index('std_msgs/Header header')


def _rosidl_fields(type_name: str) -> list:
    parser = pytest.importorskip('rosidl_adapter.parser')
    package, _, name = type_name.split('/')
    spec = parser.parse_message_file(package, str(msg_file(type_name)))
    result = []
    for field in spec.fields:
        base = field.type
        if base.is_primitive_type():
            base_type = base.type
        else:
            base_type = f'{base.pkg_name}/msg/{base.type}'
        if not base.is_array:
            kind, size = ArrayKind.NONE, None
        elif base.array_size is None:
            kind, size = ArrayKind.SEQUENCE, None
        elif base.is_upper_bound:
            kind, size = ArrayKind.BOUNDED, base.array_size
        else:
            kind, size = ArrayKind.FIXED, base.array_size
        result.append((field.name, base_type, kind, size, base.string_upper_bound))
    return result


@pytest.mark.parametrize('type_name', all_types())
def test_fields_match_rosidl_adapter(type_name: str) -> None:
    ours = [
        (field.name, field.base_type, field.array_kind, field.array_size, field.string_bound)
        for field in default_registry().spec(type_name).fields]
    assert ours == _rosidl_fields(type_name)


def test_point_cloud_fields() -> None:
    spec = default_registry().spec('sensor_msgs/PointCloud2')
    assert spec.type_name == 'sensor_msgs/msg/PointCloud2'
    assert [field.name for field in spec.fields] == [
        'header', 'height', 'width', 'fields', 'is_bigendian', 'point_step', 'row_step',
        'data', 'is_dense']
    assert spec.fields[0] == FieldSpec('header', 'std_msgs/msg/Header')
    assert spec.fields[3] == FieldSpec('fields', 'sensor_msgs/msg/PointField', ArrayKind.SEQUENCE)
    assert spec.fields[7] == FieldSpec('data', 'uint8', ArrayKind.SEQUENCE)
    assert not spec.fields[0].is_primitive and spec.fields[7].is_primitive


def test_bounds_fixed_arrays_and_empty_messages() -> None:
    primitive = default_registry().spec('shape_msgs/msg/SolidPrimitive')
    assert primitive.fields[1] == FieldSpec('dimensions', 'float64', ArrayKind.BOUNDED, 3)
    info = default_registry().spec('rmw_dds_common/msg/NodeEntitiesInfo')
    assert info.fields[0] == FieldSpec('node_namespace', 'string', string_bound=256)
    covariance = default_registry().spec('geometry_msgs/msg/PoseWithCovariance').fields[1]
    assert covariance == FieldSpec('covariance', 'float64', ArrayKind.FIXED, 36)
    # rosbags stores rosidl's placeholder member; the message has no fields.
    assert default_registry().spec('std_msgs/msg/Empty').fields == ()


def test_schema_text_with_ros1_conventions_and_own_types() -> None:
    text = '\n'.join([
        '# comment, constants and defaults',
        'int32 LIMIT=3',
        'Header header  # unqualified: std_msgs',
        'Inner[<=2] inners',
        'float64 gain 1.5',
        'string<=4 tag',
        '',
        SEPARATOR,
        'MSG: std_msgs/Header',
        'uint32 seq',
        'time stamp',
        'string frame_id',
        SEPARATOR,
        'MSG: my_msgs/Inner',
        'char[2] code',
        '',
    ])
    registry = registry_from_schema('my_msgs/Outer', text)
    assert registry.spec('my_msgs/msg/Outer').fields == (
        FieldSpec('header', 'std_msgs/msg/Header'),
        FieldSpec('inners', 'my_msgs/msg/Inner', ArrayKind.BOUNDED, 2),
        FieldSpec('gain', 'float64'),
        FieldSpec('tag', 'string', string_bound=4),
    )
    # The file's own Header (ROS 1 layout), not Jazzy's; time needs no definition.
    assert [field.name for field in registry.spec('std_msgs/Header').fields] == [
        'seq', 'stamp', 'frame_id']
    assert sorted(registry.resolve('my_msgs/Outer')) == [
        'builtin_interfaces/msg/Time', 'my_msgs/msg/Inner', 'my_msgs/msg/Outer',
        'std_msgs/msg/Header']
    assert [field.name for field in default_registry().spec('std_msgs/Header').fields] == [
        'stamp', 'frame_id']
    message = {
        'header': {'seq': 7, 'stamp': {'sec': 1, 'nanosec': 2}, 'frame_id': 'f'},
        'inners': [{'code': [65, 66]}], 'gain': 0.5, 'tag': 'abcd'}
    codec = CdrCodec(registry)
    decoded = codec.decode('my_msgs/msg/Outer', codec.encode('my_msgs/msg/Outer', message))
    assert normalize(decoded) == message
    again = registry_from_schema('my_msgs/Outer', registry.full_text('my_msgs/Outer'))
    assert again.resolve('my_msgs/Outer') == registry.resolve('my_msgs/Outer')


def test_unknown_type_names_type_and_store() -> None:
    with pytest.raises(MessageDefinitionError) as info:
        default_registry().spec('nowhere_msgs/Thing')
    assert 'nowhere_msgs/msg/Thing' in str(info.value)
    assert 'ROS 2 Jazzy' in str(info.value)
    assert isinstance(info.value, ConeFeederError)
    with pytest.raises(MessageDefinitionError, match='nowhere_msgs/msg/Thing'):
        default_registry().full_text('nowhere_msgs/msg/Thing')


def test_schema_without_a_dependency_is_refused() -> None:
    with pytest.raises(
            MessageDefinitionError, match=r'my_msgs/msg/Missing .*used by my_msgs/msg/Outer'):
        registry_from_schema('my_msgs/Outer', 'float64 x\nMissing inner\n')


def test_unparsable_schema_is_refused() -> None:
    with pytest.raises(MessageDefinitionError, match='invalid schema text of my_msgs/msg/Bad'):
        registry_from_schema('my_msgs/msg/Bad', 'float64 ok\nint32\n')


def test_recursive_schema_is_refused() -> None:
    text = f'B b\n{SEPARATOR}\nMSG: loop_msgs/B\nA a\n'
    with pytest.raises(MessageDefinitionError, match='recursive'):
        registry_from_schema('loop_msgs/A', text)


@pytest.mark.parametrize('name, expected', [
    ('std_msgs/msg/Header', 'std_msgs/msg/Header'),
    ('std_msgs/Header', 'std_msgs/msg/Header'),
    (' std_msgs/Header ', 'std_msgs/msg/Header'),
])
def test_normalize_type_name(name: str, expected: str) -> None:
    assert normalize_type_name(name) == expected


@pytest.mark.parametrize('name', ['Header', 'std_msgs/srv/Foo', 'a/msg/b/c', '', '1pkg/X'])
def test_invalid_type_names(name: str) -> None:
    with pytest.raises(MessageDefinitionError, match='invalid message type name'):
        normalize_type_name(name)
    with pytest.raises(MessageDefinitionError, match='invalid message type name'):
        default_registry().spec(name)
