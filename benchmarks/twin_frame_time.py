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
Benchmark: the twin's own time per frame (``Twin.update``), the window's frames apart.

The stream of twin_headless.py (30 pieces, ±3 rad/s, 30 frames/s); a twin of M members
with the given window takes it frame by frame, and the times of the frames after the first
2 s are printed: p50, p95, the largest, and the mean of the frames that close a window
against the others::

    .venv/bin/python benchmarks/twin_frame_time.py [--seconds 20] [--members 4] [--window 0.5]
"""

import argparse
from pathlib import Path
import tempfile
import time

from calibration import calibration_line
from cone_feeder_sim.physics.params import ModelParams
from cone_feeder_sim.physics.simulation import SimParams, warm_up
from cone_feeder_sim.twin.estimator import Twin, TwinSettings
import numpy as np
from twin_headless import stream_twin, write_stream


def main() -> None:
    """Print the calibration and the frame times."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seconds', type=float, default=20.0)
    parser.add_argument('--members', type=int, default=4)
    parser.add_argument('--window', type=float, default=0.5)
    args = parser.parse_args()
    print(calibration_line(), flush=True)
    warm_up()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write_stream(folder, args.seconds)
        spec = stream_twin(folder)
    times, first = np.unique(spec.detections[:, 0], return_index=True)
    frames = np.split(spec.detections[:, 1:3], first[1:])
    cone = dict(zip(spec.cone[:, 0].tolist(), spec.cone[:, 1].tolist()))
    twin = Twin(SimParams(model=ModelParams()), TwinSettings(
        members=args.members, sigma=0.002, window=args.window))
    spent, closes = [], []
    for t, xy in zip(times.tolist(), frames):
        twin.cone_speed(t, cone[t])
        opened = twin._window_t0
        start = time.perf_counter()
        twin.update(t, xy)
        spent.append(1e3 * (time.perf_counter() - start))
        closes.append(twin._window_t0 != opened)
    skip = int(round(2.0 * 30))
    ms, window = np.array(spent[skip:]), np.array(closes[skip:])
    print(f'{len(ms)} frames, M = {args.members}, window {args.window:g} s: p50 '
          f'{np.percentile(ms, 50):.1f} ms, p95 {np.percentile(ms, 95):.1f} ms, max '
          f'{ms.max():.1f} ms; frames closing a window {window.sum()}: mean '
          f'{ms[window].mean() if window.any() else np.nan:.1f} ms, the others '
          f'{ms[~window].mean():.1f} ms; pieces {len(twin.pieces()[0])}', flush=True)
    print(calibration_line(), flush=True)


if __name__ == '__main__':
    main()
