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
How long a run and a node take to end after SIGINT or SIGTERM, in the expensive states.

Each case starts a process, lets it compute for ``--after`` seconds of wall time and sends
the signal; the figure is the time from the signal to the process's exit (its files
closed). Cases: ``cone-feeder-sim run`` of 70 pieces in one island coupled exactly (each
0.01-s output interval takes seconds) and by the default island coupling, of 2,000 pieces
alone on a reversing cone, and ``sim_node`` with the same crowd as its initial pieces
(exact and the default island coupling; the tick under way takes seconds)::

    .venv/bin/python benchmarks/stop_latency.py [--after 5] [--repeat 3]
"""

import argparse
import os
from pathlib import Path
import signal
import statistics
import subprocess
import sys
import tempfile
import time

from calibration import calibration_line
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
from crowds import crowd_in_layers  # noqa: E402, I100 - the tests' crowd


def scenario(positions: np.ndarray, extra: str, duration: float = 10.0) -> str:
    """Return a scenario of ``duration`` s of pieces at positions (N, 3), with extra keys."""
    pieces = ''.join(f'  - {{position: [{x!r}, {y!r}, {z!r}]}}\n'
                     for x, y, z in positions.tolist())
    return (f'duration: {duration}\noutput_interval: 0.01\n{extra}'
            f'rotation: [[0.0, 0.0], [0.3, -8.0], [1.5, -8.0], [1.9, 8.0]]\n'
            f'particles:\n{pieces}')


def alone(count: int) -> np.ndarray:
    """Return count resting pieces spread over the annulus 0.03-0.2 m (N, 3) m."""
    rng = np.random.default_rng(0)
    rho = np.sqrt(rng.uniform(0.03 ** 2, 0.2 ** 2, count))
    phi = rng.uniform(0.0, 2 * np.pi, count)
    return np.column_stack([rho * np.cos(phi), rho * np.sin(phi),
                            0.0296 * (1 - rho / 0.225) + 0.03])


def measure(command: list[str], after: float, signum: int, files: dict[str, str]) -> float:
    """
    Start command in a new folder with files; return how long it took to exit (s).

    The signal is sent `after` s after the start.
    """
    cwd = tempfile.mkdtemp(prefix='stop_latency_')
    for name, text in files.items():
        Path(cwd, name).write_text(text)
    env = dict(os.environ, ROS_DOMAIN_ID=str(100 + os.getpid() % 100))
    with open(Path(cwd, 'log.txt'), 'wb') as log:
        proc = subprocess.Popen(
            command, cwd=cwd, env=env, stdout=log, stderr=subprocess.STDOUT,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    time.sleep(after)
    if proc.poll() is not None:
        raise RuntimeError(f'{command[:4]} ended before the signal ({proc.returncode}): '
                           + Path(cwd, 'log.txt').read_text()[-2000:])
    sent = time.perf_counter()
    proc.send_signal(signum)
    proc.wait(600)
    return time.perf_counter() - sent


def main() -> None:
    """Run every case and print the latencies."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--after', type=float, default=5.0, help='s of wall time first')
    parser.add_argument('--repeat', type=int, default=3)
    args = parser.parse_args()
    print(calibration_line())
    crowd = crowd_in_layers(2, lift=0.0)
    python = sys.executable
    files = {'crowd.yaml': scenario(crowd, 'interactions: {enabled: true, coupling: exact}\n'),
             'island.yaml': scenario(crowd, 'interactions: {enabled: true}\n', 600.0),
             'alone.yaml': scenario(alone(2000), '')}
    flat = ', '.join(repr(float(v)) for v in crowd.reshape(-1))
    node = [python, '-m', 'cone_feeder_sim.ros.sim_node', '--ros-args', '-p',
            'record_path:=run.mcap', '-p', 'feed.rate:=0.0', '-p',
            f'initial_pieces.positions:=[{flat}]', '-p',
            f'initial_pieces.d:=[{", ".join(["225.0"] * len(crowd))}]']
    cases = {
        'run, 70-piece island, coupling exact': [
            python, '-m', 'cone_feeder_sim.cli', 'run', 'crowd.yaml', '--events', 'e.csv',
            '--mcap', 'run.mcap', '--quiet'],
        'run, 70-piece island, coupling island': [
            python, '-m', 'cone_feeder_sim.cli', 'run', 'island.yaml', '--events', 'e.csv',
            '--mcap', 'run.mcap', '--quiet'],
        'run, 2,000 pieces alone': [
            python, '-m', 'cone_feeder_sim.cli', 'run', 'alone.yaml', '--events', 'e.csv',
            '--mcap', 'run.mcap', '--quiet'],
        'sim_node, 70-piece island, coupling exact': node + [
            '-p', 'interactions.coupling:=exact'],
        'sim_node, 70-piece island, coupling island': node,
    }
    print(f'{"case":>46} {"signal":>7} {"exit after the signal (s): median, max":>40}')
    for label, command in cases.items():
        for signum in (signal.SIGINT, signal.SIGTERM):
            took = [measure(command, args.after, signum, files) for _ in range(args.repeat)]
            print(f'{label:>46} {signum.name:>7} {statistics.median(took):>20.3f} '
                  f'{max(took):>8.3f}')


if __name__ == '__main__':
    main()
