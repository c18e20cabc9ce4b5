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
Scenario files for the headless runner: validated before anything runs.

A scenario is a YAML mapping::

    duration: 4.0                 # s
    parameters: table2.yaml       # optional parameter file (relative to the scenario)
    model: {d: 225.0}             # optional overrides of the parameter file, same keys
    solver: {rtol: 1.0e-5}        # optional integrator settings
    interactions: {enabled: true} # optional contact between pieces (default: the
                                  # parameter file's, off in table2.yaml: the paper's model)
    weigher: {target: 0.5}        # optional multihead weigher below the cone ({} = the
                                  # default machine of config/weigher.yaml); packs CSV
    output_interval: 0.01         # s, optional: interval of progress and trajectory output
    rotation: [[0.0, 0.0], [0.4, -10.47]]   # [t s, omega rad/s]; linear between, held after
    feed: {rate: 5.0, seed: 3}    # optional product feed, the node's feed.* keys (pieces/s,
                                  # rho_min, rho_max, drop_height, mass_rel_std, d_values,
                                  # max_pieces, seed); drawn per output interval
    particles:                    # may be empty or left out when a feed is given
      - position: [0.11, -0.01, 0.03]      # m, world frame
        velocity: [0.0, 0.0, 0.0]          # optional; default: moving with the cone surface
        on_surface: false                  # optional; true: z set to the resting height
        d: 225.0                           # optional per-particle product overrides

