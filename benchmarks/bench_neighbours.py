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
Benchmark: the neighbour search of piece-piece contact, cost per piece against N.

N default pieces (contact reach as in the simulation) in one layer at the density of a
full cone (pieces 5 cm apart on average, with random jitter), on a square that grows with
N so that the density stays the same; best of 5 calls per N, after a warm-up. The cost per
piece stays flat when the search is O(N). The calibration workload is printed first::

    .venv/bin/python benchmarks/bench_neighbours.py --pieces 150 1000 10000 100000
"""

import argparse
import time

from calibration import calibration_line
from cone_feeder_sim.physics.neighbours import contact_pairs
from cone_feeder_sim.physics.params import product_row, ProductParams
from cone_feeder_sim.physics.simulation import contact_reach
import numpy as np


def main() -> None:
    """Print the calibration and one row per piece count."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--pieces', type=int, nargs='+', default=[150, 1000, 10000, 100000])
    args = parser.parse_args()
    print(calibration_line())
    reach = float(contact_reach(np.array([product_row(ProductParams())]))[0])
    contact_pairs(np.zeros((2, 3)), np.full(2, reach))  # compile / load
    print(f'# one layer, 5 cm spacing on average, reach {1e3 * reach:.1f} mm per piece')
    print(f'{"N":>7} {"pairs":>8} {"ms":>9} {"us/piece":>9}')
    rng = np.random.default_rng(0)
    for count in args.pieces:
        side = 0.05 * np.sqrt(count)
        x = np.column_stack([rng.uniform(0.0, side, (count, 2)), rng.uniform(0, 0.01, count)])
        reaches = np.full(count, reach)
        best = np.inf
        for _ in range(5):
            start = time.perf_counter()
            pairs = contact_pairs(x, reaches)
            best = min(best, time.perf_counter() - start)
        print(f'{count:>7} {len(pairs):>8} {1e3 * best:>9.3f} {1e6 * best / count:>9.3f}',
              flush=True)


if __name__ == '__main__':
    main()
