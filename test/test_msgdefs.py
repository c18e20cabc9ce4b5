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
Tests of .msg lookup, parsing and ros2msg schema text.

Independent references: rosidl_adapter's parser (the one ROS 2 builds messages
with), rosbags' .msg parser and built-in Jazzy type store, and a re-statement of
rosbag2's dependency scan (its regular expression over the raw file text).
"""

import os
import pathlib
import re
import sys

from cone_feeder_sim import msgdefs
from cone_feeder_sim.errors import ConeFeederError
from cone_feeder_sim.msgdefs import (
    ArrayKind,
    FieldSpec,
    MessageDefinitionError,
    MessageDefinitionRegistry,
)
import pytest
from rosbags.typesys import get_types_from_msg, get_typestore
from rosbags.typesys.stores import Stores

REQUIRED_TYPES = [
    'std_msgs/msg/Float64',
    'std_msgs/msg/Float64MultiArray',
    'std_msgs/msg/Header',
    'std_msgs/msg/String',
    'builtin_interfaces/msg/Time',
    'rosgraph_msgs/msg/Clock',
    'geometry_msgs/msg/PoseArray',
    'geometry_msgs/msg/PoseStamped',
    'sensor_msgs/msg/PointCloud2',
    'sensor_msgs/msg/JointState',
    'visualization_msgs/msg/MarkerArray',
    'diagnostic_msgs/msg/DiagnosticArray',
]

# rosbag2's LocalMessageDefinitionSource finds dependencies with this expression.
ROSBAG2_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
ROSBAG2_PRIMITIVES = {
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string'}


def rosbag2_full_text(type_name: str) -> str:
    """Re-state rosbag2's msgdefs.get_full_text on raw files, independently of our parser."""
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
        path = pathlib.Path(sys.prefix, 'share', package, 'msg', f'{short}.msg')
        text = path.read_bytes().decode('utf-8')
        result = text
        for dependency in dependencies(text, package):
            if dependency not in seen:
                seen.add(dependency)
                result += '\n' + '=' * 80 + '\n' + f'MSG: {dependency}\n' + append(dependency)
        return result

    return append(type_name)


@pytest.mark.parametrize('type_name', REQUIRED_TYPES)
def test_full_text_matches_rosbag2_algorithm(type_name: str) -> None:
    assert msgdefs.get_full_text(type_name) == rosbag2_full_text(type_name)


@pytest.mark.parametrize('type_name', REQUIRED_TYPES)
def test_full_text_is_understood_by_rosbags(type_name: str) -> None:
    reference = get_typestore(Stores.ROS2_JAZZY)
    parsed = get_types_from_msg(msgdefs.get_full_text(type_name), type_name)
    assert type_name in parsed
    for name, (_, fields) in parsed.items():
        assert [field[0] for field in fields] == [
            field[0] for field in reference.fielddefs[name][1]], name


def test_full_text_layout_for_marker_array() -> None:
    text = msgdefs.get_full_text('visualization_msgs/msg/MarkerArray')
    path = pathlib.Path(sys.prefix, 'share/visualization_msgs/msg/MarkerArray.msg')
    main, *rest = text.split('\n' + msgdefs.SEPARATOR + '\n')
    assert main == path.read_text(encoding='utf-8')
    names = [part.split('\n', 1)[0] for part in rest]
    assert all(name.startswith('MSG: ') and '/msg/' not in name for name in names)
    assert len(names) == len(set(names))
    assert set(names) == {
        'MSG: ' + msgdefs.short_type_name(name)
        for name in msgdefs.default_registry().resolve('visualization_msgs/msg/MarkerArray')
        if name != 'visualization_msgs/msg/MarkerArray'}
    # Depth first: Marker comes first and its Header before Header's Time.
    assert names[0] == 'MSG: visualization_msgs/Marker'
    assert names.index('MSG: std_msgs/Header') < names.index('MSG: builtin_interfaces/Time')


def test_full_text_without_dependencies_is_the_file() -> None:
    path = pathlib.Path(sys.prefix, 'share/std_msgs/msg/Float64.msg')
    assert msgdefs.get_full_text('std_msgs/Float64') == path.read_text(encoding='utf-8')


def test_point_cloud_fields() -> None:
    spec = msgdefs.get_message_spec('sensor_msgs/PointCloud2')
    assert spec.type_name == 'sensor_msgs/msg/PointCloud2'
    assert [field.name for field in spec.fields] == [
        'header', 'height', 'width', 'fields', 'is_bigendian', 'point_step', 'row_step',
        'data', 'is_dense']
    assert spec.fields[0] == FieldSpec('header', 'std_msgs/msg/Header')
    assert spec.fields[3] == FieldSpec(
        'fields', 'sensor_msgs/msg/PointField', ArrayKind.SEQUENCE)
    assert spec.fields[7] == FieldSpec('data', 'uint8', ArrayKind.SEQUENCE)
    assert spec.dependencies == ('sensor_msgs/PointField', 'std_msgs/Header')


