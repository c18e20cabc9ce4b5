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


"""The fixed workload every benchmark prints first: this machine's speed varies by the hour."""

import time

#: Iterations of the calibration loop.
CALIBRATION_LOOPS = 3_000_000


def calibration_loop() -> int:
    """Run the fixed pure-Python workload."""
    total = 0
    for i in range(CALIBRATION_LOOPS):
        total += i
    return total


def calibration_line(seconds: float | None = None) -> str:
    """Return the line that reports the calibration (timed now unless ``seconds`` given)."""
    if seconds is None:
        start = time.perf_counter()
        calibration_loop()
        seconds = time.perf_counter() - start
    return (f'calibration: {CALIBRATION_LOOPS:,}-iteration pure-Python loop '
            f'{1e3 * seconds:.1f} ms')
