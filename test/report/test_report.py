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
Tests of the run report: MCAP files written here with McapRecorder, read back and drawn.

The messages use exactly the layouts of doc/sim_node.md: ``particle_states`` points of 32
bytes (x, y, z, vx, vy, vz FLOAT32 at 0..20, id UINT32 at 24, mass FLOAT32 at 28),
``exit_events`` points of 80 bytes (nine FLOAT64 from 0 to 64, id and channel UINT32 at 72
and 76), ``cone_state`` JointState with name ``cone`` and ``channel_mass``
Float64MultiArray with a ``channel`` dimension.
"""

import dataclasses
import math
from pathlib import Path
import struct
from typing import Any
import zlib

from cone_feeder_sim.cli import main
from cone_feeder_sim.errors import ConeFeederError
from cone_feeder_sim.errors import ReportError
from cone_feeder_sim.formats.mcap_writer import McapRecorder
from cone_feeder_sim.physics.params import ChannelLayout, ModelParams
from cone_feeder_sim.physics.simulation import ExitEvents
from cone_feeder_sim.report.draw import build_figure, write_report
from cone_feeder_sim.report.read import (
    check_channel_mass, exits_per_channel, layout_from_metadata, read_run)
import numpy as np
from point_layouts import EXIT_FIELDS, STATE_FIELDS
import pytest

STATE_DTYPE = np.dtype({
    'names': [f[0] for f in STATE_FIELDS], 'formats': ['<f4'] * 6 + ['<u4', '<f4'],
    'offsets': [f[1] for f in STATE_FIELDS], 'itemsize': 32})
EXIT_DTYPE = np.dtype({
    'names': [f[0] for f in EXIT_FIELDS], 'formats': ['<f8'] * 9 + ['<u4', '<u4'],
    'offsets': [f[1] for f in EXIT_FIELDS], 'itemsize': 80})
CLOUD = 'sensor_msgs/msg/PointCloud2'

#: The layout written into the metadata of the sample run (not the defaults).
LAYOUT = ChannelLayout(count=8, boundary=90.0, numbering='counter_clockwise')
RADIUS = 0.25
METADATA = {
    'model.cone_diameter': '0.5', 'model.channel_count': '8',
    'model.channel_boundary': '90.0', 'model.channel_numbering': 'counter_clockwise',
    'model.cone_tilt': '7.5', 'feed.seed': '7', 'update_rate': '50.0'}


def header(t_ns: int) -> dict[str, Any]:
    """Return a std_msgs/Header at ``t_ns`` in frame feeder."""
    return {'stamp': {'sec': t_ns // 1_000_000_000, 'nanosec': t_ns % 1_000_000_000},
            'frame_id': 'feeder'}


def cloud(t_ns: int, points: np.ndarray, fields: list[tuple[str, int, int]]) -> dict[str, Any]:
    """Return a PointCloud2 message (height 1, little endian) of structured ``points``."""
    step = points.dtype.itemsize
    return {'header': header(t_ns), 'height': 1, 'width': points.shape[0],
            'fields': [{'name': n, 'offset': o, 'datatype': d, 'count': 1} for n, o, d in fields],
            'is_bigendian': False, 'point_step': step, 'row_step': step * points.shape[0],
            'data': points, 'is_dense': True}


def state_points(ids: list[int], xy: np.ndarray, masses: list[float]) -> np.ndarray:
    """Return particle_states points of pieces ``ids`` at positions ``xy`` (n, 2)."""
    points = np.zeros(len(ids), dtype=STATE_DTYPE)
    points['x'], points['y'] = xy[:, 0], xy[:, 1]
    points['z'] = 0.01
    points['vx'], points['vy'] = -xy[:, 1], xy[:, 0]
    points['id'] = ids
    points['mass'] = masses
    return points


def exit_points(t: float, ids: list[int], angles: list[float], masses: list[float],
                radius: float, layout: ChannelLayout) -> np.ndarray:
    """Return exit_events points of pieces leaving at ``angles`` (rad) on the rim."""
    points = np.zeros(len(ids), dtype=EXIT_DTYPE)
    angle = np.asarray(angles)
    points['x'], points['y'] = radius * np.cos(angle), radius * np.sin(angle)
    points['vx'] = 0.3
    points['exit_time'] = t - 0.005
    points['angle'] = angle
    points['mass'] = masses
    points['id'] = ids
    points['channel'] = layout.channel_of(np.degrees(angle))
    return points


class SampleRun:
    """A small synthetic run: pieces circling outwards, leaving at known angles."""

    dt_ns = 20_000_000
    ticks = 60
    masses = {0: 0.125, 1: 0.1, 2: 0.15, 3: 0.2, 4: 0.05}
    #: tick of the exit and exit angle (rad) per id; id 4 stays on the cone.
    leave = {0: (20, 0.3), 1: (35, 2.0), 2: (35, 2.1), 3: (50, -1.0)}

    def __init__(self, radius: float = RADIUS, layout: ChannelLayout = LAYOUT) -> None:
        """Precompute what is written."""
        self.radius = radius
        self.layout = layout
        self.times_ns = [(k + 1) * self.dt_ns for k in range(self.ticks)]
        self.omega = [3.0 * math.sin(0.1 * k) for k in range(self.ticks)]

    def on_cone(self, k: int) -> list[int]:
        """Return the ids on the cone in tick ``k`` (id 3 arrives in tick 10)."""
        ids = [i for i in self.masses if k < self.leave.get(i, (10 ** 9,))[0]]
        return [i for i in ids if i != 3 or k >= 10]

    def position(self, i: int, k: int) -> tuple[float, float]:
        """Return the position of piece ``i`` in tick ``k``."""
        rho = 0.05 + 0.02 * i + 0.002 * k
        phi = 0.5 * i + 0.05 * k * (1 + i)
        return rho * math.cos(phi), rho * math.sin(phi)

    def exits_in(self, k: int) -> list[int]:
        """Return the ids leaving in tick ``k``."""
        return [i for i, (tick, _) in self.leave.items() if tick == k]

    def channel_totals(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the expected exits per channel: count and mass."""
        count = np.zeros(self.layout.count, dtype=np.int64)
        mass = np.zeros(self.layout.count)
        for i, (_, angle) in self.leave.items():
            channel = int(self.layout.channel_of(math.degrees(angle)))
            count[channel - 1] += 1
            mass[channel - 1] += self.masses[i]
        return count, mass

    def write(self, path: Path, metadata: dict[str, str] | None = METADATA, *,
              chunk_size: int = 1024 * 1024, prefix: str = '') -> None:
        """Write the run to ``path`` the way the node's topics look."""
        totals = np.zeros(self.layout.count)
        with McapRecorder(path, chunk_size=chunk_size, compression='zstd') as recorder:
            if metadata is not None:
                recorder.add_metadata('cone_feeder_sim', metadata)
            for k, t_ns in enumerate(self.times_ns):
                ids = self.on_cone(k)
                xy = np.array([self.position(i, k) for i in ids]).reshape(-1, 2)
                points = state_points(ids, xy, [self.masses[i] for i in ids])
                recorder.write(f'{prefix}/particle_states', CLOUD,
                               cloud(t_ns, points, STATE_FIELDS), t_ns)
                leaving = self.exits_in(k)
                if leaving:
                    rows = exit_points(
                        t_ns * 1e-9, leaving, [self.leave[i][1] for i in leaving],
                        [self.masses[i] for i in leaving], self.radius, self.layout)
                    recorder.write(f'{prefix}/exit_events', CLOUD,
                                   cloud(t_ns, rows, EXIT_FIELDS), t_ns)
                    np.add.at(totals, rows['channel'].astype(np.int64) - 1, rows['mass'])
                recorder.write(f'{prefix}/channel_mass', 'std_msgs/msg/Float64MultiArray', {
                    'layout': {'dim': [{'label': 'channel', 'size': self.layout.count,
                                        'stride': self.layout.count}], 'data_offset': 0},
                    'data': totals.copy()}, t_ns)
                recorder.write(f'{prefix}/cone_state', 'sensor_msgs/msg/JointState', {
                    'header': header(t_ns), 'name': ['cone'],
                    'position': np.array([0.1 * k]), 'velocity': np.array([self.omega[k]]),
                    'effort': np.zeros(0)}, t_ns)
                recorder.write(f'{prefix}/particles', 'geometry_msgs/msg/PoseArray',
                               {'header': header(t_ns), 'poses': np.zeros((len(ids), 7))},
                               t_ns)


