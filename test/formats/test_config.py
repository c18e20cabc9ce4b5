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

"""Tests of cone_feeder_sim.formats.parameter_file: the default parameter file and its errors."""

from pathlib import Path

from cone_feeder_sim.errors import ParameterError
from cone_feeder_sim.formats.parameter_file import config_dir, load_model_params
from cone_feeder_sim.physics.params import ModelParams, solver_params_from_mapping
import pytest


def test_default_parameter_file_is_table_ii() -> None:
    assert (config_dir() / 'table2.yaml').is_file()
    assert load_model_params() == ModelParams()


def test_overrides_are_validated_with_the_file(tmp_path: Path) -> None:
    model = load_model_params(overrides={'d': 750.0})
    assert model.product.d == 750.0
    with pytest.raises(ParameterError, match="table2.yaml: parameter 'd' = -5"):
        load_model_params(overrides={'d': -5.0})


def test_errors_name_the_file(tmp_path: Path) -> None:
    bad = tmp_path / 'bad.yaml'
    bad.write_text('m: [1, 2\n')
    with pytest.raises(ParameterError, match='bad.yaml is not valid YAML'):
        load_model_params(bad)
    with pytest.raises(ParameterError, match='cannot read .*missing.yaml'):
        load_model_params(tmp_path / 'missing.yaml')
    bad.write_text('- 1\n- 2\n')
    with pytest.raises(ParameterError, match='must hold a mapping'):
        load_model_params(bad)
    bad.write_text('m: 0.1\nmass: 0.1\n')
    with pytest.raises(ParameterError, match="bad.yaml: unknown parameter\\(s\\) 'mass'"):
        load_model_params(bad)


def test_solver_settings() -> None:
    assert solver_params_from_mapping({'rtol': 1e-6}).rtol == 1e-6
    with pytest.raises(ParameterError, match="unknown solver setting\\(s\\) 'tol'"):
        solver_params_from_mapping({'tol': 1e-6})


def test_the_parameter_file_holds_the_contact_settings(tmp_path: Path) -> None:
    assert load_model_params().interactions == ModelParams().interactions
    assert not ModelParams().interactions.enabled
    path = tmp_path / 'sticky.yaml'
    path.write_text('interactions: {enabled: true, pull_off: 0.5}\n')
    model = load_model_params(path)
    assert model.interactions.enabled and model.interactions.pull_off == 0.5
    path.write_text('interactions: {pull_of: 0.5}\n')
    with pytest.raises(ParameterError, match="unknown interactions key.*'pull_of'"):
        load_model_params(path)
