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
Print the constraints file of this environment: every distribution pip installed, pinned.

Run by scripts/refresh_constraints.sh after the suite passed. The package itself (an
editable install) and the packages the ROS wheels unpack themselves (their egg-info
directories: pip never resolves them) are left out; pip is left out, setuptools kept (the
colcon build test needs an old one). Local version labels are dropped (``torch==2.13.0``
admits this disk's 2.13.0+cpu and PyPI's 2.13.0 alike).
"""

import datetime
import importlib.metadata
import platform
import sys


def pinned() -> list[str]:
    """Return 'name==version' of every distribution pip installed here, sorted by name."""
    pins = {}
    for dist in importlib.metadata.distributions():
        name = dist.metadata['Name']
        installer = (dist.read_text('INSTALLER') or '').strip()
        if installer != 'pip' or name in ('pip', 'cone_feeder_sim', 'cone-feeder-sim'):
            continue
        if dist.read_text('direct_url.json') and 'editable' in dist.read_text('direct_url.json'):
            continue
        # without a local label (torch 2.13.0+cpu): == 2.13.0 admits the builds of any index
        pins[name.lower()] = f'{name}=={dist.version.split("+")[0]}'
    return [pins[key] for key in sorted(pins)]


def main() -> None:
    """Write the file to standard output."""
    today = datetime.date.today().isoformat()
    print('# The exact versions the test suite last passed with (a constraints file: it pins,')
    print('# it does not ask for anything). scripts/setup_venv.sh and CI install with it;')
    print('# the floors for users and packagers stay in runtime.txt. Refresh: README,')
    print('# "Dependencies". Written by scripts/freeze_constraints.py on '
          f'{today}, Python {platform.python_version()}, {sys.platform}.')
    for line in pinned():
        print(line)


if __name__ == '__main__':
    main()