Every problem is reported with its location (e.g. `particles[2].position`).
"""

from collections.abc import Mapping
import copy
from dataclasses import replace
import difflib
import math
from pathlib import Path
from typing import Any

import numpy as np

from .parameter_file import load_model_params, load_weigher_params, read_yaml
from ..errors import ConeFeederError, ScenarioError
from ..feeder.feed import check_feed_fits, feed_from_mapping
from ..feeder.scenario import check_output_count, ParticleSpec, Scenario
from ..physics.params import (
    interaction_params_from_mapping, PRODUCT_LIMITS, product_row, solver_params_from_mapping)
from ..physics.rotation import RotationProfile
from ..physics.simulation import check_positions, overlap_problems, resting_height
from ..weigher.machine import check_machine

SCENARIO_KEYS = ('duration', 'parameters', 'model', 'solver', 'interactions', 'weigher',
                 'output_interval', 'rotation', 'particles', 'feed')
PARTICLE_KEYS = ('position', 'velocity', 'on_surface')


def _vector(where: str, value: Any) -> tuple[float, float, float]:
    if (not isinstance(value, (list, tuple)) or len(value) != 3
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value)):
        raise ScenarioError(f'{where} must be a list of 3 numbers, got {value!r}')
    vec = tuple(float(v) for v in value)
    if not all(math.isfinite(v) for v in vec):
        raise ScenarioError(f'{where} must be finite, got {list(vec)}')
    return vec  # type: ignore[return-value]


def _positive(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            math.isfinite(value) and value > 0):
        raise ScenarioError(f'{where} must be a positive number of seconds, got {value!r}')
    return float(value)


def scenario_from_mapping(content: Any, base_dir: Path | None = None) -> Scenario:
    """Validate a parsed scenario and return it; raise ScenarioError naming the problem."""
    if content is None:
        raise ScenarioError('the scenario is empty: it needs the keys duration, rotation, '
                            'particles')
    if not isinstance(content, Mapping):
        raise ScenarioError('a scenario must be a mapping with keys duration, rotation, '
                            f'particles, got {type(content).__name__} {content!r:.40}')
    unknown = sorted(str(k) for k in set(content) - set(SCENARIO_KEYS))
    if unknown:
        raise ScenarioError(f'unknown scenario key(s) {", ".join(map(repr, unknown))}; '
                            f'known: {", ".join(SCENARIO_KEYS)}')
    has_feed = content.get('feed') is not None
    for key in ('duration', 'rotation') + (() if has_feed else ('particles',)):
        if key not in content:
            raise ScenarioError(f'scenario is missing the key {key!r}')
    duration = _positive('duration', content['duration'])
    interval = _positive('output_interval', content.get('output_interval', 0.01))
    check_output_count(duration, interval)
    overrides = content.get('model') or {}
    if not isinstance(overrides, Mapping):
        raise ScenarioError(f'model must be a mapping of parameter overrides, got {overrides!r}')
    param_file = content.get('parameters')
    if param_file is not None:
        param_file = Path(str(param_file))
        if not param_file.is_absolute() and base_dir is not None:
            param_file = base_dir / param_file
    try:
        model = load_model_params(param_file, overrides)
        if content.get('interactions') is not None:
            model = replace(model, interactions=interaction_params_from_mapping(
                content['interactions'], model.interactions))
        solver = solver_params_from_mapping(content.get('solver'))
        rotation = RotationProfile.from_table(content['rotation'])
    except ConeFeederError as exc:
        raise ScenarioError(str(exc)) from exc
    feed, feed_seed = None, 0
    if has_feed:
        try:
            feed, feed_seed = feed_from_mapping(content['feed'])
            check_feed_fits(model, feed)
        except ConeFeederError as exc:
            raise ScenarioError(str(exc)) from exc
    raw_particles = content.get('particles')
    if raw_particles is None and has_feed:
        raw_particles = []
    if not isinstance(raw_particles, list) or not (raw_particles or has_feed):
        raise ScenarioError('particles must be a non-empty list of pieces (it may be empty '
                            'when the scenario has a feed)')
    particles = []
    for i, raw in enumerate(raw_particles):
        where = f'particles[{i}]'
        if not isinstance(raw, Mapping):
            raise ScenarioError(f'{where} must be a mapping with at least a position')
        extra = sorted(str(k) for k in set(raw) - set(PARTICLE_KEYS) - set(PRODUCT_LIMITS))
        if extra:
            raise ScenarioError(f'{where}: unknown key(s) {", ".join(map(repr, extra))}')
        if 'position' not in raw:
            raise ScenarioError(f'{where} has no position')
        position = _vector(f'{where}.position', raw['position'])
        velocity = (_vector(f'{where}.velocity', raw['velocity'])
                    if raw.get('velocity') is not None else None)
        try:
            product = model.product.with_overrides(
                {k: v for k, v in raw.items() if k in PRODUCT_LIMITS})
        except ConeFeederError as exc:
            raise ScenarioError(f'{where}: {exc}') from exc
        on_surface = raw.get('on_surface', False)
        if not isinstance(on_surface, bool):
            raise ScenarioError(f'{where}.on_surface must be true or false')
        if on_surface:
            position = (position[0], position[1],
                        resting_height(model, product, position[0], position[1]))
        try:
            check_positions(model, np.array([position]))
        except ScenarioError as exc:
            raise ScenarioError(f'{where}: {exc}') from exc
        particles.append(ParticleSpec(position=position, velocity=velocity, product=product))
    if model.interactions.enabled and particles:
        positions = np.array([spec.position for spec in particles])
        rows = np.array([product_row(spec.product) for spec in particles])
        _, problems = overlap_problems(positions, rows, np.zeros((0, 3)),
                                       np.zeros((0, rows.shape[1])), label='particles')
        if problems:
            raise ScenarioError(problems[0])
    weigher = None
    if 'weigher' in content:  # weigher: {} is the default machine of config/weigher.yaml
        try:
            weigher = load_weigher_params(overrides=content['weigher'] or {})
            check_machine(weigher, model.channels.count)  # one head per channel
        except ConeFeederError as exc:
            raise ScenarioError(str(exc)) from exc
    return Scenario(duration=duration, model=model, solver=solver, rotation=rotation,
                    particles=tuple(particles), output_interval=interval, weigher=weigher,
                    feed=feed, feed_seed=feed_seed)


def set_scenario_key(root: Any, key: str, value: Any) -> Any:
    """
    Return a deep copy of the scenario mapping ``root`` with the dotted ``key`` set.

    ``model.d``, ``rotation.1.1`` (lists by index), ``particles.2.position``; a key of a
    section the mapping leaves out adds it. Raises ScenarioError naming the key.
    """
    parts = key.split('.')
    if not all(parts):
        raise ScenarioError(f'{key!r} is not a dotted key (empty part)')
    if parts[0] not in SCENARIO_KEYS:
        close = difflib.get_close_matches(parts[0], SCENARIO_KEYS, n=1)
        hint = f' (did you mean {close[0]!r}?)' if close else ''
        raise ScenarioError(f'{key}: {parts[0]!r} is not a scenario key{hint}; known: '
                            f'{", ".join(SCENARIO_KEYS)}')
    root = copy.deepcopy(root)
    node = root
    for depth, part in enumerate(parts):
        last = depth == len(parts) - 1
        parent = '.'.join(parts[:depth]) or 'the scenario'
        if isinstance(node, list):
            if not part.isdigit():
                raise ScenarioError(f'{key}: {parent} is a list; {part!r} is not an index')
            if int(part) >= len(node):
                raise ScenarioError(f'{key}: {parent} has {len(node)} items (indices from 0)')
            if last:
                node[int(part)] = value
            else:
                node = node[int(part)]
        elif isinstance(node, dict):
            if not last:
                known = [k for k in node if isinstance(k, str) and k.lower() == part.lower()]
                if part not in node and known:
                    raise ScenarioError(f'{key}: {parent} has no key {part!r} (did you '
                                        f'mean {known[0]!r}?)')
                if node.get(part) is None:
                    node[part] = {}
                node = node[part]
            else:
                node[part] = value
        else:
            raise ScenarioError(f'{key}: {parent} is a value ({node!r}), not a mapping or list')
    return root


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file."""
    path = Path(path)
    try:
        content = read_yaml(path)
    except ConeFeederError as exc:
        raise ScenarioError(str(exc)) from exc
    try:
        return scenario_from_mapping(content, base_dir=path.parent)
    except ScenarioError as exc:
        raise ScenarioError(f'{path}: {exc}') from exc
