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
same messages in both files.
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


def plain(value: Any) -> Any:
    """Return plain data of a decoded message of any of the three readers."""
    if isinstance(value, SimpleNamespace):  # mcap-ros2-support: fields are __slots__
        return {key: plain(getattr(value, key)) for key in value.__slots__}
    if isinstance(value, (list, tuple)):
        return [plain(item) for item in value]
    return normalize(value)


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
    assert new_messages == old_messages


def test_the_report_reads_both_alike(new: Path) -> None:
    old_run, new_run = read_run(OLD), read_run(new)
    assert len(old_run.exits) == len(new_run.exits) == 1
    np.testing.assert_array_equal(old_run.exits.position, new_run.exits.position)
    np.testing.assert_array_equal(old_run.omega.value, new_run.omega.value)
    assert old_run.notes == new_run.notes
