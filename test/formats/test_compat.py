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
Recordings written before and after the message definitions came from rosbags read the same.

``data/run_0.1.0.mcap`` was written by cone_feeder_sim 0.1.0 (commit 474285c, schemas
taken from the installed ``.msg`` files, comments included) with
``cone-feeder-sim run data/short_run.yaml --mcap``. The test records the same scenario with
this version (schemas from rosbags' Jazzy type store) and reads both files with three
independent readers: rosbags, mcap-ros2-support and the project's own. Each must see the
same messages in both files: the same topics, stamps, types, fields, strings and integers.

The numbers in them come from the integrator, whose step control has changed since 0.1.0
(issue 37: an error floor as rodas.f has it, reciprocals instead of divisions): its last bits
differ (positions by about 1e-10 m, a velocity by 1.9e-7 m/s). Floating-point values, those
packed in point clouds included, are held to a tenth of the solver's tolerances (rtol 1e-5,
atol_velocity 1e-5, the largest for a value a reader shows): far below the product's
0.1 degree / 2 ms, and far above round-off.
"""

from pathlib import Path
from types import SimpleNamespace
from typing import Any

from cone_feeder_sim.cli import main
from cone_feeder_sim.formats.cdr import default_codec
from cone_feeder_sim.formats.mcap_reader import open_recording
from cone_feeder_sim.report.read import read_run
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from msg_compare import normalize
import numpy as np
import pytest
from rosbags.highlevel import AnyReader

DATA = Path(__file__).resolve().parent / 'data'
OLD = DATA / 'run_0.1.0.mcap'
#: PointCloud2 datatypes (sensor_msgs/PointField) to numpy, little endian.
POINT_TYPES = {1: '<i1', 2: '<u1', 3: '<i2', 4: '<u2', 5: '<i4', 6: '<u4', 7: '<f4', 8: '<f8'}
RTOL = ATOL = 1e-6


def plain(value: Any) -> Any:
    """Return plain data of a decoded message of any of the three readers."""
    if isinstance(value, SimpleNamespace):  # mcap-ros2-support: fields are __slots__
        return {key: plain(getattr(value, key)) for key in value.__slots__}
    if isinstance(value, (list, tuple)):
        return [plain(item) for item in value]
    return normalize(value)


def unpack_points(message: dict[str, Any]) -> dict[str, Any]:
    """Return a PointCloud2's plain data with its bytes read as its fields' numbers."""
    layout = np.dtype({
        'names': [field['name'] for field in message['fields']],
        'formats': [POINT_TYPES[field['datatype']] for field in message['fields']],
        'offsets': [field['offset'] for field in message['fields']],
        'itemsize': message['point_step']})
    points = np.frombuffer(bytes(message['data']), dtype=layout)
    return {**message, 'data': {name: points[name].tolist() for name in layout.names}}


def assert_close(new: Any, old: Any, where: str = '') -> None:
    """Assert equal plain data, floating-point values to RTOL and ATOL."""
    if isinstance(old, dict) and {'fields', 'data', 'point_step'} <= set(old):
        new, old = unpack_points(new), unpack_points(old)
    if isinstance(old, dict):
        assert isinstance(new, dict) and set(new) == set(old), where
        for key in old:
            assert_close(new[key], old[key], f'{where}.{key}')
    elif isinstance(old, list):
        assert isinstance(new, list) and len(new) == len(old), where
        for index, (a, b) in enumerate(zip(new, old)):
            assert_close(a, b, f'{where}[{index}]')
    elif isinstance(old, float):
        assert isinstance(new, float), where
        assert new == pytest.approx(old, rel=RTOL, abs=ATOL), where
    else:
        assert type(new) is type(old) and new == old, where


def by_rosbags(path: Path) -> list[tuple[str, int, Any]]:
    with AnyReader([path]) as reader:
        return [(connection.topic, time, plain(reader.deserialize(data, connection.msgtype)))
                for connection, time, data in reader.messages()]


def by_mcap_ros2(path: Path) -> list[tuple[str, int, Any]]:
    with path.open('rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        return [(channel.topic, message.log_time, plain(decoded))
                for _, channel, message, decoded in reader.iter_decoded_messages()]


def by_own_reader(path: Path) -> list[tuple[str, int, Any]]:
    codec = default_codec()
    return [(m.topic, m.log_time_ns, plain(codec.decode(m.type_name, m.data)))
            for m in open_recording(path).messages()]


@pytest.fixture(scope='module')
def new(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp('compat')
    path = out / 'run.mcap'
    assert main(['run', str(DATA / 'short_run.yaml'), '--events', str(out / 'events.csv'),
                 '--mcap', str(path), '--quiet']) == 0
    return path


def schemas(path: Path) -> dict[str, str]:
    with path.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    return {schema.name: schema.data.decode() for schema in summary.schemas.values()}


def test_the_schemas_differ_but_declare_the_same_types(new: Path) -> None:
    old_schemas, new_schemas = schemas(OLD), schemas(new)
    assert set(old_schemas) == set(new_schemas)
    assert old_schemas != new_schemas  # comments and order: the case this test is about


@pytest.mark.parametrize('read', [by_rosbags, by_mcap_ros2, by_own_reader])
def test_every_reader_sees_the_same_messages(new: Path, read: Any) -> None:
    old_messages, new_messages = read(OLD), read(new)
    assert len(old_messages) > 30
    assert {topic for topic, _, _ in old_messages} >= {
        '/particles', '/particle_states', '/exit_events', '/channel_mass', '/cone_state',
        '/markers'}
    assert [(topic, time) for topic, time, _ in new_messages] == [
        (topic, time) for topic, time, _ in old_messages]
    for (topic, time, a), (_, _, b) in zip(new_messages, old_messages):
        assert_close(a, b, f'{topic}@{time}')


def test_the_report_reads_both_alike(new: Path) -> None:
    old_run, new_run = read_run(OLD), read_run(new)
    assert len(old_run.exits) == len(new_run.exits) == 1
    np.testing.assert_allclose(
        new_run.exits.position, old_run.exits.position, rtol=RTOL, atol=ATOL)
    np.testing.assert_array_equal(new_run.exits.channel, old_run.exits.channel)
    np.testing.assert_array_equal(old_run.omega.value, new_run.omega.value)
    assert old_run.notes == new_run.notes
