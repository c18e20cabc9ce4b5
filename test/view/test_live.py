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
Tests of the live Foxglove view.

`run --view` as a real process watched by three clients, the RL environment's 'human'
mode, the scene of a scripted snapshot, the refusals, the layout file.

The clients are the tests' own (``foxglove_client``: the published WebSocket protocol, the
protobuf wire format read with the schema the server advertises).
"""

import math
from pathlib import Path
import re
import signal
import subprocess
import sys
import time

from cone_feeder_sim.cli import main as cli_main
from cone_feeder_sim.formats.events_csv import EVENT_COLUMNS
from cone_feeder_sim.formats.mcap_reader import open_recording
from cone_feeder_sim.formats.messages import pose_array_positions
from cone_feeder_sim.formats.scenario_file import load_scenario
from cone_feeder_sim.physics.params import ModelParams
from cone_feeder_sim.physics.simulation import world_from_cone
from cone_feeder_sim.view.frame import PALETTE
from cone_feeder_sim.view.live import INSTALL_HINT, LiveView
from cone_feeder_sim.view.snapshot import Snapshot, touching_pairs
from foxglove_client import FoxgloveClient, Schema
import mcap.reader
import numpy as np
import pytest

foxglove = pytest.importorskip('foxglove')

# Six pieces on a cone that starts turning; the weigher below. Four leave; two, side by side
# near the tip, stick to the cone and touch all along (contact between pieces on: the scene
# has a contact to mark in every frame).
SCENARIO = """\
duration: 2.0
parameters: {table2}
interactions: {{enabled: true, coupling: exact}}
weigher: {{}}
rotation: [[0.0, 0.0], [0.5, -8.37758]]
particles:
  - {{position: [0.11, -0.01, 0.03], d: 225.0}}
  - {{position: [-0.10, -0.01, 0.03], d: 135.0}}
  - {{position: [0.08, -0.13, 0.03], d: 750.0}}
  - {{position: [-0.07, 0.04, 0.03], d: 750.0}}
  - {{position: [0.03, 0.0, 0.0], on_surface: true}}
  - {{position: [0.03, 0.045, 0.0], on_surface: true}}
"""
#: Generous waits: a fresh process imports numpy and numba and loads the kernels.
START_TIMEOUT = 120.0
RUN_TIMEOUT = 300.0
CONFIG = Path(__file__).resolve().parents[2] / 'config'


def write_scenario(folder: Path) -> Path:
    path = folder / 'scenario.yaml'
    path.write_text(SCENARIO.format(table2=CONFIG / 'table2.yaml'))
    return path


def wait_for(condition, what: str, log: Path, timeout: float = RUN_TIMEOUT) -> None:
    end = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < end, f'{what} not in time:\n{log.read_text()}'
        time.sleep(0.02)


def default_sigint() -> None:
    """Let the child see SIGINT even where the test runner's parent ignores it."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def pieces(message: dict) -> np.ndarray:
    """Return the sphere centres (N, 3) of a decoded SceneUpdate's 'pieces' entity."""
    entity = next(e for e in message['entities'] if e['id'] == 'pieces')
    return np.array([[s['pose']['position'].get(k, 0.0) for k in 'xyz']
                     for s in entity.get('spheres', [])]).reshape(-1, 3)


def contact_points(message: dict) -> int:
    entity = next(e for e in message['entities'] if e['id'] == 'contacts')
    return sum(len(line.get('points', [])) for line in entity.get('lines', []))


def mcap_content(path: Path) -> tuple[list, list]:
    """Return a file's messages (topic, log time, data) and metadata less 'created'."""
    with path.open('rb') as stream:
        reader = mcap.reader.make_reader(stream)
        messages = [(channel.topic, message.log_time, message.data)
                    for _, channel, message in reader.iter_messages()]
        metadata = [(m.name, {k: v for k, v in m.metadata.items() if k != 'created'})
                    for m in reader.iter_metadata()]
    return messages, metadata


