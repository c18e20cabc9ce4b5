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
"""The headless twin: a twin file's streams (CSV or MCAP) in, the CSVs out; bad input named."""

import csv
from pathlib import Path

from cone_feeder_sim.cli import main
from cone_feeder_sim.errors import TwinError
from cone_feeder_sim.formats.cdr import encode
from cone_feeder_sim.formats.mcap_reader import open_recording
from cone_feeder_sim.formats.mcap_writer import McapRecorder
from cone_feeder_sim.formats.messages import cloud_message, cone_state_message, header
from cone_feeder_sim.formats.pointcloud import DETECTION_DTYPE, EXIT_DTYPE, NO_TRACK
from cone_feeder_sim.physics.params import ModelParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    add_particles, advance, resting_height, SimParams, SimState, world_from_cone)
from cone_feeder_sim.twin.association import GATE_CHI2
from cone_feeder_sim.twin.run import FILES, run_twin
from cone_feeder_sim.twin.spec import load_twin, TwinSpec
import numpy as np
import pytest
import yaml

MODEL = ModelParams()
PARAMS = SimParams(model=MODEL)
ROTATION = [[0.0, 0.0], [0.5, 6.0]]
PLACES = [[0.10, 0.02], [-0.08, 0.09], [0.03, -0.13], [-0.12, -0.05], [0.20, 0.03]]


def write_streams(folder: Path, seconds: float = 1.5) -> dict[float, int]:
    """
    Simulate the plant; write detections.csv (with one bad row), cone.csv, the files.

    Return, per frame's stamp (s, to 1e-6), how many of its detections are beyond the
    association's gate by their noise alone (from a perfect twin, chi-square with 2 degrees
    of freedom): the gate's 0.999 quantile leaves out one detection in a thousand so.
    """
    profile = RotationProfile.from_table(ROTATION)
    q = np.array([[x, y, resting_height(MODEL, MODEL.product, x, y)] for x, y in PLACES])
    plant, _ = add_particles(SimState(), PARAMS, q)
    rng = np.random.default_rng(0)
    outside: dict[float, int] = {}
    with (folder / 'detections.csv').open('w', newline='') as d, \
            (folder / 'cone.csv').open('w', newline='') as c:
        detections, cone = csv.writer(d), csv.writer(c)
        detections.writerow(['t', 'x', 'y', 'z', 'track_id'])
        cone.writerow(['t', 'omega'])
        for k in range(1, int(seconds * 30) + 1):
            t = k / 30.0
            plant = advance(plant, PARAMS, profile, t).state
            cone.writerow([f'{t:.6f}', profile.omega(t)])
            seen, _, _ = world_from_cone(plant.y, plant.angle, profile.omega(t))
            noise = rng.normal(0.0, 0.001, (plant.count, 2))
            seen[:, :2] += noise
            outside[round(t, 6)] = int(np.sum(np.sum((noise / 0.001) ** 2, axis=1) > GATE_CHI2))
            for (x, y, z), i in zip(seen, plant.ids):
                detections.writerow([f'{t:.6f}', x, y, z, '' if k % 7 == 0 else int(i)])
            if k == 20:  # a bad frame of its own stamp: a coordinate not finite
                detections.writerow([f'{t + 0.01:.6f}', 'nan', 0.0, 0.0, ''])
    (folder / 'scenario.yaml').write_text(yaml.safe_dump(
        {'duration': seconds, 'rotation': ROTATION,
         'particles': [{'position': [0.1, 0.0, 0.0], 'on_surface': True}]}))
    (folder / 'twin.yaml').write_text(yaml.safe_dump(
        {'scenario': 'scenario.yaml', 'detections': 'detections.csv', 'cone': 'cone.csv',
         'sigma': 0.001}))
    return outside


def read(path: Path) -> list[dict]:
    """Return a CSV's rows as dicts."""
    with path.open(newline='') as stream:
        return list(csv.DictReader(stream))