def test_constants_are_parsed_but_not_fields() -> None:
    spec = msgdefs.get_message_spec('visualization_msgs/msg/Marker')
    constants = {constant.name: constant.value for constant in spec.constants}
    assert constants['SPHERE_LIST'] == '7'
    assert constants['DELETEALL'] == '3'
    assert 'SPHERE_LIST' not in [field.name for field in spec.fields]
    spaced = msgdefs.get_message_spec('type_description_interfaces/msg/FieldType')
    assert {constant.name for constant in spaced.constants} >= {'FIELD_TYPE_NOT_SET'}


def _rosidl_fields(type_name: str) -> list:
    parser = pytest.importorskip('rosidl_adapter.parser')
    package, _, name = type_name.split('/')
    path = pathlib.Path(sys.prefix, 'share', package, 'msg', f'{name}.msg')
    spec = parser.parse_message_file(package, str(path))
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


@pytest.mark.parametrize('type_name', sorted({
    name for root in REQUIRED_TYPES + [
        'shape_msgs/msg/SolidPrimitive', 'rmw_dds_common/msg/NodeEntitiesInfo',
        'geometry_msgs/msg/PoseWithCovariance']
    for name in msgdefs.default_registry().resolve(root)}))
def test_fields_match_rosidl_adapter(type_name: str) -> None:
    ours = [
        (field.name, field.base_type, field.array_kind, field.array_size, field.string_bound)
        for field in msgdefs.get_message_spec(type_name).fields]
    assert ours == _rosidl_fields(type_name)


def test_bounded_types() -> None:
    primitive = msgdefs.get_message_spec('shape_msgs/msg/SolidPrimitive')
    dimensions = {field.name: field for field in primitive.fields}['dimensions']
    assert (dimensions.array_kind, dimensions.array_size) == (ArrayKind.BOUNDED, 3)
    info = msgdefs.get_message_spec('rmw_dds_common/msg/NodeEntitiesInfo')
    assert info.fields[0] == FieldSpec('node_namespace', 'string', string_bound=256)


def test_parse_message_text_details() -> None:
    text = (
        '# file comment\n'
        'int32 FOO=3\n'
        'uint8 INT8 = 1  # constant with spaces\n'
        'string GREETING="hi"\n'
        'float64 gain 1.5\n'
        'string<=10 name "cone"  # bounded string with default\n'
        'int32[<=4] counts [1, 2]\n'
        'string<=3[<=2] tags\n'
        'float32[9] matrix\n'
        '\tuint8\tdata_flag # tab separated\n'
        'Point p\n'
        'geometry_msgs/Pose pose\n'
        'time stamp\n'
    )
    fields, constants = msgdefs.parse_message_text('my_pkg/msg/Thing', text)
    assert [(c.name, c.type_string, c.value) for c in constants] == [
        ('FOO', 'int32', '3'), ('INT8', 'uint8', '1'), ('GREETING', 'string', '"hi"')]
    assert fields == (
        FieldSpec('gain', 'float64', default='1.5'),
        FieldSpec('name', 'string', string_bound=10, default='"cone"'),
        FieldSpec('counts', 'int32', ArrayKind.BOUNDED, 4, default='[1, 2]'),
        FieldSpec('tags', 'string', ArrayKind.BOUNDED, 2, string_bound=3),
        FieldSpec('matrix', 'float32', ArrayKind.FIXED, 9),
        FieldSpec('data_flag', 'uint8'),
        FieldSpec('p', 'my_pkg/msg/Point'),
        FieldSpec('pose', 'geometry_msgs/msg/Pose'),
        FieldSpec('stamp', 'builtin_interfaces/msg/Time'),
    )


@pytest.mark.parametrize('line, match', [
    ('int32', 'missing field name'),
    ('int32 1abc', 'invalid field name'),
    ('int32[0] x', 'must be positive'),
    ('int32[<=x] y', 'invalid sequence bound'),
    ('string<=-1 s', 'invalid string bound'),
    ('a/b/c/d x', 'invalid message type name'),
    ('float64 ok', 'duplicate field name'),
])
def test_malformed_lines_name_type_and_line(line: str, match: str) -> None:
    with pytest.raises(MessageDefinitionError, match=match) as info:
        msgdefs.parse_message_text('my_pkg/Broken', 'float64 ok\n' + line + '\n')
    assert 'my_pkg/msg/Broken, line 2' in str(info.value)


