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
The nodes' common frame: :class:`GuardedNode` and :func:`run_node`, every executable's main.

A :class:`GuardedNode` makes its handles in ``_setup`` and destroys what it made when that
fails. :func:`run_node` is the ``main()`` of every node of the package, written once: it
initialises rclpy (one line and exit status 1 on a bad command line), builds the node (one
``cannot start`` line and status 1 on a refused parameter or file), spins it until it is
done or shut down (SIGINT and SIGTERM: rclpy's handlers shut the context down), and destroys
it in every path with both signals blocked, so that a second Ctrl-C cannot cut short what
``destroy_node`` finishes (a node's recording).
"""

from collections.abc import Callable
import signal
import sys
from typing import Any

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from ..errors import ConeFeederError

__all__ = ['GuardedNode', 'init_or_exit', 'run_node']


class GuardedNode(Node):
    """
    A node whose handles are made by :meth:`_setup`, called from ``__init__``.

    When ``_setup`` raises (a refused parameter, an unreadable file), the handles already
    made are destroyed before the error propagates, so a refused start leaves nothing behind
    in the context.
    """

    def __init__(self, default_name: str, **kwargs: Any) -> None:
        """Create the node (``node_name`` overrides ``default_name``), then call _setup()."""
        super().__init__(kwargs.pop('node_name', default_name), **kwargs)
        try:
            self._setup()
        except BaseException:
            self.destroy_node()
            raise

    def _setup(self) -> None:
        """Declare parameters and create the node's handles; overridden by each node."""
        raise NotImplementedError

    def log_at_exit(self, level: str, text: str) -> None:
        """Log at ``level`` also at shutdown: after a signal the context, and /rosout, are gone."""
        if self.context.ok():
            getattr(self.get_logger(), level)(text)
        else:
            sys.stderr.write(f'[{level.upper()}] [{self.get_name()}]: {text}\n')


def init_or_exit(args: list[str] | None, name: str) -> bool:
    """
    Initialise rclpy; on a bad command line or parameter file, print one line and say no.

    rcl reports an unparsable ``--params-file`` by raising from ``rclpy.init``; a node's
    ``main`` returns 1 when this returns False, with no traceback.
    """
    try:
        rclpy.init(args=args)
    except RuntimeError as exc:  # rclpy's RCLError
        sys.stderr.write(f'[FATAL] [{name}]: cannot start: {exc}\n')
        return False
    return True


def run_node(make: Callable[[], Node], name: str, args: list[str] | None = None, *,
             spin: Callable[[Node], None] = rclpy.spin, refusal: str = 'cannot start') -> int:
    """
    Run a node until it is done or shut down; return the process exit status.

    make: builds the node (after rclpy is initialised); name: the node's default name, for
    the log lines written before it exists; spin: how to run it (default ``rclpy.spin``;
    a node with an end spins until its future completes); refusal: the words of the fatal
    line when the node refuses to start (a ConeFeederError or a rejected parameter).
    """
    if not init_or_exit(args, name):
        return 1
    node = None
    status = 0
    try:
        node = make()
        spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ConeFeederError, ParameterException) as exc:
        rclpy.logging.get_logger(name).fatal(f'{refusal}: {exc}')
        status = 1
    except Exception:  # noqa: B902 - only to tell a shutdown race from a real error
        if rclpy.ok():
            raise
        # SIGINT/SIGTERM shut the context down while the executor built its wait set
    finally:
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        try:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
        finally:
            # a second Ctrl-C that arrived meanwhile is dropped, not raised on unblocking
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    return status
