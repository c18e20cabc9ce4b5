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

"""Tests of cone_feeder_sim.physics.rotation: piecewise-linear omega and its exact angle."""

import math

from cone_feeder_sim.errors import ParameterError
from cone_feeder_sim.physics.rotation import rotate_z, RotationProfile
import numpy as np
import pytest
from scipy.integrate import quad

TABLE = [[0.0, 0.0], [0.4, -10.47], [2.0, 10.47]]


def test_omega_is_linear_between_points_and_held_outside() -> None:
    prof = RotationProfile.from_table(TABLE)
    assert prof.omega(0.2) == pytest.approx(-5.235)
    assert prof.omega(1.2) == pytest.approx(0.0)
    assert prof.omega(5.0) == 10.47
    assert prof.omega(-1.0) == 0.0


def test_angle_is_the_exact_integral() -> None:
    prof = RotationProfile.from_table([[0.5, 2.0], [1.0, -3.0], [3.0, 1.0]])
    for t in (0.0, 0.3, 0.75, 1.0, 2.2, 4.0):
        expected, _ = quad(prof.omega, 0.0, t, points=[0.5, 1.0, 3.0], epsabs=1e-13)
        assert prof.angle(t) == pytest.approx(expected, abs=1e-12)
    # hand value: 0.5 s at 2 rad/s, then the ramp from 2 to -3 over 0.5 s averages -0.5
    assert prof.angle(1.0) == pytest.approx(1.0 - 0.25)
    assert prof.integral(0.3, 2.2) == pytest.approx(prof.angle(2.2) - prof.angle(0.3))


def test_segments_split_at_breakpoints() -> None:
    prof = RotationProfile.from_table(TABLE)
    seg_t, seg_w, seg_dw = prof.segments(0.2, 1.0)
    np.testing.assert_allclose(seg_t, [0.2, 0.4, 1.0])
    np.testing.assert_allclose(seg_w, [-5.235, -10.47])
    np.testing.assert_allclose(seg_dw, [-10.47 / 0.4, 20.94 / 1.6])
    with pytest.raises(ParameterError, match='must be after its start'):
        prof.segments(1.0, 1.0)


@pytest.mark.parametrize('table, fragment', [
    ([], 'rotation must be a number'),
    ([[0.0, 1.0], [0.0, 2.0]], 'strictly increasing'),
    ([[0.0, float('nan')]], 'non-finite'),
    ([[0.0, 1.0, 2.0]], 'rotation[0] must be a pair'),
    ('fast', 'rotation must be a number'),
])
def test_bad_tables_are_refused(table: object, fragment: str) -> None:
    with pytest.raises(ParameterError) as info:
        RotationProfile.from_table(table)
    assert fragment in str(info.value)


def test_constant_and_rotate_z() -> None:
    prof = RotationProfile.from_table(-2.5)
    assert prof.omega(7.0) == -2.5 and prof.angle(2.0) == pytest.approx(-5.0)
    v = rotate_z(np.array([[1.0, 0.0, 0.3]]), math.pi / 2)
    np.testing.assert_allclose(v, [[0.0, 1.0, 0.3]], atol=1e-15)