def png_size(path: Path) -> tuple[int, int]:
    """Return the width and height of a PNG after checking its signature and IHDR CRC."""
    data = path.read_bytes()
    assert data[:8] == b'\x89PNG\r\n\x1a\n'
    length, kind = struct.unpack('>I4s', data[8:16])
    assert kind == b'IHDR' and length == 13
    body = data[16:16 + length]
    (crc,) = struct.unpack('>I', data[16 + length:20 + length])
    assert crc == zlib.crc32(kind + body)
    assert data.endswith(b'IEND\xaeB`\x82')
    width, height = struct.unpack('>II', body[:8])
    return width, height


@pytest.fixture(scope='module')
def sample(tmp_path_factory: pytest.TempPathFactory) -> tuple[SampleRun, Path]:
    """Return the sample run and its MCAP file."""
    run = SampleRun()
    path = tmp_path_factory.mktemp('report') / 'run.mcap'
    run.write(path)
    return run, path


def test_read_run_gives_what_was_written(sample: tuple[SampleRun, Path]) -> None:
    run, path = sample
    data = read_run(path)
    assert data.truncated is None
    assert data.layout == LAYOUT and data.cone_radius == pytest.approx(RADIUS)
    assert data.layout_from_metadata and data.metadata == METADATA
    assert data.topics == {'particle_states': '/particle_states', 'exit_events': '/exit_events',
                           'cone_state': '/cone_state', 'channel_mass': '/channel_mass'}
    assert data.notes == ()
    times = np.array(run.times_ns) * 1e-9
    # piece counts and omega: one sample per message, log time in s
    np.testing.assert_allclose(data.pieces.t, times, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(data.pieces.value, [len(run.on_cone(k))
                                                      for k in range(run.ticks)])
    np.testing.assert_allclose(data.omega.t, times, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(data.omega.value, run.omega)
    # trajectories per id: every point written, float32 as on the wire
    trajectories = data.trajectories
    assert trajectories.message_stride == 1 and trajectories.id_stride == 1
    assert trajectories.pieces_seen == 5
    by_id = trajectories.by_id()
    assert sorted(by_id) == [0, 1, 2, 3, 4]
    for i, rows in by_id.items():
        ticks = [k for k in range(run.ticks) if i in run.on_cone(k)]
        expected = np.array([run.position(i, k) for k in ticks], dtype=np.float32)
        np.testing.assert_allclose(rows[:, 0], times[ticks], rtol=0, atol=1e-12)
        np.testing.assert_array_equal(rows[:, 1:3], expected.astype(np.float64))
    # exits: one row each, channel and mass as written
    exits = data.exits
    assert sorted(exits.ids.tolist()) == [0, 1, 2, 3]
    for i, (tick, angle) in run.leave.items():
        row = int(np.flatnonzero(exits.ids == i)[0])
        assert data.exit_log_time[row] == pytest.approx(run.times_ns[tick] * 1e-9)
        assert exits.t[row] == pytest.approx(run.times_ns[tick] * 1e-9 - 0.005)
        assert exits.angle_deg[row] == pytest.approx(math.degrees(angle) % 360.0)
        assert exits.mass[row] == run.masses[i]
        assert exits.channel[row] == LAYOUT.channel_of(math.degrees(angle))
        assert math.hypot(*exits.position[row, :2]) == pytest.approx(RADIUS)
    count, mass = run.channel_totals()
    totals = data.exit_totals()
    np.testing.assert_array_equal(totals.count, count)
    np.testing.assert_array_equal(totals.mass, mass)
    assert count.sum() == 4 and np.count_nonzero(count) == 3  # two pieces share a channel
    np.testing.assert_array_equal(data.channel_mass, mass)
    assert data.channel_mass_time == pytest.approx(run.times_ns[-1] * 1e-9)
    assert check_channel_mass(data, totals) == (True, 0.0)
    # the last frame: the pieces of the last message, as written
    t_last, xy = data.last_frame
    assert t_last == pytest.approx(times[-1])
    k = run.ticks - 1
    np.testing.assert_array_equal(
        xy, np.array([run.position(i, k) for i in run.on_cone(k)], dtype=np.float32))


def test_contact_setting_and_piece_size_come_from_the_metadata(
        sample: tuple[SampleRun, Path]) -> None:
    from cone_feeder_sim.report.read import RunData
    base = read_run(sample[1])
    assert base.contact() is None and base.piece_radius() == 0.025  # not recorded: default
    on = dataclasses.replace(base, metadata={'interactions.enabled': 'true',
                                             'interactions.pull_off': '0.05',
                                             'interactions.max_island': '48',
                                             'model.s0': '0.03'})
    assert on.contact() == ('on (pull-off 0.05 N, max island 48; the pair law before soft '
                            'contact)')
    assert on.piece_radius() == 0.03
    soft = dataclasses.replace(base, metadata={'interactions.enabled': 'true',
                                               'interactions.restitution': '0.3',
                                               'interactions.friction': '0.5',
                                               'interactions.pull_off': '0.05',
                                               'interactions.coupling': 'multirate'})
    assert soft.contact() == 'on (restitution 0.3, friction 0.5, pull-off 0.05 N, multirate)'
    off = dataclasses.replace(base, metadata={'interactions.enabled': 'false'})
    assert off.contact() == 'off' and isinstance(off, RunData)


def test_write_report_writes_a_png(sample: tuple[SampleRun, Path], tmp_path: Path) -> None:
    _, path = sample
    out = tmp_path / 'report.png'
    data = write_report(path, out)
    width, height = png_size(out)
    assert (width, height) == (1700, 960)
    assert 30_000 < out.stat().st_size < 2_000_000
    assert len(data.exits) == 4


def test_channel_mass_mismatch_is_reported(sample: tuple[SampleRun, Path]) -> None:
    _, path = sample
    data = read_run(path)
    totals = data.exit_totals()
    changed = data.channel_mass.copy()
    changed[0] += 0.01
    data = dataclasses.replace(data, channel_mass=changed)
    agree, delta = check_channel_mass(data, totals)
    assert not agree and delta == pytest.approx(0.01)
    texts = [t.get_text() for ax in build_figure(data).axes for t in [ax.title]]
    assert any('channel_mass differs by up to 0.01 kg' in text for text in texts)


def test_truncated_file_reports_what_is_readable(
    sample: tuple[SampleRun, Path], tmp_path: Path
) -> None:
    run, _ = sample
    path = tmp_path / 'chunked.mcap'
    run.write(path, chunk_size=2048)  # many small chunks
    full = read_run(path)
    data = path.read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:len(data) * 6 // 10])
    part = read_run(cut)
    assert part.truncated is not None
    assert 'incomplete or corrupt' in part.notes[0]
    n = len(part.pieces)
    assert 0 < n < len(full.pieces)
    np.testing.assert_array_equal(part.pieces.t, full.pieces.t[:n])
    np.testing.assert_array_equal(part.pieces.value, full.pieces.value[:n])
    np.testing.assert_array_equal(part.omega.value, full.omega.value[:len(part.omega)])
    assert part.layout == LAYOUT  # the metadata record came first
    for i, rows in part.trajectories.by_id().items():
        np.testing.assert_array_equal(rows, full.trajectories.by_id()[i][:rows.shape[0]])
    out = tmp_path / 'cut.png'
    write_report(cut, out)
    assert png_size(out) == (1700, 960)
    # a corrupt byte in the middle: what precedes the damaged chunk is still read
    damaged = bytearray(data)
    damaged[len(data) // 2] ^= 0xFF
    cut.write_bytes(bytes(damaged))
    part = read_run(cut)
    assert part.truncated is not None and 0 < len(part.pieces) < len(full.pieces)


def test_not_an_mcap_file_gives_a_clear_error(tmp_path: Path) -> None:
    path = tmp_path / 'notes.mcap'
    path.write_text('this is not MCAP\n' * 10)
    with pytest.raises(ReportError, match='notes.mcap.*is not an MCAP file') as info:
        read_run(path)
    assert isinstance(info.value, ConeFeederError)
    path.write_bytes(b'')
    with pytest.raises(ReportError, match='is not an MCAP file'):
        read_run(path)
    with pytest.raises(ReportError, match='cannot read MCAP file.*missing.mcap'):
        read_run(tmp_path / 'missing.mcap')


def test_defaults_without_metadata(tmp_path: Path) -> None:
    defaults = ModelParams()
    run = SampleRun(radius=defaults.r, layout=defaults.channels)
    path = tmp_path / 'plain.mcap'
    run.write(path, metadata=None)
    data = read_run(path)
    assert data.layout == defaults.channels and data.cone_radius == defaults.r
    assert not data.layout_from_metadata
    assert any('ModelParams() defaults' in note for note in data.notes)
    np.testing.assert_array_equal(data.exit_totals().count, run.channel_totals()[0])
    figure = build_figure(data)
    assert any('defaults' in text.get_text() for text in figure.texts)


def test_exits_per_channel_counts_and_masses() -> None:
    exits = ExitEvents(ids=np.arange(5), t=np.arange(5.0), angle_deg=np.zeros(5),
                       channel=np.array([2, 2, 0, 5, 1]), position=np.zeros((5, 3)),
                       velocity=np.zeros((5, 3)), mass=np.array([0.1, 0.2, 0.3, 0.4, 0.5]))
    totals = exits_per_channel(exits, 3)
    np.testing.assert_array_equal(totals.count, [1, 2, 0, 0, 1])  # channel 0 is not counted
    np.testing.assert_allclose(totals.mass, [0.5, 0.3, 0.0, 0.0, 0.4])


def test_layout_from_metadata_values() -> None:
    layout, radius, complete, notes = layout_from_metadata(METADATA)
    assert (layout, radius, complete, notes) == (LAYOUT, 0.25, True, [])
    layout, radius, complete, notes = layout_from_metadata({'model.channel_count': '10.0'})
    assert layout == ChannelLayout(count=10) and radius == ModelParams().r
    assert not complete and 'model.cone_diameter' in notes[0]
    layout, radius, complete, notes = layout_from_metadata(
        {**METADATA, 'model.channel_numbering': 'sideways'})
    assert layout == ModelParams().channels and not complete
    assert 'invalid metadata' in notes[0]


def test_namespaced_topics_and_missing_channel_field(tmp_path: Path) -> None:
    run = SampleRun()
    path = tmp_path / 'ns.mcap'
    run.write(path, prefix='/feeder1')
    data = read_run(path)
    assert data.topics['particle_states'] == '/feeder1/particle_states'
    assert len(data.exits) == 4
    assert read_run(path, namespace='feeder2').topics == {}
    # exits without a channel field get their channel from the angle and the layout
    with McapRecorder(tmp_path / 'nochannel.mcap') as recorder:
        recorder.add_metadata('cone_feeder_sim', METADATA)
        rows = exit_points(1.0, [5, 6], [0.1, 3.0], [0.2, 0.3], RADIUS, LAYOUT)
        fields = [f for f in EXIT_FIELDS if f[0] != 'channel']
        recorder.write('/exit_events', CLOUD, cloud(10 ** 9, rows, fields), 10 ** 9)
    exits = read_run(tmp_path / 'nochannel.mcap').exits
    np.testing.assert_array_equal(exits.channel, LAYOUT.channel_of(np.degrees([0.1, 3.0])))


def test_trajectories_are_thinned_for_large_runs(tmp_path: Path) -> None:
    path = tmp_path / 'many.mcap'
    n, messages = 300, 64
    ids = list(range(n))
    with McapRecorder(path) as recorder:
        for k in range(messages):
            xy = np.column_stack((np.full(n, 0.001 * k), np.linspace(-0.1, 0.1, n)))
            points = state_points(ids, xy, [0.1] * n)
            recorder.write('/particle_states', CLOUD, cloud(k * 10 ** 7, points, STATE_FIELDS),
                           k * 10 ** 7)
    data = read_run(path, max_trajectories=50, max_trajectory_points=500)
    trajectories = data.trajectories
    assert trajectories.pieces_seen == n
    assert trajectories.id_stride == 8  # 300 / 8 -> 38 pieces <= 50
    assert trajectories.pieces_kept == 38
    assert np.all(trajectories.ids % 8 == 0)
    assert trajectories.message_stride == 8  # 8 messages of 38 points <= 500
    assert trajectories.t.shape[0] <= 500
    np.testing.assert_allclose(np.unique(trajectories.t), np.arange(0, messages, 8) * 0.01)
    np.testing.assert_array_equal(data.pieces.value, [n] * messages)  # counts stay complete
    assert any('thinned' in note for note in data.notes)


def test_cli_report(sample: tuple[SampleRun, Path], tmp_path: Path,
                    capsys: pytest.CaptureFixture) -> None:
    _, path = sample
    out = tmp_path / 'cli.png'
    assert main(['report', str(path), '--out', str(out)]) == 0
    assert png_size(out) == (1700, 960)
    err = capsys.readouterr().err
    assert f'report written to {out}' in err
    bad = tmp_path / 'bad.mcap'
    bad.write_text('no')
    assert main(['report', str(bad), '--out', str(out)]) == 2
    assert 'is not an MCAP file' in capsys.readouterr().err


def test_a_report_never_overwrites_its_recording(sample: tuple[SampleRun, Path],
                                                 tmp_path: Path,
                                                 capsys: pytest.CaptureFixture) -> None:
    _, path = sample
    before = path.read_bytes()
    link = tmp_path / 'link.mcap'
    link.symlink_to(path)
    for out in (str(path), f'{path.parent}/./{path.name}', str(link)):  # one file, 3 names
        assert main(['report', str(path), '--out', out]) == 2
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and f'would overwrite the recording {path}' in err
        assert path.read_bytes() == before  # byte for byte