def make_prefix(root: pathlib.Path, files: dict) -> pathlib.Path:
    for relative, text in files.items():
        path = root / 'share' / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding='utf-8')
    return root


def test_missing_type_names_type_and_searched_paths(tmp_path: pathlib.Path) -> None:
    registry = MessageDefinitionRegistry([tmp_path / 'a', tmp_path / 'b'])
    with pytest.raises(MessageDefinitionError) as info:
        registry.get('nowhere_msgs/Thing')
    message = str(info.value)
    assert 'nowhere_msgs/msg/Thing' in message
    assert str(tmp_path / 'a' / 'share' / 'nowhere_msgs' / 'msg' / 'Thing.msg') in message
    assert str(tmp_path / 'b' / 'share' / 'nowhere_msgs' / 'msg' / 'Thing.msg') in message
    assert isinstance(info.value, ConeFeederError)


def test_missing_dependency_is_reported(tmp_path: pathlib.Path) -> None:
    prefix = make_prefix(tmp_path, {'my_pkg/msg/Outer.msg': 'Missing inner\n'})
    registry = MessageDefinitionRegistry([prefix])
    assert registry.get('my_pkg/Outer').dependencies == ('my_pkg/Missing',)
    with pytest.raises(MessageDefinitionError, match='my_pkg/msg/Missing'):
        registry.full_text('my_pkg/Outer')


def test_search_order_and_environment(tmp_path: pathlib.Path,
                                      monkeypatch: pytest.MonkeyPatch) -> None:
    first = make_prefix(tmp_path / 'first', {'std_msgs/msg/Float64.msg': 'float32 data\n'})
    second = tmp_path / 'second'
    monkeypatch.setenv('AMENT_PREFIX_PATH', os.pathsep.join([str(first), str(second)]))
    prefixes = msgdefs.default_search_prefixes()
    assert prefixes == [first, second, pathlib.Path(sys.prefix)]
    registry = MessageDefinitionRegistry()
    spec = registry.get('std_msgs/msg/Float64')
    assert spec.path == first / 'share/std_msgs/msg/Float64.msg'
    assert spec.fields == (FieldSpec('data', 'float32'),)
    # Not found under AMENT_PREFIX_PATH: falls back to sys.prefix (the wheels).
    assert registry.get('std_msgs/msg/String').path == pathlib.Path(
        sys.prefix, 'share/std_msgs/msg/String.msg')
    monkeypatch.delenv('AMENT_PREFIX_PATH')
    assert msgdefs.default_search_prefixes() == [pathlib.Path(sys.prefix)]


def test_unqualified_header_prefers_own_package(tmp_path: pathlib.Path) -> None:
    prefix = make_prefix(tmp_path, {
        'a_msgs/msg/Stamped.msg': 'Header header\n',
        'b_msgs/msg/Stamped.msg': 'Header header\n',
        'b_msgs/msg/Header.msg': 'uint32 seq\n',
    })
    registry = MessageDefinitionRegistry([prefix, pathlib.Path(sys.prefix)])
    assert registry.get('a_msgs/Stamped').fields[0].base_type == 'std_msgs/msg/Header'
    assert registry.get('b_msgs/Stamped').fields[0].base_type == 'b_msgs/msg/Header'
    assert registry.full_text('a_msgs/Stamped').startswith(
        'Header header\n\n' + msgdefs.SEPARATOR + '\nMSG: std_msgs/Header\n')


def test_add_definition_and_recursion_guard() -> None:
    registry = MessageDefinitionRegistry([])
    registry.add_definition('loop_msgs/A', 'B b\n')
    registry.add_definition('loop_msgs/B', 'A a\n')
    with pytest.raises(MessageDefinitionError, match='recursive'):
        registry.full_text('loop_msgs/A')


@pytest.mark.parametrize('name, expected', [
    ('std_msgs/msg/Header', 'std_msgs/msg/Header'),
    ('std_msgs/Header', 'std_msgs/msg/Header'),
    (' std_msgs/Header ', 'std_msgs/msg/Header'),
])
def test_normalize_type_name(name: str, expected: str) -> None:
    assert msgdefs.normalize_type_name(name) == expected


@pytest.mark.parametrize('name', ['Header', 'std_msgs/srv/Foo', 'a/msg/b/c', '', '1pkg/X'])
def test_invalid_type_names(name: str) -> None:
    with pytest.raises(MessageDefinitionError, match='invalid message type name'):
        msgdefs.normalize_type_name(name)