def test_run_view_serves_the_run_to_early_late_and_vanishing_clients(tmp_path: Path) -> None:
    scenario = write_scenario(tmp_path)
    events, run_mcap, log_path = tmp_path / 'view.csv', tmp_path / 'view.mcap', tmp_path / 'log'
    with log_path.open('wb') as log:
        proc = subprocess.Popen(
            [sys.executable, '-m', 'cone_feeder_sim.cli', 'run', str(scenario), '--quiet',
             '--events', str(events), '--mcap', str(run_mcap), '--view', '--port', '0',
             '--speed', '0.5'],
            stdout=log, stderr=subprocess.STDOUT, preexec_fn=default_sigint)
    clients: list[FoxgloveClient] = []
    try:
        wait_for(lambda: 'live view on ws://' in log_path.read_text(), 'the view', log_path,
                 START_TIMEOUT)
        port = int(re.search(r'ws://127\.0\.0\.1:(\d+)', log_path.read_text()).group(1))
        early, vanishing = FoxgloveClient(port), FoxgloveClient(port)
        clients += [early, vanishing]
        assert early.protocol == 'foxglove.sdk.v1'
        early.subscribe('/scene', '/cone_state', '/hopper_weights', '/events')
        vanishing.subscribe('/scene', '/channel_mass')
        wait_for(lambda: min(len(vanishing.received('/scene')),
                             len(vanishing.received('/channel_mass'))) >= 3, 'frames', log_path)
        vanishing.vanish()
        late = FoxgloveClient(port)
        clients.append(late)
        late.subscribe('/scene')
        wait_for(lambda: 'the run ended at t = 2.000 s' in log_path.read_text(), 'the end',
                 log_path)
        wait_for(lambda: len(late.received('/scene')) >= 1, 'a late frame', log_path, 10.0)
        after = FoxgloveClient(port)  # after the end: the view stays, with the last frame
        clients.append(after)
        after.subscribe('/scene', '/cone_state')
        wait_for(lambda: len(after.received('/scene')) >= 1, 'the last frame', log_path, 30.0)
        assert proc.poll() is None and not early.closed
        proc.send_signal(signal.SIGINT)
        code = proc.wait(60.0)
    finally:
        for client in clients:
            client.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    log = log_path.read_text()
    assert code == 0, log
    assert '4 of 6 pieces left the cone; 2 still on it' in log

    # the files are those of a run without the view: the CSV byte for byte, the MCAP file
    # message for message (its metadata differ only in the wall-clock time of creation)
    plain_events, plain_mcap = tmp_path / 'plain.csv', tmp_path / 'plain.mcap'
    assert cli_main(['run', str(scenario), '--quiet', '--events', str(plain_events),
                     '--mcap', str(plain_mcap)]) == 0
    assert events.read_bytes() == plain_events.read_bytes()
    assert mcap_content(run_mcap) == mcap_content(plain_mcap)

    # every frame: the pieces where the recording has them at that time, the contacts
    recording = open_recording(str(run_mcap))
    recorded = {m.log_time_ns: pose_array_positions(m.data)[1]
                for m in recording.messages({'/particles'})}
    frames = early.decoded('/scene')
    assert len(frames) >= 10
    radii = np.full(6, ModelParams().product.s0)
    for t_ns, message in frames:
        expected = recorded[t_ns]
        np.testing.assert_allclose(pieces(message), expected, rtol=0, atol=1e-12)
        assert contact_points(message) == 2 * len(touching_pairs(expected, radii[:len(expected)]))
        assert message['entities'][0]['frame_id'] == 'feeder'
    assert len(pieces(frames[-1][1])) == 2  # the last frame: the run's end
    assert all(contact_points(m) == 2 for _, m in frames)  # the two near the tip

    # the plot channels follow the cone and the weigher
    profile = load_scenario(scenario).rotation
    states = early.json('/cone_state')
    # (the two subscriptions of one request may start a frame apart)
    assert len({t for t, _ in states} ^ {t for t, _ in frames}) <= 1
    for t_ns, state in states:
        assert state['velocity'][0] == pytest.approx(profile.omega(t_ns * 1e-9), abs=1e-12)
        assert state['header']['frame_id'] == 'feeder'
    assert all(len(w['data']) == 14 for _, w in early.json('/hopper_weights'))
    assert len(vanishing.json('/channel_mass')) >= 3

    # the events: a log line per exit, as in the CSV
    lines = [m['message'] for _, m in early.decoded('/events')]
    rows = events.read_text().splitlines()[1:]
    assert rows and EVENT_COLUMNS[0] == 'particle'
    exits = [line for line in lines if line.startswith('piece ')]
    first_seen = frames[0][0] * 1e-9
    expected_exits = [r.split(',') for r in rows if float(r.split(',')[1]) > first_seen]
    for row in expected_exits:
        assert any(line.startswith(f'piece {row[0]} left into channel {row[3]} ')
                   for line in exits), (row, exits)

    last_t, last = after.decoded('/scene')[0]
    assert last_t == 2_000_000_000 and len(pieces(last)) == 2
    assert after.json('/cone_state')[0][0] == last_t

    # the late client came in mid-run and saw the whole scene, cone included
    late_frames = late.decoded('/scene')
    assert frames[0][0] < late_frames[0][0] < frames[-1][0]
    feeder = late_frames[0][1]['entities'][0]
    assert feeder['id'] == 'feeder' and len(feeder['cylinders']) == 1


