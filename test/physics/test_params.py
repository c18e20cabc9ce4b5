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

"""Tests of cone_feeder_sim.physics.params: Table II defaults, validation, channel layout."""

import math

from cone_feeder_sim.errors import ParameterError
from cone_feeder_sim.physics.params import (
    ChannelLayout, model_params_from_mapping, ModelParams, P_C_S, P_D, P_M, P_R_C, P_R_T,
    product_row, PRODUCT_WIDTH, ProductParams, SolverParams)
import numpy as np
import pytest


def test_defaults_are_table_ii() -> None:
    p = ProductParams()
    assert (p.m, p.d, p.mu_C, p.mu_S) == (0.125, 225.0, 0.85, 0.99)
    assert (p.v_C, p.v_S, p.T_F, p.qdot_F) == (5e-5, 0.1, 3e-4, 1e-4)
    assert (p.s0, p.s_c, p.r_a, p.r_d, p.r_f) == (0.025, 0.0125, 0.99, 120.0, 120.0)
    m = ModelParams()
    assert (m.g, m.cone_diameter, m.cone_tilt, m.epsilon) == (9.81, 0.45, 7.5, 1e-7)
    assert m.channels.count == 14


def test_derived_geometry_and_activation_constants_by_hand() -> None:
    m = ModelParams()
    assert m.r == pytest.approx(0.225)
    assert m.h == pytest.approx(0.225 * 0.13165249758739583)  # tan(7.5 deg)
    p = ProductParams()
    # eq. 32: r_t = 2 artanh(0.99) / (0.025 - 0.0125); artanh(0.99) = 2.6466524123622457
    assert p.r_t == pytest.approx(2 * 2.6466524123622457 / 0.0125)
    assert p.r_c == pytest.approx(0.01875)  # eq. 33


def test_product_row_layout() -> None:
    p = ProductParams(m=0.2, d=30.0)
    row = product_row(p)
    assert row.shape == (PRODUCT_WIDTH,)
    assert row[P_M] == 0.2 and row[P_D] == 30.0
    assert row[P_R_T] == pytest.approx(p.r_t) and row[P_R_C] == pytest.approx(p.r_c)
    # c_S = mu_S - mu_C tanh(v_S / v_C); tanh(2000) = 1 to double precision
    assert row[P_C_S] == pytest.approx(0.99 - 0.85)


@pytest.mark.parametrize('key, value, fragment', [
    ('m', -1.0, "'m' = -1 is out of range: allowed (0, 100] kg"),
    ('m', 0.0, "'m' = 0 is out of range"),
    ('d', float('nan'), "'d' must be finite"),
    ('mu_C', True, "'mu_C' must be a number"),
    ('s_c_ratio', 1.0, "'s_c_ratio' = 1 is out of range: allowed (0, 1)"),
    ('r_a', 'high', "'r_a' must be a number"),
    ('v_C', float('inf'), "'v_C' must be finite"),
])
def test_product_validation_names_key_and_range(key: str, value: object,
                                                fragment: str) -> None:
    with pytest.raises(ParameterError) as info:
        ProductParams(**{key: value})
    assert fragment in str(info.value)


def test_model_validation() -> None:
    with pytest.raises(ParameterError, match="'cone_tilt' = 75 is out of range"):
        ModelParams(cone_tilt=75.0)
    with pytest.raises(ParameterError, match="'normal_force' must be one of newton, literal"):
        ModelParams(normal_force='N/r_f')
    with pytest.raises(ParameterError, match="'channel_count' must be an integer"):
        ChannelLayout(count=14.5)  # type: ignore[arg-type]


def test_mapping_with_unknown_key_is_refused() -> None:
    with pytest.raises(ParameterError, match="unknown parameter\\(s\\) 'mu_K'"):
        model_params_from_mapping({'mu_K': 0.5})


def test_mapping_overrides_product_model_and_channels() -> None:
    m = model_params_from_mapping({'d': 30.0, 'cone_tilt': 10.0, 'channel_count': 12,
                                   'friction_direction': 'tangential'})
    assert m.product.d == 30.0 and m.product.m == 0.125
    assert m.cone_tilt == 10.0 and m.channels.count == 12
    assert m.friction_direction == 'tangential'


@pytest.mark.parametrize('angle, channel', [
    (69.5, 2), (63.5, 2), (93.6, 1), (115.2, 14), (147.4, 13), (287.4, 8),
    (108.0, 14), (108.0 - 360.0 / 14, 1), (82.0, 2), (-72.6, 8), (360.0 + 93.6, 1)])
def test_default_channel_layout_reproduces_table_i(angle: float, channel: int) -> None:
    assert int(ChannelLayout().channel_of(angle)) == channel


def test_counter_clockwise_numbering() -> None:
    layout = ChannelLayout(count=4, boundary=0.0, numbering='counter_clockwise')
    assert layout.channel_of([0.0, 89.9, 90.0, 180.0, 359.9]).tolist() == [1, 1, 2, 3, 4]
    assert layout.sector_edges(2) == (90.0, 180.0)


def test_sector_edges_match_channel_of() -> None:
    layout = ChannelLayout()
    for channel in range(1, layout.count + 1):
        start, end = layout.sector_edges(channel)
        mid = 0.5 * (start + end)
        assert int(layout.channel_of(mid)) == channel
        assert end - start == pytest.approx(360.0 / 14)


def test_solver_params_validation_and_atol_row() -> None:
    s = SolverParams(atol_position=1e-7, atol_velocity=1e-6, atol_force=1e-5)
    np.testing.assert_array_equal(s.atol_row(), [1e-7] * 3 + [1e-6] * 3 + [1e-5] * 3)
    with pytest.raises(ParameterError, match="'rtol'"):
        SolverParams(rtol=0.0)
    assert math.isclose(SolverParams().rtol, 1e-5)
