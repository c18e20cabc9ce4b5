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
What each pytest-xdist worker has alone, and what the workers share.

The README's test command runs the suite on every core (``-n auto``). Nodes of two workers
on one ROS domain would hear each other, so every worker draws its domains from a block of
its own; without xdist the one process has them all. Expensive references that tests of
several files read are computed once per run and shared (``shared``).
"""

from collections.abc import Callable
import fcntl
import functools
import hashlib
import os
from pathlib import Path
import pickle
import random
from typing import Any, TypeVar

T = TypeVar('T')

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


#: The environment variable naming a directory that every worker of this run shares (set by
#: the shared_directory fixture of conftest.py under xdist; unset: nothing shared).
SHARED_ENV = 'CONE_FEEDER_SIM_TEST_SHARED'


def shared(function: Callable[..., T]) -> Callable[..., T]:
    """
    Cache ``function``'s results for the whole test run, across the xdist workers.

    For the expensive references that tests of several files read (a crowd's reference
    solution): the first worker that needs a value computes it while holding a lock, the
    others wait and read it back (pickled in the run's shared directory). Arguments must have
    a stable repr. Without xdist, an in-memory cache.
    """
    memory = functools.cache(function)

    @functools.wraps(function)
    def wrapper(*args: Any) -> T:
        directory = os.environ.get(SHARED_ENV)
        if not directory:
            return memory(*args)
        key = hashlib.sha256(repr(args).encode()).hexdigest()[:20]
        path = Path(directory) / f'{function.__module__}.{function.__qualname__}-{key}.pickle'
        with path.with_suffix('.lock').open('w') as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if not path.exists():
                partial = path.with_suffix('.partial')
                partial.write_bytes(pickle.dumps(function(*args)))
                partial.replace(path)
        return pickle.loads(path.read_bytes())
    return functools.cache(wrapper)


def with_threads(threads: int, module: str, function: str, out: Path) -> dict[str, Any]:
    """
    Return ``module.function()`` (a dict of arrays) computed in a new process on ``threads``.

    The process starts with ``NUMBA_NUM_THREADS`` = threads and uses all of them, whatever
    this one (an xdist worker at one thread) or the machine (one CPU) has: a test that
    compares thread counts then compares two counts for real. out: the file (.npz) the
    arrays come back in.
    """
    import subprocess
    import sys

    import numpy as np
    test_dir = Path(__file__).resolve().parent
    path = [str(test_dir), str(test_dir / module.split('.')[0])]
    code = (f'import sys; sys.path[:0] = {path!r}\n'
            f'import numba, numpy\nnumba.set_num_threads({threads})\n'
            f'assert numba.get_num_threads() == {threads}\n'
            f'from {module.split(".")[-1]} import {function}\n'
            f'numpy.savez({str(out)!r}, **{function}())\n')
    env = {**os.environ, 'NUMBA_NUM_THREADS': str(threads)}
    done = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    with np.load(out) as arrays:
        return {name: arrays[name] for name in arrays.files}
