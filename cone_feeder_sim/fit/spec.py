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
Fit files: a scenario, tracks of its pieces and the keys to fit, validated before any run.

A fit file is a YAML mapping::

    scenario: base.yaml      # start positions and rotation history, as for `run`
    tracks: tracks.csv       # columns particle, t, x, y (m, world frame; z optional), or a
                             # recording RUN.mcap (its particle_states)
    tracks_every: 1          # a recording's every n-th particle_states message
    free:                    # dotted scenario keys -> [low, high]
      model.d: [10.0, 1000.0]
      model.mu_C: [0.3, 0.98]
    residual: trajectory     # positions at the tracked times, or exits: where and when the
                             # pieces left (tracks: a CSV particle, angle_deg[, t])
    exit_sigma: {angle_deg: 1.0, t: 0.02}   # exits: the uncertainty of an angle and a time
    segments: 0.5            # optional: multiple shooting over windows of 0.5 s first
    loss: linear             # or soft_l1, huber, cauchy, arctan (scipy's robust losses)
    starts: auto             # batches of 8 starts (the start values and seeded points in the
                             # bounds) until 3 reach the lowest cost, 32 at most; or a count
    noise: 0.001             # optional: the tracks' noise sigma (m); estimated if absent
    processes: 0             # processes for the starts and profiles (0: one per numba thread)
    profiles: true           # false: intervals from the Jacobian (±1.96 sigma), no profiles
    method: local            # or global: differential evolution over the bounds, then local
    global: {popsize: 8, maxiter: 15, seed: 0}   # the differential evolution (method: global)
    workers: 1               # threads that run a fit's simulations side by side (0: cores)

