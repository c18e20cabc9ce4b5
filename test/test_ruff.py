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

"""ruff over the repository (skipped where ruff is not installed, e.g. a plain apt ROS)."""

from pathlib import Path
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.linter
def test_ruff() -> None:
    ruff = pytest.importorskip('ruff')
    binary = ruff.find_ruff_bin() if hasattr(ruff, 'find_ruff_bin') else 'ruff'
    proc = subprocess.run([str(binary), 'check', str(ROOT)], capture_output=True, text=True,
                          cwd=ROOT, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert sys.version_info >= (3, 10)
