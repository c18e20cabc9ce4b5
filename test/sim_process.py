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
Helpers for the node tests: a private rclpy Context with an executor and a client node.

:class:`Client` talks to a node run as its own process (:class:`SimProcess`) over ROS 2;
:class:`InProcess` also spins the node under test, created in the test's own process.
"""

from collections.abc import Callable, Sequence
import os
from pathlib import Path
import signal
import subprocess
import time
from typing import Any, Self

from geometry_msgs.msg import Pose, PoseArray
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from workers import random_domain

#: Generous wait for a fresh process's first message: it imports rclpy and loads (or, on
#: the first start, compiles) the numba kernels.
FIRST_MESSAGE_TIMEOUT = 120.0


class SimProcess:
    """A node started as a child process; stopped with SIGINT, killed if it hangs."""

    def __init__(self, command: Sequence[str], domain: int, log_path: Path,
                 env: dict[str, str] | None = None, cwd: Path | None = None) -> None:
        """Start the process with ROS_DOMAIN_ID = domain, output to log_path."""
        self.domain = domain
        self.log_path = log_path
        full_env = dict(os.environ if env is None else env)
        full_env['ROS_DOMAIN_ID'] = str(domain)
        full_env['PYTHONUNBUFFERED'] = '1'
        full_env['RCUTILS_LOGGING_BUFFERED_STREAM'] = '0'
        self._log = log_path.open('wb')
        self.proc = subprocess.Popen(list(command), env=full_env, cwd=cwd, stdout=self._log,
                                     stderr=subprocess.STDOUT)

    def log(self) -> str:
        """Return what the process wrote so far."""
        return self.log_path.read_text(errors='replace')

    def alive(self) -> bool:
        """Tell whether the process is still running."""
        return self.proc.poll() is None

    def stop(self, timeout: float = 20.0) -> int:
        """Send SIGINT and wait; kill the process if it does not end. Return its status."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10.0)
        self._log.close()
        return self.proc.returncode


class Client:
    """
    A test node in its own context on the given domain, with spin helpers.

    ``node`` is the client node; :meth:`add` lets the executor spin more nodes (those of an
    in-process test). close() destroys them all; ``with Client(...) as client:`` closes too.
    """

    def __init__(self, domain: int, namespace: str = '', *, name: str = 'process_test_client',
                 timeout: float = 30.0, spin_step: float = 0.02) -> None:
        """Create the context, the node and an executor; timeout: spin_until's default."""
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list[Node] = []
        self.timeout = timeout
        self.spin_step = spin_step
        self.node = self.add(Node(name, namespace=namespace, context=self.context))

    def __enter__(self) -> Self:
        """Return the client (closed at the end of the with block)."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Close the client."""
        self.close()

    def add(self, node: Node) -> Any:
        """Let the executor spin ``node`` (destroyed by close()) and return it."""
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def spin_until(self, condition: Callable[[], bool], timeout: float | None = None) -> bool:
        """Spin until condition() holds; False after timeout seconds (None: the default)."""
        end = time.monotonic() + (self.timeout if timeout is None else timeout)
        while not condition():
            if time.monotonic() > end:
                return False
            self.executor.spin_once(timeout_sec=self.spin_step)
        return True

    def spin_for(self, seconds: float) -> None:
        """Spin for a while (to let messages in while nothing specific is awaited)."""
        self.spin_until(lambda: False, seconds)

    def call(self, srv_type: Any, name: str, request: Any, timeout: float = 30.0,
             ready_timeout: float | None = None) -> Any:
        """
        Call a service and return its response (fail the test if there is none).

        ready_timeout: how long to wait for the service (None: timeout), timeout: for the
        answer.
        """
        client = self.node.create_client(srv_type, name)
        try:
            ready = self.spin_until(
                client.service_is_ready, timeout if ready_timeout is None else ready_timeout)
            assert ready, f'no service {name}'
            future = client.call_async(request)
            assert self.spin_until(future.done, timeout), f'{name} did not answer'
            return future.result()
        finally:
            self.node.destroy_client(client)

    def close(self) -> None:
        """Destroy the nodes and shut the context down."""
        self.executor.shutdown()
        for node in self.nodes:
            node.destroy_node()
        self.context.try_shutdown()


class InProcess(Client):
    """
    A client on a random domain for a test that runs the node under test in its process.

    ``client`` is the client node (``node``); the node under test is added with add().
    """

    def __init__(self, name: str, *, timeout: float, spin_step: float) -> None:
        """Create the context, the client node ``name`` and the executor."""
        super().__init__(random_domain(), name=name, timeout=timeout, spin_step=spin_step)
        self.client = self.node


def wait_for_log(process: SimProcess, client: Client, text: str, timeout: float) -> bool:
    """Spin the client until the process's output contains text."""
    return client.spin_until(lambda: text in process.log(), timeout)


def pose_array(*points: tuple[float, float, float], frame: str = 'feeder') -> PoseArray:
    """Return a PoseArray in ``frame`` with a pose at each (x, y, z) point."""
    msg = PoseArray()
    msg.header.frame_id = frame
    for x, y, z in points:
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = x, y, z
        msg.poses.append(pose)
    return msg
