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

"""Smoke test of benchmarks/bench_states.py: every state runs and prints a row (no timing)."""

from pathlib import Path
import subprocess
import sys

BENCH = Path(__file__).resolve().parent.parent / 'benchmarks' / 'bench_states.py'


def test_benchmark_runs_every_state() -> None:
    proc = subprocess.run([sys.executable, str(BENCH), '--pieces', '4', '8'],
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith('calibration:')
    rows = [line.split() for line in lines if line and not line.startswith(('#', 'calib'))]
    rows = [row for row in rows if row[0] != 'state']
    assert [(row[0], int(row[1])) for row in rows] == [
        (state, n) for state in ('resting', 'turning', 'dropped', 'reversing') for n in (4, 8)]
    # falling and landing pieces cost more steps than the same pieces at rest
    steps = {(row[0], int(row[1])): float(row[3]) for row in rows}
    assert steps['resting', 8] < steps['dropped', 8]
