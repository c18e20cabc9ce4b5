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

"""Helpers for tests that run sim_node as its own process and talk to it over ROS 2."""

from collections.abc import Callable, Sequence
import os
from pathlib import Path
import random
import signal
import subprocess
import time
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

#: Domain ids used by the process tests; one is drawn per run to isolate it.
DOMAIN_RANGE = (100, 200)
#: Generous wait for a fresh process's first message: it imports rclpy and loads (or, on
#: the first start, compiles) the numba kernels.
FIRST_MESSAGE_TIMEOUT = 120.0


def random_domain() -> int:
    """Return a ROS_DOMAIN_ID for one test run."""
    return random.randint(*DOMAIN_RANGE)


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
    """A test node in its own context on the given domain, with spin helpers."""

    def __init__(self, domain: int, namespace: str = '') -> None:
        """Create the context, the node and an executor."""
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = Node('process_test_client', namespace=namespace, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_until(self, condition: Callable[[], bool], timeout: float) -> bool:
        """Spin until condition() holds; False after timeout seconds."""
        end = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > end:
                return False
            self.executor.spin_once(timeout_sec=0.02)
        return True

    def spin_for(self, seconds: float) -> None:
        """Spin for a while (to let messages in while nothing specific is awaited)."""
        self.spin_until(lambda: False, seconds)

    def call(self, srv_type: Any, name: str, request: Any, timeout: float = 30.0) -> Any:
        """Call a service and return its response (fail the test if there is none)."""
        client = self.node.create_client(srv_type, name)
        try:
            assert self.spin_until(client.service_is_ready, timeout), f'no service {name}'
            future = client.call_async(request)
            assert self.spin_until(future.done, timeout), f'{name} did not answer'
            return future.result()
        finally:
            self.node.destroy_client(client)

    def close(self) -> None:
        """Destroy the node and shut the context down."""
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


def wait_for_log(process: SimProcess, client: Client, text: str, timeout: float) -> bool:
    """Spin the client until the process's output contains text."""
    return client.spin_until(lambda: text in process.log(), timeout)
