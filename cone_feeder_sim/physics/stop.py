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
A request to stop a long computation, which the compiled kernels read without the GIL.

The integration kernels release the GIL and can run for seconds (a crowd integrated as one
system). Python's signal handlers run only between bytecodes of the main thread, so a
signal cannot stop a kernel by itself; a :class:`StopFlag` can: its one int64 is read by
every kernel between two steps, from any thread. Whoever stops a run (the command line's
signal watcher, the node at shutdown) calls :meth:`StopFlag.request`; the kernel returns at its
next step and :func:`~cone_feeder_sim.physics.simulation.advance` drops the interval (the
state stays the one before it: a stopped step is a result, ``StepResult.stopped``).

Kernels read the flag with :func:`stop_requested`, an atomic load: a plain ``stop[0]`` is
a data race in the compiler's model, which may then read it once before a loop whose other
writes it can tell apart from it; an atomic load is read anew every time.

How soon a stop is seen is one step of the kernel under way: a step of a piece alone is
microseconds, a step of an island integrated as one system (``coupling: exact``) grows with
the cube of its unknowns (60 ms for 70 pieces of one island over a 0.01-s interval; the
pairs within reach, and so the island, grow with the interval's length).
"""

from llvmlite import ir
from numba import types
from numba.extending import intrinsic
import numpy as np

__all__ = ['StopFlag', 'stop_requested']


@intrinsic
def stop_requested(typingctx, flag):  # type: ignore[no-untyped-def]
    """
    Return flag[0] != 0 for an int64 array flag (compiled code only).

    An atomic (monotonic) load: never moved out of a loop, so a write from another thread
    is seen at the next call.
    """
    del typingctx
    if not (isinstance(flag, types.Array) and flag.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        value = builder.load_atomic(data, 'monotonic', 8)
        return builder.icmp_signed('!=', value, ir.Constant(value.type, 0))

    return types.boolean(flag), codegen


class StopFlag:
    """
    A stop request: ``array`` (1,) int64, 0 to go on, 1 to stop.

    Callable: ``flag()`` tells whether it is set (the runner's stop predicate).
    """

    def __init__(self) -> None:
        """Start unset."""
        self.array = np.zeros(1, dtype=np.int64)

    def request(self) -> None:
        """Ask every computation that reads this flag to stop at its next step."""
        self.array[0] = 1

    def clear(self) -> None:
        """Withdraw the request (a new run may start)."""
        self.array[0] = 0

    def is_set(self) -> bool:
        """Tell whether a stop was asked for."""
        return bool(self.array[0])

    def __call__(self) -> bool:
        """Tell whether a stop was asked for (the runner's stop predicate)."""
        return self.is_set()