def test_the_command_writes_the_forecasts(tmp_path: Path,
                                          capsys: pytest.CaptureFixture) -> None:
    outside = write_streams(tmp_path)
    out = tmp_path / 'out'
    assert main(['twin', str(tmp_path / 'twin.yaml'), '--out', str(out)]) == 0
    printed = capsys.readouterr().err
    assert 'refused: a detection is not finite' in printed and '(1 refused)' in printed
    assert 'over-confident' not in printed  # 32 values of d and mu_C (8 members)
    for name, columns in FILES.items():
        with (out / name).open(newline='') as stream:
            assert next(csv.reader(stream)) == list(columns)
    channels = read(out / 'channel_forecast.csv')
    times = sorted({float(r['t']) for r in channels})
    assert len(times) == 15 and np.allclose(np.diff(times), 0.1, atol=0.02)
    assert {r['horizon'] for r in channels} == {'0.5', '1', '2'}
    assert len(channels) == 15 * 3 * MODEL.channels.count
    # the masses: none negative, and no channel gets more than the pieces on the cone weigh
    masses = np.array([float(r['mass']) for r in channels])
    assert masses.min() >= 0.0 and masses.max() <= 5 * MODEL.product.m + 1e-12
    pieces = read(out / 'pieces.csv')
    assert {r['piece'] for r in pieces} == {'0', '1', '2', '3', '4'}
    # the track ids are the plant's ids, and the first frame bore the pieces in their order
    assert all(r['track_id'] == r['piece'] for r in pieces)
    assert all(0.0 < float(r['probability']) <= 1.0 for r in pieces)
    parameters = read(out / 'parameters.csv')
    assert {r['key'] for r in parameters} == {'d', 'mu_C'} and len(parameters) == 30
    frames = read(out / 'frames.csv')
    assert len(frames) == 45 and int(frames[0]['births']) == 5
    report = (out / 'report.png').read_bytes()
    assert report[:8] == b'\x89PNG\r\n\x1a\n' and len(report) > 20000
    # every detection after the first frame is associated, but for those whose noise alone
    # is beyond the gate (this stream has one: 3.8 sigma at 1.1 s; 8 members leave it out)
    assert sum(outside.values()) == 1
    for f in frames[1:]:
        detections, left_out = int(f['detections']), outside[round(float(f['t']), 6)]
        assert detections - left_out <= int(f['associated']) <= detections, f


@pytest.mark.parametrize(('change', 'message'), [
    ({'speed': 1}, "unknown twin key(s) 'speed'"),
    ({'members': 1}, 'members must be an integer >= 2, got 1'),
    ({'horizons': [0.5, -1]}, 'horizons must be a list of numbers in (0, 60] s'),
    ({'cone': 'detections.csv'}, 'missing column(s) omega'),
    ({'detections': 'none.csv'}, 'cannot be read'),
])
def test_a_bad_twin_file_is_named(tmp_path: Path, capsys: pytest.CaptureFixture,
                                  change: dict, message: str) -> None:
    write_streams(tmp_path, 0.2)
    content = yaml.safe_load((tmp_path / 'twin.yaml').read_text())
    (tmp_path / 'twin.yaml').write_text(yaml.safe_dump({**content, **change}))
    assert main(['twin', str(tmp_path / 'twin.yaml'), '--out', str(tmp_path / 'o')]) == 2
    assert message in capsys.readouterr().err


def record_plant(folder: Path, places: list, seconds: float) -> Path:
    """Run the headless runner on the pieces; return its recording (events.csv beside it)."""
    (folder / 'scenario.yaml').write_text(yaml.safe_dump(
        {'duration': seconds, 'rotation': ROTATION, 'output_interval': 1.0 / 30.0,
         'particles': [{'position': [x, y, 0.0], 'on_surface': True} for x, y in places]}))
    recording = folder / 'plant.mcap'
    assert main(['run', str(folder / 'scenario.yaml'), '--events', str(folder / 'events.csv'),
                 '--mcap', str(recording), '--quiet']) == 0
    return recording


def test_the_streams_are_read_from_a_recording(tmp_path: Path) -> None:
    # the headless runner's recording stands in for a camera's and an encoder's: its
    # particle_states are the detections, its cone_state the cone speed
    recording = record_plant(tmp_path, PLACES[:4], 1.0)
    (tmp_path / 'twin.yaml').write_text(yaml.safe_dump(
        {'scenario': 'scenario.yaml', 'detections': 'plant.mcap', 'cone': 'plant.mcap',
         'members': 8, 'sigma': 0.001}))
    spec = load_twin(tmp_path / 'twin.yaml')
    states = list(open_recording(recording).messages({'/particle_states'}))
    assert len(np.unique(spec.detections[:, 0])) == len(states) >= 29
    assert len(spec.detections) == 4 * len(states)
    assert np.allclose(spec.detections[:, 3], MODEL.product.m)  # particle_states' mass field
    assert len(spec.cone) >= 29 and spec.cone[-1, 1] == pytest.approx(
        RotationProfile.from_table(ROTATION).omega(spec.cone[-1, 0]))
    summary = run_twin(spec, tmp_path / 'out')
    frames = read(tmp_path / 'out' / 'frames.csv')
    assert summary.refused == 0 and int(frames[0]['births']) == 4
    assert all(int(f['associated']) == 4 for f in frames[1:])
    (tmp_path / 'twin.yaml').write_text(yaml.safe_dump(
        {'scenario': 'scenario.yaml', 'detections': 'plant.mcap', 'cone': 'plant.mcap',
         'detections_topic': '/exit_events_nowhere'}))
    with pytest.raises(TwinError, match='no sensor_msgs/msg/PointCloud2 topic '
                                        '/exit_events_nowhere'):
        load_twin(tmp_path / 'twin.yaml')


