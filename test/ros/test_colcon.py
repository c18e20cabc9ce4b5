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
The package as a ROS 2 workspace sees it: colcon build, ament index, `ros2 run` lookup.

The source is copied to a temporary workspace (so no build/, install/ or log/ lands in the
repository), built with colcon, and the install space is sourced with its setup.bash. The
executables are then found exactly as `ros2 run cone_feeder_sim sim_node` finds them:
ament_index_python.get_package_prefix(), then <prefix>/lib/cone_feeder_sim/<executable>; the
config files and the launch file (`ros2 launch cone_feeder_sim sim.launch.py`) in its share
directory.
The installed node is started with the installed config and driven over ROS 2; the example
controller runs beside it. The build leaves numba's cache warm in the install (setup.py's
install step: the kernels the README's set-up compiled in the source tree are copied with the
source, and whatever they lack is compiled), so the node's first start loads its kernels from
the install's cache; where the source tree has none, the build compiles them (about a minute
on a free core).
"""

from collections.abc import Iterator
import importlib.util
import os
from pathlib import Path
import random
import shutil
import subprocess
import sys
from typing import Any

from ament_index_python.packages import get_package_prefix, get_package_share_directory
import pytest
from sensor_msgs.msg import JointState
from sim_process import Client, FIRST_MESSAGE_TIMEOUT, random_domain, SimProcess
from std_msgs.msg import Float64

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = 'cone_feeder_sim'
IGNORE = shutil.ignore_patterns('build', 'install', 'log', '__pycache__', '.git', '*.egg-info',
                                '.pytest_cache', '.ruff_cache', 'runs', '.venv', '.ci-venv')

SPEED = 5.0  # rad/s, the example controller's speed in this test

pytestmark = pytest.mark.slow


@pytest.fixture(scope='module')
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    # colcon of this interpreter, so that the build and the installed scripts use it too
    if importlib.util.find_spec('colcon_core') is None:
        pytest.skip('colcon is not installed for this Python')
    base = tmp_path_factory.mktemp('ws')
    before = {p.name for p in ROOT.iterdir()}
    src = base / 'src' / PACKAGE
    shutil.copytree(ROOT, src, ignore=IGNORE)
    for cached in (ROOT / PACKAGE).glob('**/__pycache__/*.nb[ic]'):  # what set-up compiled
        copy = src / cached.relative_to(ROOT)
        copy.parent.mkdir(exist_ok=True)
        shutil.copy2(cached, copy)
    proc = subprocess.run(
        [sys.executable, '-m', 'colcon', '--log-base', str(base / 'log'), 'build',
         '--base-paths', str(base / 'src'), '--build-base', str(base / 'build'),
         '--install-base', str(base / 'install')],
        cwd=base, capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    new_in_repo = {p.name for p in ROOT.iterdir()} - before
    installed, = (base / 'install' / PACKAGE / 'lib').glob(f'python3*/site-packages/{PACKAGE}')
    yield {'base': base, 'install': base / 'install', 'src': src, 'new_in_repo': new_in_repo,
           'installed': installed}


def sourced_env(install: Path) -> dict[str, str]:
    """Return the environment after `source <install>/setup.bash` (as a user would)."""
    env = dict(os.environ)
    env.pop('PYTHONPATH', None)
    env.pop('AMENT_PREFIX_PATH', None)
    env.pop('COLCON_PREFIX_PATH', None)
    out = subprocess.run(['bash', '-c', f'source "{install}/setup.bash" && env -0'],
                         env=env, capture_output=True, check=True, timeout=60).stdout
    return dict(item.split('=', 1) for item in out.decode().split('\0') if '=' in item)


def test_build_leaves_the_source_clean(workspace: dict[str, Any]) -> None:
    outputs = {'build', 'install', 'log'}
    assert not {p.name for p in workspace['src'].iterdir()} & outputs
    assert not list(workspace['src'].glob('*.egg-info'))
    assert not workspace['new_in_repo'] & outputs
    assert (workspace['install'] / PACKAGE / 'lib' / PACKAGE / 'sim_node').is_file()


def test_ros2_run_lookup_finds_and_runs_the_installed_node(
        workspace: dict[str, Any], monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    env = sourced_env(workspace['install'])
    monkeypatch.setenv('AMENT_PREFIX_PATH', env['AMENT_PREFIX_PATH'])
    # what `ros2 run cone_feeder_sim sim_node` does
    prefix = Path(get_package_prefix(PACKAGE))
    assert prefix == workspace['install'] / PACKAGE
    executables = prefix / 'lib' / PACKAGE
    sim_node = executables / 'sim_node'
    controller = executables / 'example_controller'
    assert os.access(sim_node, os.X_OK) and os.access(controller, os.X_OK)
    share = Path(get_package_share_directory(PACKAGE))
    config = share / 'config' / 'sim_node.yaml'
    assert config.is_file() and (share / 'config' / 'table2.yaml').is_file()
    for name in ('foxglove_layout.json', 'paper_table1_exits.csv'):  # not only YAML files
        assert (share / 'config' / name).is_file(), name
    # `ros2 launch cone_feeder_sim sim.launch.py` finds the launch file here
    launch_file = share / 'launch' / 'sim.launch.py'
    assert launch_file.is_file()
    assert launch_file.read_bytes() == (ROOT / 'launch' / 'sim.launch.py').read_bytes()
    # the installed package is the one imported, not the source tree
    where = subprocess.run([sys.executable, '-c', 'import cone_feeder_sim; '
                            'print(cone_feeder_sim.__file__)'], env=env, cwd=tmp_path,
                           capture_output=True, text=True, check=True).stdout
    assert where.startswith(str(prefix))

    domain = random_domain()
    namespace = f'/colcon{random.randrange(1_000_000)}'
    node = SimProcess([str(sim_node), '--ros-args', '--params-file', str(config), '-r',
                       f'__ns:={namespace}'], domain, tmp_path / 'sim_node.log', env=env,
                      cwd=tmp_path)
    ctl = None
    client = Client(domain, namespace=namespace)
    try:
        states: list[JointState] = []
        commands: list[Float64] = []
        client.node.create_subscription(JointState, 'cone_state', states.append, 10)
        client.node.create_subscription(Float64, 'rotation_cmd', commands.append, 10)
        assert client.spin_until(lambda: bool(states) or not node.alive(),
                                 FIRST_MESSAGE_TIMEOUT + 60.0), node.log()
        assert states, node.log()
        assert states[0].name == ['cone']
        # the example controller takes over from the open-loop pattern
        ctl = SimProcess([str(controller), '--ros-args', '-p', f'speed:={SPEED}', '-r',
                          f'__ns:={namespace}'], domain, tmp_path / 'controller.log',
                         env=env, cwd=tmp_path)
        assert client.spin_until(lambda: len(commands) >= 3 or not ctl.alive(), 60.0), \
            ctl.log()
        assert commands, ctl.log()
        assert all(abs(c.data) == SPEED for c in commands)
        # the cone follows: it reaches the controller's speed (the pattern uses 8 rad/s)
        assert client.spin_until(lambda: abs(abs(states[-1].velocity[0]) - SPEED) < 1e-9,
                                 30.0)
        assert node.alive() and ctl.alive()
    finally:
        client.close()
        status = node.stop()
        if ctl is not None:
            ctl.stop()
    assert status == 0, node.log()
    assert 'Traceback' not in node.log()
    # the build left the kernels in the install's cache: the first start compiled nothing
    cache = workspace['installed'].resolve() / 'physics' / '__pycache__'
    assert 'numba kernels loaded from the cache in' in node.log(), node.log()
    assert f'(cache: {cache})' in node.log(), node.log()
