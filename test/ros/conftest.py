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

"""Fixtures of the node tests."""

from collections.abc import Iterator

import pytest
import rclpy
from rclpy.context import Context
from workers import random_domain


@pytest.fixture
def context() -> Iterator[Context]:
    """Return an rclpy context of its own (a domain id of this worker's), shut down after."""
    ctx = Context()
    rclpy.init(context=ctx, domain_id=random_domain())
    try:
        yield ctx
    finally:
        ctx.try_shutdown()
