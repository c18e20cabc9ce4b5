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
Study: what sets the multirate coupling's intervals in a reversing crowd.

bench_states.py's reversing state with contact (``--pieces`` kept on the cone, default 53),
1.2 s to fill, then 1 s measured, once per variant of the pair law: the defaults, without
damping (restitution 1), without friction between pieces, without cohesion, pure elastic
Hertz (all three), and the defaults at a coupling tolerance of 1e-6 m. Prints the coupling
intervals and rejected intervals per simulated second, the integration steps per
particle-second and the wall time::

    .venv/bin/python benchmarks/coupling_intervals.py [--pieces 53]
"""

import argparse
import time

from bench_states import PATTERN
from calibration import calibration_line
from cone_feeder_sim.feeder.engine import DriveParams, EngineConfig, FeederEngine, FeedParams
from cone_feeder_sim.physics.params import InteractionParams, ModelParams

VARIANTS = (('the defaults', {}), ('restitution 1 (no damping)', {'restitution': 1.0}),
            ('friction 0', {'friction': 0.0}), ('pull-off 0 (no cohesion)', {'pull_off': 0.0}),
            ('elastic Hertz alone', {'restitution': 1.0, 'friction': 0.0, 'pull_off': 0.0}),
            ('coupling tolerance 1e-6 m', {'coupling_tolerance': 1e-6}))


def main() -> None:
    """Run each variant and print its intervals."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--pieces', type=int, default=53)
    args = parser.parse_args()
    print(calibration_line())
    print(f'{"pair law":>28} {"intervals/s":>12} {"rejected/s":>11} {"steps/pc-s":>11} '
          f'{"wall s":>7}')
    for label, keys in VARIANTS:
        model = ModelParams(interactions=InteractionParams(enabled=True, **keys))
        engine = FeederEngine(EngineConfig(model=model, drive=DriveParams(pattern=PATTERN),
                                           feed=FeedParams(rate=500.0,
                                                           max_pieces=args.pieces)))
        for _ in range(60):
            engine.tick()
        intervals = rejected = steps = 0
        piece_seconds = 0.0
        start = time.perf_counter()
        for _ in range(50):
            result = engine.tick()
            intervals += result.stats.coupling_intervals
            rejected += result.stats.coupling_rejected
            steps += result.stats.accepted
            piece_seconds += engine.dt * len(result.ids)
        print(f'{label:>28} {intervals:>12} {rejected:>11} {steps / piece_seconds:>11.0f} '
              f'{time.perf_counter() - start:>7.2f}', flush=True)
    print(calibration_line())


if __name__ == '__main__':
    main()
