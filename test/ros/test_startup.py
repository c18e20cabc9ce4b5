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
Start-up problems are one line each, never a traceback; a start imports what it uses.

An unparsable parameter file ends the process with status 1 and one FATAL line; a misspelt
parameter name is a warning naming the closest valid name (the node starts). Without
contact between pieces, no node nor the command loads scipy's optimisers, statistics or
KD-tree.
"""

import os
from pathlib import Path
import subprocess
import sys

from cone_feeder_sim.ros import BLAS_THREADS
from cone_feeder_sim.ros.parameters import warn_unknown_parameters
from cone_feeder_sim.ros.sim_node import SimNode
import pytest
from rclpy.parameter import Parameter
import sim_process

MODULES = ('cone_feeder_sim.ros.sim_node', 'cone_feeder_sim.ros.replay_node',
           'cone_feeder_sim.ros.example_controller')


@pytest.mark.parametrize('module', MODULES)
def test_an_unparsable_parameter_file_is_one_line_and_status_1(
        tmp_path: Path, module: str) -> None:
    bad = tmp_path / 'bad.yaml'
    bad.write_text('/**/sim_node:\n  ros__parameters:\n    feed: {rate: [1,\n')
    done = subprocess.run([sys.executable, '-m', module, '--ros-args', '--params-file',
                           str(bad)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert 'Traceback' not in done.stderr + done.stdout
    fatal = [line for line in done.stderr.splitlines() if '[FATAL]' in line]
    assert len(fatal) == 1 and 'cannot start' in fatal[0] and 'bad.yaml' in fatal[0]


def test_misspelt_parameters_are_named_with_the_closest_valid_name() -> None:
    with sim_process.InProcess('test_startup', timeout=20.0, spin_step=0.02) as ros:
        node = ros.add(SimNode(context=ros.context, parameter_overrides=[
            Parameter('record_path', value=''), Parameter('feed.rat', value=3.0),
            Parameter('real_time_factr', value=2.0), Parameter('zzz', value=1)]))
        warnings = warn_unknown_parameters(node)
    assert len(warnings) == 3
    assert "'feed.rat'" in warnings[0] and "did you mean 'feed.rate'" in warnings[0]
    assert "did you mean 'real_time_factor'" in warnings[1]
    assert "'zzz'" in warnings[2] and 'did you mean' not in warnings[2]


#: What a start without contact between pieces must not import where the run does not ask for
#: it (together about 0.3 s of every such start): scipy's optimisers (cohesion's root finding,
#: which imports scipy.spatial itself), statistics (the twin's gate) and KD-tree (the live
#: view's touching pairs).
HEAVY = ('scipy.optimize', 'scipy.stats', 'scipy.spatial')
#: Takes the steps after the first argument in turn (a module to import, or SimParams: the
#: parameters of a run without contact built); prints after each step's name the modules of
#: the first argument (comma-separated) that are loaded by then.
LOADS = """
import importlib, sys
heavy = set(sys.argv[1].split(','))
for step in sys.argv[2:]:
    if step == 'SimParams':
        from cone_feeder_sim.physics.simulation import SimParams
        SimParams()
    else:
        importlib.import_module(step)
    print(step, *sorted(name for name in sys.modules if name in heavy))
"""


def test_the_nodes_and_the_command_start_without_the_heavy_parts_of_scipy() -> None:
    # one process, each step in turn: all it has loaded is printed after each step's name
    steps = (*MODULES, 'cone_feeder_sim.ros.camera_node', 'cone_feeder_sim.cli', 'SimParams')
    twin = 'cone_feeder_sim.ros.twin_node'
    done = subprocess.run([sys.executable, '-c', LOADS, ','.join(HEAVY), *steps, twin],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    loaded = dict(line.partition(' ')[::2] for line in done.stdout.splitlines())
    assert all(loaded[step] == '' for step in steps), loaded
    # the twin assigns detections with scipy's optimiser, and needs no statistics
    assert 'scipy.optimize' in loaded[twin] and 'scipy.stats' not in loaded[twin], loaded


#: Imports sys.argv[1], then numpy; prints the threads of the OpenBLAS loaded (-1: none).
BLAS = """
import ctypes, importlib, sys
importlib.import_module(sys.argv[1])
import numpy
found = -1
for path in sorted({line.split()[-1] for line in open('/proc/self/maps')
                    if 'openblas' in line.lower()}):
    lib = ctypes.CDLL(path)
    for name in ('scipy_openblas_get_num_threads64_', 'openblas_get_num_threads64_',
                 'openblas_get_num_threads'):
        if hasattr(lib, name):
            found = getattr(lib, name)()
print(found)
"""


def test_a_node_runs_blas_on_one_thread_unless_told_otherwise() -> None:
    # OpenBLAS reads these too, after its own (a runner that sets them would size the plain
    # import's threads)
    clean = {key: value for key, value in os.environ.items()
             if key not in {*BLAS_THREADS, 'GOTO_NUM_THREADS', 'OMP_NUM_THREADS'}}

    def threads(module: str, **env: str) -> int:
        done = subprocess.run([sys.executable, '-c', BLAS, module], capture_output=True,
                              text=True, timeout=120, env={**clean, **env})
        assert done.returncode == 0, done.stderr
        return int(done.stdout)

    plain = threads('json')
    if plain == -1:
        pytest.skip('this numpy loads no OpenBLAS')
    assert threads('cone_feeder_sim.ros.twin_node') == 1
    assert threads('cone_feeder_sim.ros.sim_node') == 1
    if len(os.sched_getaffinity(0)) > 1:  # else the plain import is on one thread too
        assert plain > 1
        assert threads('cone_feeder_sim.ros.twin_node', OPENBLAS_NUM_THREADS='2') == 2
