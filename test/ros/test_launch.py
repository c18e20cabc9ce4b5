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
The launch file ``launch/sim.launch.py``.

``launch`` and ``launch_ros`` are not on PyPI, so the file is read without them: it is
parsed with ``ast`` and the expression ``generate_launch_description`` returns,
``LaunchDescription([...])``, is turned into plain values (a call becomes ``(name, args,
keywords)``, a variable its value). That reading checks the launch arguments and their
defaults, the nodes (package, executables, namespace, parameters, condition) and that what
the file names exists: console scripts in ``setup.py``, the node's name in the key of
``config/sim_node.yaml``, the parameters it overrides, its install location in ``setup.py``'s
``data_files`` and its imports as ``exec_depend`` in ``package.xml``. Where ``launch`` is
importable the file is also loaded by launch itself; where the ``ros2`` command is on the
PATH and the package is installed in the sourced workspace, ``ros2 launch`` is run and the
nodes are checked over ROS 2. ``test_colcon.py`` checks the installed file after a build.
"""

import ast
from collections.abc import Callable
import glob
import importlib.util
from pathlib import Path
import random
import re
import shutil
import subprocess
from typing import Any
import xml.etree.ElementTree as ElementTree

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = 'cone_feeder_sim'
LAUNCH_FILE = ROOT / 'launch' / 'sim.launch.py'
#: The launch arguments and their defaults (README, the launch file's docstring).
LITERAL_DEFAULTS = {'namespace': '', 'use_sim_time': 'false', 'with_controller': 'false'}
ARGUMENTS = {*LITERAL_DEFAULTS, 'params_file'}


def call(name: str, /, *args: Any, **keywords: Any) -> tuple[str, tuple[Any, ...], dict]:
    """Return a call as the reader gives it."""
    return (name, args, keywords)


def config(name: str) -> tuple[str, tuple[Any, ...], dict]:
    """Return ``LaunchConfiguration(name)`` as the reader gives it."""
    return call('LaunchConfiguration', name)


#: The default of params_file: the package's installed config/sim_node.yaml.
PARAMS_DEFAULT = call('PathJoinSubstitution',
                      [call('FindPackageShare', PACKAGE), 'config', 'sim_node.yaml'])


class Reader:
    """
    Plain values of the expressions of a Python file, without running it.

    Variables are looked up among the module's assignments and those of ``function``; calls
    named in ``functions`` are evaluated, other calls read as ``(name, args, keywords)``.
    """

    def __init__(self, path: Path, function: str | None = None,
                 functions: dict[str, Callable[..., Any]] | None = None) -> None:
        """Parse the file."""
        self.path = path
        self.tree = ast.parse(path.read_text(), str(path))
        self.functions = functions or {}
        self.function = None
        scopes = [self.tree.body]
        for stmt in self.tree.body:
            if isinstance(stmt, ast.FunctionDef) and stmt.name == function:
                self.function = stmt
                scopes.append(stmt.body)
        self.names: dict[str, ast.expr] = {}
        for scope in scopes:
            for stmt in scope:
                if (isinstance(stmt, ast.Assign) and len(stmt.targets) == 1
                        and isinstance(stmt.targets[0], ast.Name)):
                    self.names[stmt.targets[0].id] = stmt.value

    def value(self, node: ast.expr) -> Any:
        """Return the plain value of an expression."""
        if isinstance(node, ast.Name) and node.id in self.names:
            return self.value(self.names[node.id])
        if isinstance(node, ast.Constant):
            return node.value
        if isinstance(node, (ast.List, ast.Tuple)):
            return [self.value(e) for e in node.elts]
        if isinstance(node, ast.Dict) and None not in node.keys:
            return {self.value(k): self.value(v) for k, v in zip(node.keys, node.values)}
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
            return self.value(node.left) + self.value(node.right)
        if isinstance(node, ast.Call):
            name = call_name(node)
            args = [self.value(a) for a in node.args]
            keywords = {k.arg: self.value(k.value) for k in node.keywords}
            if name in self.functions:
                return self.functions[name](*args, **keywords)
            return call(name, *args, **keywords)
        raise AssertionError(f'{self.path.name}:{node.lineno}: cannot read {ast.unparse(node)}')

    def calls(self, name: str) -> list[ast.Call]:
        """Return the calls of ``name`` in the file."""
        return [n for n in ast.walk(self.tree) if isinstance(n, ast.Call) and call_name(n) == name]


def call_name(node: ast.Call) -> str:
    """Return the name a call is made by (``f`` of ``f()`` and ``m.f()``)."""
    func = node.func
    return func.id if isinstance(func, ast.Name) else getattr(func, 'attr', '')


def importable(module: str) -> bool:
    """
    Tell whether a package is installed.

    Not merely found: with the repository root on sys.path, its ``launch/`` folder would
    be found as a namespace package named ``launch``.
    """
    spec = importlib.util.find_spec(module)
    return spec is not None and spec.origin is not None


def launch_entities() -> list[Any]:
    """Return the entities of ``LaunchDescription([...])`` the launch function returns."""
    reader = Reader(LAUNCH_FILE, 'generate_launch_description')
    function = reader.function
    assert function is not None, 'no module-level generate_launch_description()'
    assert not function.args.args and not function.args.posonlyargs
    returns = [n for n in ast.walk(function) if isinstance(n, ast.Return)]
    assert len(returns) == 1 and returns[0].value is not None
    name, args, keywords = reader.value(returns[0].value)
    assert name == 'LaunchDescription' and len(args) == 1 and not keywords
    return args[0]


def launch_arguments() -> dict[str, dict[str, Any]]:
    """Return the keywords of each DeclareLaunchArgument by argument name."""
    found = {}
    for name, args, keywords in launch_entities():
        if name == 'DeclareLaunchArgument':
            arg_name = args[0] if args else keywords.pop('name')
            assert arg_name not in found, f'{arg_name} declared twice'
            found[arg_name] = keywords
    return found


def launch_nodes() -> dict[str, dict[str, Any]]:
    """Return the keywords of each launch_ros Node by executable."""
    found = {}
    for name, args, keywords in launch_entities():
        if name == 'Node':
            assert not args, 'Node() takes keywords'
            assert keywords['executable'] not in found
            found[keywords['executable']] = keywords
    return found


def setup_keywords() -> dict[str, Any]:
    """Return the keywords of setup() in setup.py, its glob() calls made in the root."""
    def in_root(pattern: str) -> list[str]:
        return sorted(glob.glob(pattern, root_dir=ROOT))

    reader = Reader(ROOT / 'setup.py', functions={'glob': in_root})
    (setup,) = reader.calls('setup')
    return {k.arg: reader.value(k.value) for k in setup.keywords if k.arg in
            ('name', 'data_files', 'entry_points')}


def test_launch_function_returns_a_launch_description() -> None:
    entities = launch_entities()
    assert {e[0] for e in entities} == {'DeclareLaunchArgument', 'Node'}
    # the file is only read here: every statement of the module is an import, an
    # assignment, the docstring or the function
    for stmt in Reader(LAUNCH_FILE).tree.body:
        assert isinstance(stmt, (ast.Import, ast.ImportFrom, ast.Assign, ast.FunctionDef,
                                 ast.Expr)), ast.unparse(stmt)


def test_launch_arguments_and_their_defaults() -> None:
    arguments = launch_arguments()
    assert set(arguments) == ARGUMENTS
    for name, default in LITERAL_DEFAULTS.items():
        assert arguments[name]['default_value'] == default, name
    assert arguments['params_file']['default_value'] == PARAMS_DEFAULT
    assert (ROOT / 'config' / 'sim_node.yaml').is_file()
    for name, keywords in arguments.items():
        assert keywords.get('description'), f'{name} has no description'
        if 'choices' in keywords:
            assert keywords['default_value'] in keywords['choices'], name
    for name in ('use_sim_time', 'with_controller'):
        assert arguments[name]['choices'] == ['true', 'false'], name
    # every LaunchConfiguration the file uses is a declared argument (no typos)
    reader = Reader(LAUNCH_FILE, 'generate_launch_description')
    used = {reader.value(c)[1][0] for c in reader.calls('LaunchConfiguration')}
    assert used == ARGUMENTS


def test_nodes() -> None:
    nodes = launch_nodes()
    assert set(nodes) == {'sim_node', 'example_controller'}
    for executable, node in nodes.items():
        assert node['package'] == PACKAGE
        assert node['name'] == executable
        assert node['namespace'] == config('namespace')
        assert node['output'] == 'screen'
    sim = nodes['sim_node']
    # the parameter file first, the launch's own values over it
    assert sim['parameters'] == [config('params_file'), {
        'use_sim_time': config('use_sim_time'), 'publish_clock': config('use_sim_time')}]
    assert 'condition' not in sim
    controller = nodes['example_controller']
    assert controller['parameters'] == [{'use_sim_time': config('use_sim_time')}]
    assert controller['condition'] == call('IfCondition', config('with_controller'))


def test_executables_are_console_scripts_of_the_package() -> None:
    keywords = setup_keywords()
    assert keywords['name'] == PACKAGE
    scripts = dict(line.replace(' ', '').split('=')
                   for line in keywords['entry_points']['console_scripts'])
    for executable in launch_nodes():
        assert executable in scripts, f'{executable} is not a console script in setup.py'
        module, function = scripts[executable].split(':')
        source = ROOT.joinpath(*module.split('.')).with_suffix('.py')
        assert source.is_file(), source
        assert function in {n.name for n in ast.parse(source.read_text()).body
                            if isinstance(n, ast.FunctionDef)}, scripts[executable]


def test_sim_node_parameters_named_by_the_launch_file_exist() -> None:
    from cone_feeder_sim.ros.parameters import parameter_specs

    names = {spec.name for spec in parameter_specs()}
    sim = launch_nodes()['sim_node']
    overridden = set(sim['parameters'][1]) - {'use_sim_time'}  # use_sim_time: every node's
    assert overridden == {'publish_clock'} and overridden <= names
    # the parameter file applies to the node by its name, in any namespace
    document = yaml.safe_load((ROOT / 'config' / 'sim_node.yaml').read_text())
    assert list(document) == [f'/**/{sim["name"]}']


def test_setup_installs_the_launch_file_and_the_config() -> None:
    installed: dict[str, list[str]] = {}
    for destination, files in setup_keywords()['data_files']:
        installed.setdefault(destination, []).extend(files)
    assert 'launch/sim.launch.py' in installed[f'share/{PACKAGE}/launch']
    assert 'config/sim_node.yaml' in installed[f'share/{PACKAGE}/config']
    assert 'package.xml' in installed[f'share/{PACKAGE}']


def test_package_xml_has_the_imports_of_the_launch_file_as_exec_depend() -> None:
    depends = {e.text for e in ElementTree.parse(ROOT / 'package.xml').getroot()
               .iter('exec_depend')}
    imported = set()
    for node in ast.walk(Reader(LAUNCH_FILE).tree):
        if isinstance(node, ast.Import):
            imported |= {alias.name.split('.')[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            imported.add((node.module or '').split('.')[0])
    assert imported == {'launch', 'launch_ros'}
    assert imported <= depends


def test_launch_loads_the_file() -> None:
    """With launch installed (ROS 2 from apt), launch itself reads the file."""
    missing = [m for m in ('launch', 'launch_ros') if not importable(m)]
    if missing:
        pytest.skip(f'{" and ".join(missing)} not importable (not on PyPI; they come with '
                    'ROS 2 Jazzy from apt); the file was read with ast instead')
    from launch import LaunchContext
    from launch.launch_description_sources import \
        get_launch_description_from_python_launch_file
    from launch.utilities import perform_substitutions
    from launch_ros.actions import Node

    description = get_launch_description_from_python_launch_file(str(LAUNCH_FILE))
    arguments = {a.name: a for a in description.get_launch_arguments()}
    assert set(arguments) == ARGUMENTS
    context = LaunchContext()
    for name, default in LITERAL_DEFAULTS.items():
        assert perform_substitutions(context, arguments[name].default_value) == default
    nodes = [e for e in description.entities if isinstance(e, Node)]
    assert sorted((n.node_package, n.node_executable) for n in nodes) == [
        (PACKAGE, 'example_controller'), (PACKAGE, 'sim_node')]


def installed_launch_file() -> str:
    """Return the ros2 command where `ros2 launch cone_feeder_sim sim.launch.py` can run."""
    ros2 = shutil.which('ros2')
    if ros2 is None:
        pytest.skip('no ros2 command on the PATH (ros2cli is not on PyPI): source ROS 2 '
                    'Jazzy and a workspace with this package built to run ros2 launch')
    if not importable('launch'):
        pytest.skip('launch is not importable by this Python')
    from ament_index_python.packages import (get_package_share_directory,
                                             PackageNotFoundError)
    try:
        share = Path(get_package_share_directory(PACKAGE))
    except PackageNotFoundError:
        pytest.skip(f'{PACKAGE} is not in the ament index: colcon build and source '
                    'install/setup.bash to run ros2 launch (test_colcon.py checks the install)')
    installed = share / 'launch' / 'sim.launch.py'
    if not installed.is_file() or installed.read_bytes() != LAUNCH_FILE.read_bytes():
        pytest.skip(f"{installed} is missing or is not this checkout's launch file: "
                    'rebuild the workspace to run ros2 launch on it')
    return ros2


def test_ros2_launch_show_args() -> None:
    ros2 = installed_launch_file()
    proc = subprocess.run([ros2, 'launch', PACKAGE, 'sim.launch.py', '--show-args'],
                          capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for name in ARGUMENTS:
        assert f"'{name}'" in proc.stdout, proc.stdout


@pytest.mark.slow
def test_ros2_launch_starts_sim_node_and_the_controller(tmp_path: Path) -> None:
    ros2 = installed_launch_file()
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from sim_process import Client, FIRST_MESSAGE_TIMEOUT, random_domain, SimProcess
    from std_msgs.msg import Float64

    domain = random_domain()
    namespace = f'/launch{random.randrange(1_000_000)}'
    # --noninteractive: launch passes SIGINT on to the nodes (as Ctrl-C in a terminal does)
    launch = SimProcess([ros2, 'launch', '--noninteractive', PACKAGE, 'sim.launch.py',
                         f'namespace:={namespace}', 'use_sim_time:=true',
                         'with_controller:=true'], domain, tmp_path / 'launch.log',
                        cwd=tmp_path)
    client = Client(domain, namespace=namespace)
    try:
        states: list[JointState] = []
        commands: list[Float64] = []
        clocks: list[Clock] = []
        client.node.create_subscription(JointState, 'cone_state', states.append, 10)
        client.node.create_subscription(Float64, 'rotation_cmd', commands.append, 10)
        client.node.create_subscription(Clock, '/clock', clocks.append, 10)
        assert client.spin_until(lambda: bool(states and commands and clocks)
                                 or not launch.alive(), FIRST_MESSAGE_TIMEOUT + 60.0), \
            launch.log()
        assert launch.alive(), launch.log()
        assert states[0].name == ['cone']
        # use_sim_time:=true turned publish_clock on: /clock carries simulation time
        assert clocks[-1].clock.sec > 0 or clocks[-1].clock.nanosec > 0
        expected = {('sim_node', namespace), ('example_controller', namespace)}
        assert client.spin_until(
            lambda: expected <= set(client.node.get_node_names_and_namespaces()), 30.0)
    finally:
        client.close()
        status = launch.stop(timeout=40.0)
    log = launch.log()
    assert status == 0, log
    for executable in ('sim_node', 'example_controller'):
        assert re.search(rf'\[{executable}-\d+\]: process has finished cleanly', log), log
    assert 'Traceback' not in log