def test_scene_of_a_scripted_snapshot() -> None:
    from cone_feeder_sim.view.scene import SceneBuilder
    from foxglove.messages import SceneUpdate
    model = ModelParams()
    positions = np.array([[0.1, 0.0, 0.02], [0.14, 0.0, 0.02], [-0.1, 0.05, 0.02]])
    radii = np.array([0.025, 0.025, 0.03])
    snapshot = Snapshot(t=1.25, angle=0.5, omega=-2.0, ids=np.array([4, 7, 9]),
                        positions=positions, radii=radii, kinds=np.array([0, 0, 1]),
                        contacts=touching_pairs(positions, radii),
                        channel_mass=np.zeros(14), hoppers=None)
    schema = Schema(SceneUpdate.get_schema().data)
    message = schema.decode('foxglove.SceneUpdate',
                            SceneBuilder(model).update(snapshot).encode())
    feeder, spheres, contacts = message['entities']
    assert [e['id'] for e in message['entities']] == ['feeder', 'pieces', 'contacts']
    assert all(e['frame_id'] == 'feeder' and e['timestamp'] == {'seconds': 1, 'nanos': 250000000}
               for e in message['entities'])
    cone = feeder['cylinders'][0]
    assert cone['size'] == {'x': 2 * model.r, 'y': 2 * model.r, 'z': model.h}
    assert cone.get('bottom_scale') == 1.0 and 'top_scale' not in cone  # a point at the top
    boundaries, mark = feeder['lines']
    assert len(boundaries['points']) == 2 * 14 and len(feeder['texts']) == 14
    odd, even = feeder['triangles']  # the sectors: 8 parts of 2 triangles per channel
    assert len(odd['points']) == len(even['points']) == 7 * 8 * 6
    corner = odd['points'][0]  # channel 1's first inner corner, on its start edge
    assert math.atan2(corner['y'], corner['x']) == pytest.approx(
        math.remainder(math.radians(model.channels.sector_edges(1)[0]), 2 * math.pi))
    start = math.radians(model.channels.sector_edges(1)[0])
    assert boundaries['points'][0]['x'] == pytest.approx(model.r * math.cos(start))
    tip = mark['points'][1]
    assert math.atan2(tip['y'], tip['x']) == pytest.approx(0.5)
    np.testing.assert_array_equal(pieces(message), positions)
    assert [s['size']['x'] for s in spheres['spheres']] == [0.05, 0.05, 0.06]
    colours = [tuple(round(255 * s['color'].get(c, 0.0)) for c in 'rgb')
               for s in spheres['spheres']]
    assert colours == [PALETTE[0], PALETTE[0], PALETTE[1]]
    ends = [[p.get(k, 0.0) for k in 'xyz'] for p in contacts['lines'][0]['points']]
    np.testing.assert_array_equal(ends, positions[:2])  # only the first two touch


def test_human_mode_shows_the_episode(tmp_path: Path) -> None:
    pytest.importorskip('gymnasium')
    from cone_feeder_sim.rl.env import ConeFeederEnv
    env = ConeFeederEnv(render_mode='human', view_port=0, initial_pieces=6, episode_time=1.0)
    try:
        client = FoxgloveClient(env.view.port)
        client.subscribe('/scene', '/channel_mass')
        env.reset(seed=2)
        for _ in range(3):
            assert env.step(env.action_space.sample())[0] is not None
        assert env.render() is None
        engine = env.engine
        expected = world_from_cone(engine.state.y, engine.angle, engine.omega)[0]
        client.wait_for(lambda: any(t == round(engine.t * 1e9) for t, _ in client.received(
            '/scene')), 30.0)
    finally:
        env.close()
    t_ns, message = client.decoded('/scene')[-1]
    np.testing.assert_allclose(pieces(message), expected, rtol=0, atol=1e-12)
    assert len(client.json('/channel_mass')) >= 2
    client.close()


def test_port_in_use_or_no_sdk_stop_the_run_before_it_starts(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    scenario = write_scenario(tmp_path)
    events = tmp_path / 'events.csv'
    with LiveView(ModelParams(), port=0) as taken:
        assert cli_main(['run', str(scenario), '--events', str(events), '--view', '--port',
                         str(taken.port)]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and f'cannot serve the live view on 127.0.0.1:{taken.port}' in err
    assert not events.exists()
    monkeypatch.setitem(sys.modules, 'foxglove', None)  # as without the [view] extra
    assert cli_main(['run', str(scenario), '--events', str(events), '--view']) == 2
    assert capsys.readouterr().err == f'error: {INSTALL_HINT}\n'
    assert not events.exists()
    assert cli_main(['run', str(scenario), '--events', str(events), '--speed', '2']) == 2
    assert '--speed: only with --view' in capsys.readouterr().err


def test_layout_file_is_the_built_layout() -> None:
    from cone_feeder_sim.view.layout import layout_json
    from cone_feeder_sim.view.topics import VIEW_TOPICS
    from cone_feeder_sim.view.topics import layout_file
    assert layout_file() == CONFIG / 'foxglove_layout.json'  # the source tree's here
    text = layout_file().read_text(encoding='utf-8')
    assert text == layout_json()
    for topic in ('/scene', '/markers', '/cone_state.velocity[0]', '/channel_mass.data[13]',
                  '/hopper_weights.data[0]', '/events', '/sim_node/events'):
        assert f'"{topic}"' in text, topic
    assert {t.name for t in VIEW_TOPICS.values()} == {
        '/scene', '/cone_state', '/channel_mass', '/hopper_weights', '/events'}
