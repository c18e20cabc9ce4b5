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
Profile: where the headless twin's integration steps go.

Runs twin_headless.py's stream (30 pieces, the cone reversing at ±3 rad/s, every piece
sticking) through the headless twin (``run_twin``, what ``cone-feeder-sim twin`` runs) with
the twin file's defaults and counts the
steps of every call of ``Twin.advance``: the frames' predictions (the members and the
window's smoother members, one frame each) and the forecasts' probes (:data:`PROBE` s) and
their rest. Prints, per kind, the accepted and rejected steps per piece and call, and for
the probes those made while the cone ramps (a forecast holds the last speed: the cone's
acceleration jumps to zero at its start) apart from the others::

    .venv/bin/python benchmarks/twin_steps.py [--seconds 10]
"""

import argparse
from pathlib import Path
import tempfile

from calibration import calibration_line
from cone_feeder_sim.physics.simulation import warm_up
from cone_feeder_sim.twin.estimator import Twin
from cone_feeder_sim.twin.forecast import PROBE
from cone_feeder_sim.twin.run import run_twin
import numpy as np
from twin_headless import reversing_profile, stream_twin, write_stream


def main() -> None:
    """Print the calibration and the steps per piece and call, by kind of call."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seconds', type=float, default=10.0)
    args = parser.parse_args()
    print(calibration_line(), flush=True)
    warm_up()
    calls: list[tuple[float, float, int, int, int]] = []  # t0, span, pieces, acc., rej.
    advance = Twin.advance

    def counted(twin: Twin, states: list, t1: float, profile: object = None) -> list:
        results = advance(twin, states, t1, profile)
        calls.append((states[0].t, t1 - states[0].t, sum(s.count for s in states),
                      sum(r.stats.accepted for r in results),
                      sum(r.stats.rejected for r in results)))
        return results

    Twin.advance = counted  # the estimator's and the forecasts' calls alike
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write_stream(folder, args.seconds)
        run_twin(stream_twin(folder), folder / 'out')
    profile = reversing_profile(args.seconds)
    table = np.array(calls).reshape(-1, 5)
    frame = np.isclose(table[:, 1], 1.0 / 30.0, rtol=0.0, atol=1e-5)  # stamps to the µs
    probe = np.isclose(table[:, 1], PROBE, rtol=0.0, atol=1e-5)
    ramp = np.array([profile.segments(t, t + 1e-6)[2][0] != 0.0 for t in table[:, 0]])
    for name, rows in (('frames', frame), ('probes, cone ramping', probe & ramp),
                       ('probes, cone steady', probe & ~ramp), ('forecasts after the probe',
                                                                ~frame & ~probe)):
        part = table[rows]
        pieces = part[:, 2].sum()
        if not pieces:
            print(f'{name}: no piece')
            continue
        print(f'{name}: {np.count_nonzero(part[:, 2])} calls with pieces, {pieces:.0f} '
              f'pieces; per piece and call {part[:, 3].sum() / pieces:.1f} accepted, '
              f'{part[:, 4].sum() / pieces:.1f} rejected steps')
    print(calibration_line(), flush=True)


if __name__ == '__main__':
    main()