Paths are relative to the fit file. Each free key starts from its value in the scenario, or
for ``model.<key>`` from the parameter file's. The knots of the rotation history are free
keys too: ``rotation.K.t`` and ``rotation.K.omega`` (row K of the table, also
``rotation.K.0`` and ``rotation.K.1``). Every problem is named with its key.
"""

from collections.abc import Mapping
from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any

import numpy as np

from .exits import Exits, read_exits_csv
from .tracks import read_tracks, Tracks
from ..errors import ConeFeederError, ScenarioError
from ..feeder.scenario import Scenario
from ..formats.parameter_file import read_yaml
from ..formats.runlog import interaction_values, model_parameter_values
from ..formats.scenario_file import scenario_from_mapping, set_scenario_key
from ..physics.params import check_section
from ..physics.simulation import cone_surface_height

__all__ = ['FitSpec', 'fit_from_mapping', 'load_fit', 'LOSSES', 'RESIDUALS']

FIT_KEYS = ('scenario', 'tracks', 'tracks_every', 'free', 'residual', 'exit_sigma', 'segments',
            'loss', 'starts', 'method', 'global', 'workers', 'noise', 'processes', 'profiles')
#: ``starts: auto`` (the default): starts run in batches of AUTO_BATCH (the first holds the
#: file's start values) until AUTO_ENOUGH reached the lowest cost, AUTO_MAX at most
#: (multistart: doc/fit.md measured what one start misses).
AUTO_BATCH = 8
AUTO_ENOUGH = 3
AUTO_MAX = 32
#: The searches: least squares from the start values, or differential evolution first.
METHODS = ('local', 'global')
#: The keys of ``global:`` and their defaults.
GLOBAL_DEFAULTS = {'popsize': 8, 'maxiter': 15, 'seed': 0}
#: Names of a rotation knot's two numbers.
KNOT_PARTS = {'t': '0', 'omega': '1'}
#: What the residuals compare: positions at the tracked times, or exit angles and times.
RESIDUALS = ('trajectory', 'exits')
#: The keys of ``exit_sigma:`` and their defaults (deg, s).
EXIT_SIGMA_DEFAULTS = {'angle_deg': 1.0, 't': 0.02}
#: scipy.optimize.least_squares' losses.
LOSSES = ('linear', 'soft_l1', 'huber', 'cauchy', 'arctan')
#: How far outside the cone's rim (m) a tracked position may be (tracking noise).
RIM_SLACK = 0.01


@dataclass(frozen=True, eq=False)
class FitSpec:
    """
    A validated fit: the base scenario mapping and its directory, the tracks, the free keys.

    keys: the free dotted keys; bounds (low, high) and start value of each; residual,
    segments (s, or None: single shooting only), loss, starts (None: auto), method,
    global_options
    (popsize, maxiter, seed), workers, processes, profiles as in the file; noise (m, or
    None: estimated from the tracks). With ``residual: exits``, exits holds
    the observed exits, exit_sigma their uncertainty (deg, s), and tracks is empty.
    """

    mapping: Mapping[str, Any]
    base_dir: Path | None
    tracks: Tracks
    keys: tuple[str, ...]
    bounds: tuple[tuple[float, float], ...]
    start: tuple[float, ...]
    residual: str = 'trajectory'
    exits: Exits | None = None
    exit_sigma: tuple[float, float] = (1.0, 0.02)
    segments: float | None = None
    loss: str = 'linear'
    starts: int | None = None
    method: str = 'local'
    global_options: tuple[tuple[str, int], ...] = tuple(GLOBAL_DEFAULTS.items())
    workers: int = 1
    noise: float | None = None
    processes: int = 0
    profiles: bool = True

    def scenario_mapping(self, values: Any) -> dict[str, Any]:
        """Return the scenario mapping with the free keys set to ``values``."""
        mapping = dict(self.mapping)
        for key, value in zip(self.keys, values):
            mapping = set_scenario_key(mapping, scenario_key(key), float(value))
        return mapping

    def scenario(self, values: Any) -> Scenario:
        """Return the validated scenario with the free keys set to ``values``."""
        return scenario_from_mapping(self.scenario_mapping(values), self.base_dir)


def scenario_key(key: str) -> str:
    """Return the dotted scenario key of a free key (``rotation.2.omega`` -> ``rotation.2.1``)."""
    parts = key.split('.')
    if len(parts) == 3 and parts[0] == 'rotation' and parts[2] in KNOT_PARTS:
        parts[2] = KNOT_PARTS[parts[2]]
    return '.'.join(parts)


def _lookup(mapping: Mapping[str, Any], key: str) -> Any:
    node: Any = mapping
    for part in key.split('.'):
        if isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        elif isinstance(node, Mapping) and part in node:
            node = node[part]
        else:
            return None
    return node


def _section(section: str, content: Any, keys: tuple[str, ...]) -> Mapping[str, Any]:
    try:
        return check_section(section, content, keys)
    except ConeFeederError as exc:
        raise ScenarioError(str(exc)) from None


def fit_from_mapping(content: Any, base_dir: Path | None = None) -> FitSpec:
    """Validate a parsed fit file; raise ScenarioError naming the key."""
    _section('fit', content, FIT_KEYS)
    for key in ('scenario', 'tracks', 'free'):
        if key not in content:
            raise ScenarioError(f'the fit is missing the key {key!r}')
    raw = content['scenario']
    scenario_dir = base_dir
    if isinstance(raw, (str, Path)):
        path = Path(raw) if base_dir is None or Path(raw).is_absolute() else base_dir / raw
        raw = read_yaml(path)
        scenario_dir = path.parent
    if not isinstance(raw, Mapping):
        raise ScenarioError('scenario must be a scenario file or a mapping')
    mapping = dict(raw)
    if mapping.get('parameters') is not None and scenario_dir is not None:
        parameters = Path(str(mapping['parameters']))
        if not parameters.is_absolute():
            mapping['parameters'] = str((scenario_dir / parameters).resolve())
    scenario = scenario_from_mapping(mapping, scenario_dir)
    tracks_path = Path(str(content['tracks']))
    if base_dir is not None and not tracks_path.is_absolute():
        tracks_path = base_dir / tracks_path
    residual = content.get('residual', 'trajectory')
    if residual not in RESIDUALS:
        raise ScenarioError(f'residual must be one of {", ".join(RESIDUALS)}, got {residual!r}')
    exits = None
    if residual == 'exits':
        exits = read_exits_csv(tracks_path)
        _check_pieces(exits.particle, len(scenario.particles))
        known = exits.t[np.isfinite(exits.t)]
        if len(known) and (known.min() < 0.0 or known.max() > scenario.duration):
            raise ScenarioError(f'tracks: exit times must lie in [0, duration = '
                                f'{scenario.duration:g} s], got {known.min():g} .. '
                                f'{known.max():g} s')
        tracks = Tracks(np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros((0, 3)))
    else:
        every = content.get('tracks_every', 1)
        if isinstance(every, bool) or not isinstance(every, int) or every < 1:
            raise ScenarioError(f'tracks_every must be a positive integer, got {every!r}')
        tracks = read_tracks(tracks_path, every)
        _check_tracks(tracks, scenario)
    free = content['free']
    if not isinstance(free, Mapping) or not free:
        raise ScenarioError('free must be a non-empty mapping of dotted scenario keys to '
                            '[low, high]')
    defaults = {**model_parameter_values(scenario.model), **interaction_values(scenario.model)}
    keys, bounds, start = [], [], []
    for key, limits in free.items():
        key = str(key)
        if (not isinstance(limits, (list, tuple)) or len(limits) != 2
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                           and math.isfinite(v) for v in limits)):
            raise ScenarioError(f'free.{key} must be [low, high] (two finite numbers), got '
                                f'{limits!r}')
        low, high = float(limits[0]), float(limits[1])
        if not low < high:
            raise ScenarioError(f'free.{key}: the range [{low:g}, {high:g}] is empty')
        value = _lookup(mapping, scenario_key(key))
        if value is None:
            value = defaults.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(f'free.{key}: no numeric start value in the scenario or the '
                                'parameter file')
        for probe in (low, high):
            try:
                scenario_from_mapping(set_scenario_key(mapping, scenario_key(key), probe),
                                      scenario_dir)
            except ConeFeederError as exc:
                raise ScenarioError(f'free.{key} = {probe:g}: {exc}') from None
        keys.append(key)
        bounds.append((low, high))
        start.append(min(max(float(value), low), high))
    given = _section('exit_sigma', content.get('exit_sigma') or {}, tuple(EXIT_SIGMA_DEFAULTS))
    sigma = {**EXIT_SIGMA_DEFAULTS, **given}
    for key, value in sigma.items():
        if (isinstance(value, bool) or not isinstance(value, (int, float))
                or not 0.0 < value < math.inf):
            raise ScenarioError(f'exit_sigma.{key} must be a positive number, got {value!r}')
    segments = content.get('segments')
    if segments is not None and residual == 'exits':
        raise ScenarioError('segments (multiple shooting) needs residual: trajectory')
    if segments is not None:
        if (isinstance(segments, bool) or not isinstance(segments, (int, float))
                or not 0.0 < segments < float(tracks.t.max())):
            raise ScenarioError(f'segments must be a window length in s, above 0 and below '
                                f'the last tracked time {float(tracks.t.max()):g} s, got '
                                f'{segments!r}')
        segments = float(segments)
    loss = content.get('loss', 'linear')
    if loss not in LOSSES:
        raise ScenarioError(f'loss must be one of {", ".join(LOSSES)}, got {loss!r}')
    starts = content.get('starts', 'auto')
    if starts == 'auto':
        starts = None
    elif isinstance(starts, bool) or not isinstance(starts, int) or not 1 <= starts <= 100:
        raise ScenarioError(f'starts must be auto or an integer in [1, 100], got {starts!r}')
    method = content.get('method', 'local')
    if method not in METHODS:
        raise ScenarioError(f'method must be one of {", ".join(METHODS)}, got {method!r}')
    merged = {**GLOBAL_DEFAULTS,
              **_section('global', content.get('global') or {}, tuple(GLOBAL_DEFAULTS))}
    for key, value in merged.items():
        low = 0 if key == 'seed' else 1
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ScenarioError(f'global.{key} must be an integer >= {low}, got {value!r}')
    workers = content.get('workers', 1)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
        raise ScenarioError(f'workers must be 0 (one per core) or a positive integer, got '
                            f'{workers!r}')
    noise = content.get('noise')
    if noise is not None and residual == 'exits':
        raise ScenarioError("noise is the tracks' noise (residual: trajectory); exits have "
                            'exit_sigma')
    if noise is not None and (isinstance(noise, bool) or not isinstance(noise, (int, float))
                              or not 0.0 < noise < math.inf):
        raise ScenarioError(f'noise must be a positive number (m), got {noise!r}')
    profiles = content.get('profiles', True)
    if not isinstance(profiles, bool):
        raise ScenarioError(f'profiles must be true or false, got {profiles!r}')
    processes = content.get('processes', 0)
    if isinstance(processes, bool) or not isinstance(processes, int) or processes < 0:
        raise ScenarioError(f'processes must be 0 (one per core) or a positive integer, got '
                            f'{processes!r}')
    return FitSpec(mapping=mapping, base_dir=scenario_dir, tracks=tracks, keys=tuple(keys),
                   bounds=tuple(bounds), start=tuple(start), residual=residual, exits=exits,
                   exit_sigma=(float(sigma['angle_deg']), float(sigma['t'])),
                   segments=segments, loss=loss,
                   starts=starts, method=method, global_options=tuple(merged.items()),
                   workers=workers, noise=None if noise is None else float(noise),
                   processes=processes, profiles=profiles)


def _check_pieces(particle: np.ndarray, pieces: int) -> None:
    strangers = sorted(set(particle.tolist()) - set(range(pieces)))
    if strangers:
        raise ScenarioError(f'tracks: particle(s) {", ".join(map(str, strangers))} are not in '
                            f'the scenario (its particles are 0..{pieces - 1})')


def _check_tracks(tracks: Tracks, scenario: Scenario) -> None:
    _check_pieces(tracks.particle, len(scenario.particles))
    rho = (tracks.xyz[:, 0] ** 2 + tracks.xyz[:, 1] ** 2) ** 0.5
    outside = rho > scenario.model.r + RIM_SLACK
    if outside.any():
        i = int(outside.argmax())
        raise ScenarioError(f'tracks: particle {tracks.particle[i]} at t = {tracks.t[i]:g} s is '
                            f'{rho[i]:.3f} m from the axis, outside the cone (radius '
                            f'{scenario.model.r:g} m)')
    if tracks.has_z:
        surface = [cone_surface_height(scenario.model, x, y) for x, y, _ in tracks.xyz]
        if (tracks.xyz[:, 2] < min(surface) - 0.05).any():
            raise ScenarioError('tracks: a z is more than 5 cm below the cone surface')
    if tracks.t.min() < 0.0 or tracks.t.max() > scenario.duration:
        raise ScenarioError(f'tracks: times must lie in [0, duration = {scenario.duration:g} '
                            f's], got {tracks.t.min():g} .. {tracks.t.max():g} s')


def load_fit(path: str | Path, tracks: str | Path | None = None) -> FitSpec:
    """
    Read and validate a fit file (paths in it relative to it).

    tracks: a tracks file or recording (relative to the working directory) that replaces the
    file's ``tracks``.
    """
    path = Path(path)
    try:
        content = read_yaml(path)
        if tracks is not None and isinstance(content, Mapping):
            content = {**content, 'tracks': str(Path(tracks).resolve())}
        return fit_from_mapping(content, path.parent)
    except ConeFeederError as exc:
        raise ScenarioError(f'{path}: {exc}') from exc
