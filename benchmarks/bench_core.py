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
Benchmark of the physics core: particle-seconds simulated per CPU-second, and accuracy.

Usage: python benchmarks/bench_core.py [--sizes 1 100 1000 10000] [--accuracy 8]
                                       [--scale 1 10 100] [--only atol_force]

Each size runs in its own process (so its peak memory is its own) on a reversing scenario:
pieces at random positions (seeded) resting on the cone, the cone reversing between
clockwise and counter-clockwise rotation, advanced in 20 ms intervals like the node at
50 Hz. CPU time excludes the one-off numba compilation (a warm-up run comes first).
Accuracy: for a sample of the same pieces, exit angles and times (or final positions of
pieces that stay) are compared with scipy's Radau at rtol 1e-10 on the paper's world-frame
equations (test/reference_model.py), with the same default solver settings.
``--scale S ...`` repeats both at tolerances S times the defaults (rtol and every atol),
side by side in one run: how much accuracy a looser tolerance gives up for its speed;
``--only atol_force`` (or another) scales that one alone.
"""

import argparse
import json
import os
from pathlib import Path
import resource
import subprocess
import sys
import time

from calibration import calibration_line
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
TABLE = [[0.0, 0.0], [0.4, -10.47], [1.5, -10.47], [1.9, 10.47], [3.0, 10.47], [3.4, -10.47]]
DURATION = 4.0
INTERVAL = 0.02


def starts(count: int, seed: int = 1) -> np.ndarray:
    """Return (count, 3) start positions resting on the cone, rho in [0.03, 0.19] m."""
    from cone_feeder_sim.physics.params import ModelParams
    from cone_feeder_sim.physics.simulation import resting_height
    model = ModelParams()
    rng = np.random.default_rng(seed)
    rho = np.sqrt(rng.uniform(0.03 ** 2, 0.19 ** 2, count))
    theta = rng.uniform(0.0, 2.0 * np.pi, count)
    x, y = rho * np.cos(theta), rho * np.sin(theta)
    z = np.array([resting_height(model, model.product, a, b) for a, b in zip(x, y)])
    return np.column_stack([x, y, z])


#: The tolerances ``--scale`` multiplies (``--only`` picks one of them).
TOLERANCES = ('rtol', 'atol_position', 'atol_velocity', 'atol_force')
#: Set by ``--only``: the one tolerance scaled (None: all of them).
ONLY: str | None = None


def params(scale: float) -> object:
    """Return the default SimParams with the tolerances (or ONLY) multiplied by ``scale``."""
    from cone_feeder_sim.physics.params import SolverParams
    from cone_feeder_sim.physics.simulation import SimParams
    d = SolverParams()
    return SimParams(solver=SolverParams(**{
        key: getattr(d, key) * (scale if ONLY in (None, key) else 1.0) for key in TOLERANCES}))


def run(count: int, scale: float = 1.0) -> dict[str, float]:
    """Simulate count pieces; return timing, particle-seconds and exits."""
    from cone_feeder_sim.physics.rotation import RotationProfile
    from cone_feeder_sim.physics.simulation import Simulator
    profile = RotationProfile.from_table(TABLE)
    sim = Simulator(params(scale), profile)
    sim.add(starts(count))
    exits: dict[int, tuple[float, float]] = {}
    accepted = rejected = 0
    k = 0
    cpu0 = time.process_time()
    while sim.t < DURATION - 1e-12 and sim.state.count:
        k += 1
        step = sim.advance_to(min(DURATION, k * INTERVAL))
        accepted += step.stats.accepted
        rejected += step.stats.rejected
        for i, pid in enumerate(step.exits.ids):
            exits[int(pid)] = (float(step.exits.t[i]), float(step.exits.angle_deg[i]))
    cpu = time.process_time() - cpu0
    on_cone = sum(exits[i][0] if i in exits else DURATION for i in range(count))
    return {'count': count, 'cpu_s': cpu, 'particle_s': on_cone, 'accepted': accepted,
            'rejected': rejected, 'exited': len(exits),
            'peak_rss_mib': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def accuracy(sample: int, scale: float = 1.0) -> dict[str, float]:
    """
    Compare pieces of the benchmark set with the Radau reference.

    The reference (rtol 1e-10) needs microsecond steps while a piece sticks to the turning
    cone, so a piece that stays for seconds costs it many minutes: the comparison uses the
    first `sample` pieces that leave the cone, each run to its exit (plus 0.2 s).
    """
    sys.path.insert(0, str(ROOT / 'test'))
    import reference_model as ref
    from cone_feeder_sim.physics.rotation import RotationProfile
    from cone_feeder_sim.physics.simulation import Simulator
    pos = starts(4 * sample)
    sim = Simulator(params(scale), RotationProfile.from_table(TABLE))
    sim.add(pos)
    mine: dict[int, tuple[float, float]] = {}
    k = 0
    while sim.t < DURATION - 1e-12 and sim.state.count:
        k += 1
        step = sim.advance_to(min(DURATION, k * INTERVAL))
        for i, pid in enumerate(step.exits.ids):
            mine[int(pid)] = (float(step.exits.t[i]), float(step.exits.angle_deg[i]))
    worst = {'angle_deg': 0.0, 'time_ms': 0.0, 'compared': 0, 'mismatch': 0}
    for i in sorted(mine)[:sample]:
        t_end = min(DURATION, mine[i][0] + 0.2)
        r = ref.reference_trajectory(ref.table2_params(1), ref.initial_state_on_feeder(
            pos[i], 0.0), TABLE, t_end)
        worst['compared'] += 1
        if not r.exited:
            worst['mismatch'] += 1
            continue
        dang = (mine[i][1] - r.angle_deg + 180.0) % 360.0 - 180.0
        worst['angle_deg'] = max(worst['angle_deg'], abs(dang))
        worst['time_ms'] = max(worst['time_ms'], 1e3 * abs(mine[i][0] - r.t_exit))
    return worst


def main() -> int:
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--sizes', type=int, nargs='+', default=[1, 100, 1000, 10000])
    parser.add_argument('--accuracy', type=int, default=6,
                        help='pieces compared with the Radau reference (0: skip)')
    parser.add_argument('--scale', type=float, nargs='+', default=[1.0],
                        help='tolerances (rtol and atols) times the defaults, one row each')
    parser.add_argument('--only', choices=TOLERANCES,
                        help='scale this tolerance alone (which one buys the steps)')
    parser.add_argument('--single', type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    global ONLY
    ONLY = args.only
    if args.single is not None:
        run(2)  # warm-up: load or compile the numba kernels
        print(json.dumps(run(args.single, args.scale[0])))
        return 0
    print(calibration_line())
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get('PYTHONPATH', ''))
    print(f'reversing scenario: {DURATION} s, omega table {TABLE}, {INTERVAL * 1e3:.0f} ms '
          f'intervals, default solver settings, one core; scaled: {args.only or "all tolerances"}')
    print(f'{"scale":>6} {"N":>6} {"CPU s":>8} {"particle-s":>11} {"p-s per CPU-s":>14} '
          f'{"steps/p-s":>10} {"rejected":>9} {"exited":>7} {"peak RSS MiB":>13}')
    for scale in args.scale:
        for count in args.sizes:
            only = ['--only', args.only] if args.only else []
            out = subprocess.run([sys.executable, __file__, '--single', str(count), '--scale',
                                  str(scale), *only], env=env, capture_output=True, text=True,
                                 check=True).stdout
            r = json.loads(out.strip().splitlines()[-1])
            rate = r['particle_s'] / r['cpu_s']
            print(f'{scale:>6g} {count:>6} {r["cpu_s"]:>8.2f} {r["particle_s"]:>11.1f} '
                  f'{rate:>14.0f} {r["accepted"] / r["particle_s"]:>10.0f} '
                  f'{r["rejected"]:>9} {r["exited"]:>7} {r["peak_rss_mib"]:>13.0f}',
                  flush=True)
    for scale in args.scale if args.accuracy else ():
        worst = accuracy(args.accuracy, scale)
        print(f'tolerances x{scale:g}: accuracy vs Radau rtol 1e-10 on {worst["compared"]} '
              f'pieces of this set that leave: max |exit angle error| '
              f'{worst["angle_deg"]:.2e} deg, max |exit time error| {worst["time_ms"]:.2e} '
              f'ms, pieces the reference keeps on the cone {worst["mismatch"]}', flush=True)
    print(calibration_line())
    return 0


if __name__ == '__main__':
    sys.exit(main())
