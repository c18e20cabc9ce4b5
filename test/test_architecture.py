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
The rooms of the package import one way (doc/architecture.md).

physics <- feeder <- formats, view <- report, sweep, rl, fit <- ros, cli: a module imports
only from its own room and the rooms before it (ros uses rl in policy_controller only);
physics imports no rclpy, mcap or yaml; nothing below ros imports rclpy or ROS message
packages; in ros, the ticker, the input handling and what they use are free of them too
(their tests drive them without ROS).
"""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / 'cone_feeder_sim'
#: Rank of each room; physics and weigher, ros, report and sweep are side by side.
RANK = {'errors': 0, '__init__': 0, 'physics': 1, 'weigher': 1, 'feeder': 2, 'formats': 3,
        'view': 3, 'report': 4, 'sweep': 4, 'rl': 4, 'fit': 4, 'twin': 4, 'ros': 5, 'cli': 5}
SIDE_BY_SIDE = ('report', 'sweep', 'rl', 'fit', 'twin')
#: Rooms that must not import each other although one ranks after the other.
APART = {('ros', 'report'), ('ros', 'sweep'), ('ros', 'fit'), ('cli', 'ros')}
#: The optional dependency of the sweep: imported by its Dask modules only.
DASK_MODULES = {'sweep/cluster.py', 'sweep/run.py'}
#: The optional dependencies of the RL environment, and the modules that may import them.
RL_PACKAGES = {'gymnasium': 'rl/', 'stable_baselines3': 'rl/sb3.py', 'torch': 'rl/sb3.py'}
#: The one ROS module that uses the RL room (and so gymnasium and stable-baselines3).
RL_USERS = {'ros/policy_controller.py'}
ROS_PACKAGES = {'rclpy', 'rcl_interfaces', 'std_msgs', 'std_srvs', 'geometry_msgs',
                'sensor_msgs', 'visualization_msgs', 'diagnostic_msgs', 'rosgraph_msgs',
                'builtin_interfaces'}  # ament_index_python: an optional look-up of files
MODULES = sorted(PACKAGE.rglob('*.py'))
#: Modules of the ros room that import no ROS package, nor a module of ros that does.
ROS_FREE = {'ros/ticker.py', 'ros/inputs.py', 'ros/pacing.py', 'ros/diagnostics.py'}


def room(parts: tuple[str, ...]) -> str:
    """Return the room of a module given by its parts below the package."""
    return parts[0].removesuffix('.py')


def imports(path: Path) -> list[tuple[str, str | None]]:
    """Return (top-level package, room within cone_feeder_sim or None) of every import."""
    parts = path.relative_to(PACKAGE).parts
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found += [(alias.name.split('.')[0], None) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                top = (node.module or '').split('.')[0]
                inner = (node.module or '').split('.')[1:2]
                found.append((top, inner[0] if top == 'cone_feeder_sim' and inner else None))
                continue
            base = list(parts[:-1])[:len(parts) - node.level]
            target = base + (node.module.split('.') if node.module else [])
            if not target:  # 'from .. import x' at the top: x is a module or a name
                name = node.names[0].name
                target = [name if name in RANK else '__init__']
            found.append(('cone_feeder_sim', target[0]))
    return found


@pytest.mark.parametrize('path', MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_run_one_way(path: Path) -> None:
    source = room(path.relative_to(PACKAGE).parts)
    for top, target in imports(path):
        if top == 'cone_feeder_sim' and target is not None:
            target = target.removesuffix('.py')
            assert RANK[target] <= RANK[source], f'{source} imports {target}'
            assert source == target or not {source, target} <= set(SIDE_BY_SIDE), (
                f'{source} imports {target}')
            assert (source, target) not in APART, f'{source} imports {target}'
        if target == 'rl' and source != 'rl':
            assert str(path.relative_to(PACKAGE)) in RL_USERS, f'{path.name} imports rl'
        if RANK[source] < RANK['ros']:
            assert top not in ROS_PACKAGES, f'{source} imports {top}'
        if str(path.relative_to(PACKAGE)) not in DASK_MODULES:
            assert top not in {'dask', 'distributed'}, f'{path.name} imports {top}'
        for package, where in RL_PACKAGES.items():
            assert top != package or str(path.relative_to(PACKAGE)).startswith(where), (
                f'{path.name} imports {top}')
        if source == 'physics':
            assert top not in {'mcap', 'yaml', 'rosbags', 'matplotlib'}, top


def test_every_module_is_in_a_room() -> None:
    assert {room(p.relative_to(PACKAGE).parts) for p in MODULES} <= set(RANK)


@pytest.mark.parametrize('name', sorted(ROS_FREE))
def test_the_ticker_and_the_inputs_are_free_of_ros(name: str) -> None:
    path = PACKAGE / name
    for top, _ in imports(path):
        assert top not in ROS_PACKAGES, f'{name} imports {top}'
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1:  # a sibling in ros
            assert f'ros/{node.module}.py' in ROS_FREE, f'{name} imports .{node.module}'
