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

"""Smoke test of benchmarks/bench_node.py: it runs and prints its table (no timing checks)."""

from pathlib import Path
import subprocess
import sys

from workers import random_domain

BENCH = Path(__file__).resolve().parent.parent / 'benchmarks' / 'bench_node.py'


def test_benchmark_runs_and_reports_rows() -> None:
    proc = subprocess.run(
        [sys.executable, str(BENCH), '--scenario', 'sliding', '--counts', '20', '40',
         '--ticks', '3', '--warmup', '1', '--cpu', '-1',
         '--domain', str(random_domain())],
        capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = [line.split() for line in proc.stdout.splitlines() if not line.startswith('#')]
    assert [int(row[0]) for row in rows] == [20, 40]
    # ticks run: at least those asked (one more may be under way when the bench pauses)
    assert all(int(row[1]) >= 3 and float(row[6]) > 0 for row in rows)
