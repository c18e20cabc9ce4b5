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
Copyright and license headers.

Where ament_copyright is installed (ROS 2 from apt) it runs as in every ament_python
package. The PyPI ROS wheels do not ship it, so there the same requirement is checked
directly: every Python file starts with a copyright line and the Apache-2.0 notice.
"""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
NOTICE = 'Licensed under the Apache License, Version 2.0'
SKIP_DIRS = {'build', 'install', 'log', '.git', '.venv', '.ci-venv', 'runs'}


def python_files() -> list[Path]:
    """Return the repository's Python files outside build and tool directories."""
    return sorted(p for p in ROOT.rglob('*.py')
                  if not SKIP_DIRS.intersection(p.relative_to(ROOT).parts))


@pytest.mark.copyright
@pytest.mark.linter
def test_copyright() -> None:
    try:
        from ament_copyright.main import main
    except ImportError:
        main = None
    if main is not None:
        rc = main(argv=['.', 'test'])
        assert rc == 0, 'Found errors'
        return
    missing = []
    for path in python_files():
        head = path.read_text(encoding='utf-8').splitlines()[:15]
        has_notice = any(NOTICE in line for line in head)
        if not (head and head[0].startswith('# Copyright ') and has_notice):
            missing.append(str(path.relative_to(ROOT)))
    assert not missing, 'files without the copyright and Apache-2.0 header: ' + ', '.join(
        missing)
    assert len(python_files()) > 10
