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
Shared test set-up.

The test tree mirrors the package (``test/physics``, ``test/feeder``, ``test/io``,
``test/ros``, ``test/report``). The helpers shared between them (``reference_model``,
``msg_compare``, ``sim_process``) stay in ``test/``; pytest puts the directory of this file
on ``sys.path``, so the tests import them by name.

The README's test command runs the tests on every core with pytest-xdist: each worker has a
ROS domain of its own (``workers.py``), each test its own temporary directory and ports.
"""

import os

import numba
import pytest
from workers import SHARED_ENV, worker_domains


def pytest_configure(config: pytest.Config) -> None:
    """Give this process (an xdist worker) a ROS domain of its own, and one numba thread."""
    if getattr(config.option, 'maxworkerrestart', '') is None:
        # a worker that crashes (a segfault, pytest-timeout's thread method) is not replaced:
        # under --dist loadfile a replaced worker can leave the run waiting forever on work
        # units emptied by the crash (pytest-dev/pytest-xdist#1378, #784). The run then
        # ends with the crashed test failed and that worker's files left unrun.
        config.option.maxworkerrestart = '0'
    if getattr(config.option, 'loadscopereorder', False):
        # xdist's loadfile hands out the files with the most tests first unless told not to
        # (--no-loadscope-reorder): keep the collection's order, the slow tests' files first
        config.option.loadscopereorder = False
    os.environ['ROS_DOMAIN_ID'] = str(worker_domains()[0])
    # Fast DDS over UDP only, here and in every node a test starts. Its default adds a
    # shared-memory transport whose segments in /dev/shm all processes on the machine share,
    # so a process that dies holding one can take the others down (eProsima/Fast-DDS#6501;
    # launch_ros and system_tests turn it off in their tests). Seen here: one xdist worker
    # segfaulted in rclpy's destroy_node, then both idle workers aborted in native threads
    # and the run hung. Without SHM the workers share nothing but the network.
    os.environ.setdefault('FASTDDS_BUILTIN_TRANSPORTS', 'UDPv4')
    # Idle OpenMP threads (numba's threading layer here) sleep instead of spinning, which
    # would take the cores the other workers need: set before numba starts its threads, for
    # this process and the nodes, clusters and commands it starts.
    os.environ.setdefault('OMP_WAIT_POLICY', 'PASSIVE')
    if int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1')) > 1:
        # the workers share the cores: numba's threads of two workers spinning on the same
        # cores slow both several-fold. One thread each; the tests that compare thread
        # counts set theirs (up to NUMBA_NUM_THREADS, which stays the machine's).
        numba.set_num_threads(1)


@pytest.fixture(scope='session', autouse=True)
def shared_directory(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Under xdist, name the directory the workers of this run share (workers.shared)."""
    if os.environ.get('PYTEST_XDIST_WORKER'):
        # each worker's base is <run>/popen-gwN: the run's directory is theirs alone
        os.environ[SHARED_ENV] = str(tmp_path_factory.getbasetemp().parent)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Run the tests marked slow first, so that no worker finishes the run alone with one."""
    items.sort(key=lambda item: item.get_closest_marker('slow') is None)
