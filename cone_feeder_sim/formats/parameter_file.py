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
Reading configuration files: the parameter file and the solver settings.

All file I/O of configuration lives here; validation is done by the parameter classes in
cone_feeder_sim.physics.params, which this module feeds with plain mappings.
"""

from collections.abc import Mapping
from pathlib import Path
import sys
from typing import Any

import yaml

from ..errors import ParameterError
from ..physics.params import model_params_from_mapping, ModelParams
from ..weigher.machine import weigher_params_from_mapping, WeigherParams

PACKAGE = 'cone_feeder_sim'
DEFAULT_PARAMETER_FILE = 'table2.yaml'
DEFAULT_WEIGHER_FILE = 'weigher.yaml'


def config_dir() -> Path:
    """
    Return the directory holding the package's configuration files.

    Looked up in this order: the ament index (an installed ROS package), the Python
    installation's share/ directory (pip install), and the source tree.
    """
    candidates = []
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.append(Path(get_package_share_directory(PACKAGE)) / 'config')
    except Exception:  # noqa: B902 - not installed through ament, or no ament at all
        pass
    candidates.append(Path(sys.prefix) / 'share' / PACKAGE / 'config')
    candidates.append(Path(__file__).resolve().parents[2] / 'config')
    for candidate in candidates:
        if (candidate / DEFAULT_PARAMETER_FILE).is_file():
            return candidate
    raise ParameterError(
        'cannot find the configuration directory of cone_feeder_sim; looked in: '
        + ', '.join(str(c) for c in candidates))


#: PyYAML's safe loader, in C where PyYAML was built with libyaml (ten times faster; a fit
#: reads the parameter file at every simulation).
SAFE_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)


def read_yaml(path: str | Path) -> Any:
    """Return the parsed content of a YAML file; errors name the file."""
    path = Path(path)
    try:
        with path.open('r', encoding='utf-8') as stream:
            return yaml.load(stream, Loader=SAFE_LOADER)
    except OSError as exc:
        raise ParameterError(f'cannot read {path}: {exc.strerror or exc}') from exc
    except yaml.YAMLError as exc:
        raise ParameterError(f'{path} is not valid YAML: {exc}') from exc


def load_model_params(path: str | Path | None = None,
                      overrides: Mapping[str, Any] | None = None) -> ModelParams:
    """
    Load and validate a parameter file (default: config/table2.yaml) with overrides.

    Keys of `overrides` are the parameter file's keys; both are validated together.
    """
    path = Path(path) if path is not None else config_dir() / DEFAULT_PARAMETER_FILE
    content = read_yaml(path)
    if not isinstance(content, Mapping):
        raise ParameterError(f'{path} must hold a mapping of parameter: value')
    merged = dict(content)
    merged.update(overrides or {})
    try:
        return model_params_from_mapping(merged)
    except ParameterError as exc:
        raise ParameterError(f'{path}: {exc}') from exc


def load_weigher_params(path: str | Path | None = None,
                        overrides: Mapping[str, Any] | None = None) -> WeigherParams:
    """
    Load and validate a weigher file (default: config/weigher.yaml) with overrides.

    Keys of ``overrides`` are the file's keys (a scenario's ``weigher:`` section); both are
    validated together, and errors name the file and the key.
    """
    path = Path(path) if path is not None else config_dir() / DEFAULT_WEIGHER_FILE
    content = read_yaml(path)
    if not isinstance(content, Mapping):
        raise ParameterError(f'{path} must hold a mapping of parameter: value')
    try:
        base = weigher_params_from_mapping(content)
    except ParameterError as exc:
        raise ParameterError(f'{path}: {exc}') from exc
    try:
        return weigher_params_from_mapping(overrides or {}, base)
    except ParameterError as exc:
        raise ParameterError(f'weigher: {exc}') from exc
