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
Pieces touching on the turning cone: the product's couplings against the tests' DEM.

Four pieces in an oblique cluster (three on the cone, one on top, no symmetry) ride a cone
spun up clockwise; they push, rub and leave at four angles. And the paper's five samples
with contact on (doc/paper_replication.md, section 8): samples 1 and 5 meet on the way.
The DEM reference (reference_contacts.cone_dem_run: the paper's equations per piece, the
pair law as LIGGGHTS writes it, classic Runge-Kutta at a fixed 4-us step, histories as a
DEM code keeps them) gives the exits; both couplings of the product are held to the product's
promise against it (0.1 deg, 2 ms). Halving the reference's step moves its exits by under
0.001 deg and 0.01 ms here.
"""

import functools
import math
from pathlib import Path
import sys

from cone_feeder_sim.feeder.runner import run_scenario
from cone_feeder_sim.formats.scenario_file import scenario_from_mapping
from cone_feeder_sim.physics.params import ModelParams
from cone_feeder_sim.physics.simulation import resting_height
import numpy as np
import pytest
import reference_contacts as rc
import reference_model as rm

CONFIG = Path(__file__).resolve().parents[2] / 'config'
#: Clockwise to 100 rpm in 0.4 s, then held.
ROTATION = [[0.0, 0.0], [0.4, -10.47]]
DAMPING = (225.0, 135.0, 750.0, 30.0)
ANGLE_TOL, TIME_TOL = 0.1, 2.0e-3


def oblique_cluster() -> np.ndarray:
    """Return (4, 3) m: three pieces resting around (0.09, 0.03) m, one on top, off-centre."""
    model = ModelParams()
    centre = np.array([0.09, 0.03])
    base = []
    for bearing in (0.3, 2.4, 4.5):  # 27.5 mm from the centre: 47.6 mm apart, pressed 2.4 mm
        x, y = centre + 0.0275 * np.array([math.cos(bearing), math.sin(bearing)])
        base.append([x, y, resting_height(model, model.product, x, y)])
    pieces = np.array(base)
    top = pieces.mean(axis=0) + np.array([0.004, -0.003, 0.0])
    reach = max(math.hypot(*(top[:2] - p[:2])) for p in pieces)
    top[2] = pieces[:, 2].max() + math.sqrt(0.048 ** 2 - reach ** 2)  # 48 mm from the farthest
    return np.vstack([pieces, top])


@functools.lru_cache(maxsize=1)
def reference() -> rc.ConeRun:
    """Return the DEM reference's run of the cluster (about 2 s)."""
    params = [rm.table2_params(1, d=d) for d in DAMPING]
    y0 = np.array([rm.initial_state_on_feeder(p, 0.0) for p in oblique_cluster()])
    return rc.cone_dem_run(params, rc.Law(e=0.3, mu=0.5, k=rc.density_for(0.05)), y0,
                           ROTATION, 1.5, dt=4.0e-6)


def test_the_compiled_pair_law_is_the_reference_one() -> None:
    # the DEM's compiled transcription of pair_force, on both branches of the cap
    rng = np.random.default_rng(11)
    law = rc.Law(e=0.4, mu=0.6, k=rc.density_for(0.05))
    pieces = (rc.Piece(), rc.Piece(0.2, 0.03, 3.0e4, 0.4))
    out = np.empty(3)
    slid = 0
    for trial in range(60):
        a, b = pieces[trial % 2], pieces[(trial // 2) % 2]
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        d = n * (a.s0 + b.s0 - rng.uniform(0.0005, 0.012))
        u = rng.normal(size=3) * 0.3
        xi = rng.normal(size=3) * rng.choice([1e-5, 1e-3])
        xi -= (xi @ n) * n
        want, f_n, s_t = rc.pair_force(a, b, law, d, u, xi)
        got = rc.pair_force_compiled(np.array([a.m, a.s0, a.E, a.nu]),
                                     np.array([b.m, b.s0, b.E, b.nu]),
                                     np.array([law.e, law.mu, law.k]), d, u, xi, out)
        np.testing.assert_allclose(out, want, rtol=1e-12, atol=1e-15)
        assert got == pytest.approx((f_n, s_t), rel=1e-12)
        slid += s_t * np.linalg.norm(xi) >= law.mu * abs(f_n)
    assert 5 < slid < 55


@pytest.mark.parametrize('coupling', ['island', 'multirate', 'exact'])
def test_an_oblique_cluster_leaves_as_in_the_dem_reference(coupling: str) -> None:
    content = {'duration': 3.0, 'parameters': 'table2.yaml', 'rotation': ROTATION,
               'interactions': {'enabled': True, 'coupling': coupling},
               'particles': [{'position': [float(v) for v in p], 'd': d}
                             for p, d in zip(oblique_cluster(), DAMPING)]}
    scenario = scenario_from_mapping(content, base_dir=CONFIG)
    result = run_scenario(scenario)
    table = result.exit_table()
    assert sorted(table['ids'].tolist()) == [0, 1, 2, 3] and not result.failures
    ref = reference()
    assert np.all(np.isfinite(ref.t_exit))
    for i, t, angle in zip(table['ids'], table['t'], table['angle_deg']):
        assert abs(t - ref.t_exit[i]) <= TIME_TOL, (i, t, ref.t_exit[i])
        assert abs((angle - ref.angle_deg[i] + 180.0) % 360.0 - 180.0) <= ANGLE_TOL, (
            i, angle, ref.angle_deg[i])
    # they touched: the cluster leaves spread over more than 120 degrees
    assert np.ptp(ref.angle_deg) > 120.0


def test_the_paper_s_samples_with_contact_leave_as_in_the_dem_reference() -> None:
    # doc/paper_replication.md's exits with contact (test_paper_scenario's CONTACT_EXITS):
    # sample 1 knocks sample 5 off its slow path. Halving the reference's step moves sample
    # 1's exit by 0.016 deg (the pair slides while it presses): the reference is good to
    # about 0.03 deg here
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'feeder'))
    try:
        import test_paper_scenario as paper
    finally:
        sys.path.pop(0)
    content = paper.with_neighbours(None)
    paper.assert_held_to(paper.sample_exits(content), paper.dem_exits(content, 1.5))
