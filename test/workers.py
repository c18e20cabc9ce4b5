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
What each pytest-xdist worker may use alone: its block of ROS domain ids.

The README's test command runs the suite on every core (``-n auto``). Nodes of two workers
on one ROS domain would hear each other, so every worker draws its domains from a block of
its own; without xdist the one process has them all.
"""

import os
import random

#: Domain ids the tests use, ends included (Fast DDS takes 0-232; the low ones are left to
#: whatever else runs on the machine).
DOMAIN_RANGE = (100, 229)


def worker_domains() -> range:
    """Return the ROS domain ids of this test process (its xdist worker's block)."""
    count = max(1, int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1')))
    index = int(os.environ.get('PYTEST_XDIST_WORKER', 'gw0').removeprefix('gw') or 0)
    total = DOMAIN_RANGE[1] - DOMAIN_RANGE[0] + 1
    size = max(1, total // count)
    start = DOMAIN_RANGE[0] + (index * size) % total
    return range(start, start + size)


def random_domain() -> int:
    """Return a ROS_DOMAIN_ID for one test run, from this worker's block."""
    return random.choice(worker_domains())
