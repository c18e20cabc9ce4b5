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
Benchmark: forecasts with the riders taken out against every piece integrated, A B B A.

On the stream of twin_headless.py (30 pieces, ±3 rad/s), the headless twin with M members;
at each forecast time both forecasts are made on the same twin, in alternating order, and
their times summed; prints the sums and in how many forecasts the channel probabilities are
equal::

    .venv/bin/python benchmarks/twin_forecast_riders.py [--seconds 20] [--members 8]
"""

import argparse
from pathlib import Path
import tempfile
import time

from calibration import calibration_line
from cone_feeder_sim.physics.simulation import warm_up
from cone_feeder_sim.twin import run
from cone_feeder_sim.twin.forecast import Forecast, forecast
import numpy as np
from twin_headless import stream_twin, write_stream


def main() -> None:
    """Print the calibration, the two forecasts' summed times and their agreement."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seconds', type=float, default=20.0)
    parser.add_argument('--members', type=int, default=8)
    args = parser.parse_args()
    print(calibration_line(), flush=True)
    warm_up()
    spent = {True: 0.0, False: 0.0}
    made, equal = [0], [0]

    def both(twin, horizons, riders=True) -> Forecast:
        made[0] += 1
        out = {}
        for kind in ((True, False) if made[0] % 2 else (False, True)):
            start = time.perf_counter()
            out[kind] = forecast(twin, horizons, riders=kind)
            spent[kind] += time.perf_counter() - start
        equal[0] += np.array_equal(out[True].channel_probability,
                                   out[False].channel_probability)
        return out[riders]

    run.forecast = both  # the headless run's forecasts, made both ways
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write_stream(folder, args.seconds)
        run.run_twin(stream_twin(folder, members=args.members), folder / 'out')
    print(f'{made[0]} forecasts, M = {args.members}: riders taken out {spent[True]:.1f} s, '
          f'every piece integrated {spent[False]:.1f} s; channel probabilities equal in '
          f'{equal[0]}', flush=True)
    print(calibration_line(), flush=True)


if __name__ == '__main__':
    main()