def test_measured_exits_are_read_from_a_recording_or_a_csv(tmp_path: Path) -> None:
    # the plant's outermost piece leaves at 0.77 s: its exit_events message is the channel
    # sensor's; the twin's own exit explains it
    record_plant(tmp_path, PLACES, 1.2)
    (event,) = read(tmp_path / 'events.csv')
    twin = {'scenario': 'scenario.yaml', 'detections': 'plant.mcap', 'cone': 'plant.mcap',
            'members': 4, 'sigma': 0.001, 'd_spread': 0.05, 'mu_C_spread': 0.01}
    (tmp_path / 'twin.yaml').write_text(yaml.safe_dump({**twin, 'exits': 'plant.mcap'}))
    spec = load_twin(tmp_path / 'twin.yaml')
    # sim_node's exit_events carry the piece's mass: the exit is weighed
    assert spec.exits.tolist() == [[pytest.approx(float(event['t']), abs=1e-9),
                                    int(event['channel']), MODEL.product.m]]
    run_twin(spec, tmp_path / 'out')
    frames = read(tmp_path / 'out' / 'frames.csv')
    assert sum(int(f['measured']) for f in frames) == 1
    assert sum(int(f['explained']) for f in frames) == 1
    # a CSV's: a channel that is not one, or a mass that is not one, is refused in one
    # line, the rest taken (an empty mass: not weighed)
    (tmp_path / 'exits.csv').write_text(
        f"t,channel,mass\n{event['t']},{event['channel']},{MODEL.product.m!r}\n"
        '0.9,15,\n0.95,3,-0.1\n')
    (tmp_path / 'twin.yaml').write_text(yaml.safe_dump({**twin, 'exits': 'exits.csv'}))
    logged: list[str] = []
    run_twin(load_twin(tmp_path / 'twin.yaml'), tmp_path / 'csv', logged.append)
    assert logged == ['exit refused: measured exit: channel 15 is not one of 1..14',
                      'exit refused: measured exit: mass -0.1 is not a number of kg in (0, '
                      '6.222) (a heavier piece cannot rest on the cone) or NaN (not weighed)']
    assert read(tmp_path / 'csv' / 'frames.csv') == frames
    # a recording's: a message with an exit that is not one is refused whole, as twin_node
    # refuses it, the other messages taken
    points = np.zeros(2, dtype=EXIT_DTYPE)
    points['channel'], points['exit_time'], points['mass'] = [3, 15], [0.85, 0.86], np.nan
    good = np.zeros(1, dtype=EXIT_DTYPE)
    good['channel'], good['exit_time'], good['mass'] = int(event['channel']), float(
        event['t']), MODEL.product.m
    with McapRecorder(tmp_path / 'sensors.mcap') as recorder:
        for when, cloud in ((0.8, good), (0.9, points)):
            recorder.write('/exit_events', 'sensor_msgs/msg/PointCloud2',
                           cloud_message(header(when, 'feeder'), cloud), round(when * 1e9))
        # a message that does not decode is refused whole too, in its turn (as the node
        # refuses it on arrival); one with bytes past its payload (a DDS writer's padding)
        # is read, as the node reads it
        recorder.write_serialized('/exit_events', 'sensor_msgs/msg/PointCloud2',
                                  b'\x00\x01\x00\x00\x05', round(0.85 * 1e9))
        padded = encode('sensor_msgs/msg/PointCloud2', cloud_message(header(0.95, 'feeder'),
                                                                     good)) + bytes(3)
        recorder.write_serialized('/exit_events', 'sensor_msgs/msg/PointCloud2', padded,
                                  round(0.95 * 1e9))
    (tmp_path / 'twin.yaml').write_text(yaml.safe_dump({**twin, 'exits': 'sensors.mcap'}))
    spec = load_twin(tmp_path / 'twin.yaml')
    assert spec.exits.tolist() == [[float(event['t']), int(event['channel']),
                                    MODEL.product.m]] * 2
    logged.clear()
    run_twin(spec, tmp_path / 'mcap', logged.append)
    assert len(logged) == 2 and logged[0].startswith('cannot decode sensor_msgs/msg/')
    assert logged[1] == 'exits at t = 0.9000 s refused: a channel not in 1..14'
    frames_mcap = read(tmp_path / 'mcap' / 'frames.csv')
    assert sum(int(f['measured']) for f in frames_mcap) == 2  # the same exit twice
    assert sum(int(f['explained']) for f in frames_mcap) == 1


