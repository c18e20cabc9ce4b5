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

"""A node that makes its handles in ``_setup`` and destroys what it made when that fails."""

from typing import Any

from rclpy.node import Node

__all__ = ['GuardedNode']


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