def camera_twin(folder: Path) -> TwinSpec:
    """Return the twin file of folder's camera.mcap (detections and cone speeds) on one piece."""
    (folder / 'scenario.yaml').write_text(yaml.safe_dump(
        {'duration': 1.0, 'rotation': ROTATION,
         'particles': [{'position': [0.1, 0.0, 0.0], 'on_surface': True}]}))
    (folder / 'twin.yaml').write_text(yaml.safe_dump(
        {'scenario': 'scenario.yaml', 'detections': 'camera.mcap', 'cone': 'camera.mcap'}))
    return load_twin(folder / 'twin.yaml')


def test_a_recording_s_bad_messages_are_refused_each_in_its_turn(tmp_path: Path) -> None:
    # as twin_node refuses them: a cloud without y, a message that does not decode, a cone
    # speed of another joint; the other frames are taken and the run goes on
    points = np.zeros(2, dtype=DETECTION_DTYPE)
    points['x'], points['y'] = [0.1, -0.08], [0.02, 0.09]
    no_y = np.zeros(2, dtype=[('x', '<f4'), ('z', '<f4')])
    with McapRecorder(tmp_path / 'camera.mcap') as recorder:
        for k in range(1, 7):
            ns = round(k / 30.0 * 1e9)
            if k == 3:
                recorder.write_serialized('/detections', 'sensor_msgs/msg/PointCloud2',
                                          b'\x00\x01\x00\x00\x05', ns)
            else:
                recorder.write('/detections', 'sensor_msgs/msg/PointCloud2', cloud_message(
                    header(k / 30.0, 'feeder'), no_y if k == 5 else points), ns)
            state = cone_state_message(header(k / 30.0, 'feeder'), 0.0, 0.0)
            if k == 4:
                state['name'] = ['belt']
            recorder.write('/cone_state', 'sensor_msgs/msg/JointState', state, ns)
    spec = camera_twin(tmp_path)
    assert len(spec.detections) == 2 * 4 and len(spec.cone) == 5
    logged: list[str] = []
    summary = run_twin(spec, tmp_path / 'out', logged.append)
    assert (summary.frames, summary.refused) == (4, 2)
    assert len(logged) == 3
    assert logged[0].startswith('cannot decode sensor_msgs/msg/PointCloud2')
    assert logged[1] == "cone speed at t = 0.1333 s refused: no joint 'cone' (joints: 'belt')"
    assert logged[2] == 'frame at t = 0.1667 s refused: no x and y fields (it has x, z)'
    assert len(read(tmp_path / 'out' / 'frames.csv')) == 4


def test_a_camera_s_track_ids_are_read_from_a_recording(tmp_path: Path) -> None:
    # camera_node's detections recorded: their track_id field becomes the fifth column
    points = np.zeros(3, dtype=DETECTION_DTYPE)
    points['x'], points['y'] = [0.1, -0.08, 0.03], [0.02, 0.09, -0.13]
    points['track_id'] = [40, NO_TRACK, 42]
    with McapRecorder(tmp_path / 'camera.mcap') as recorder:
        for k in range(1, 7):  # a forecast at the first frame and at the fifth
            ns = round(k / 30.0 * 1e9)
            recorder.write('/detections', 'sensor_msgs/msg/PointCloud2',
                           cloud_message(header(k / 30.0, 'feeder'), points), ns)
            recorder.write('/cone_state', 'sensor_msgs/msg/JointState',
                           cone_state_message(header(k / 30.0, 'feeder'), 0.0, 0.0), ns)
    spec = camera_twin(tmp_path)
    assert spec.detections[:, 4].tolist() == [40, NO_TRACK, 42] * 6
    assert np.isnan(spec.detections[:, 3]).all()  # no mass field: not given
    run_twin(spec, tmp_path / 'out')
    pieces = read(tmp_path / 'out' / 'pieces.csv')
    found = [(r['piece'], r['track_id']) for r in pieces]
    assert found == [('0', '40'), ('1', ''), ('2', '42')]
