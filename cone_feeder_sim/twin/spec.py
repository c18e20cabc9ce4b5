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
The twin file of ``cone-feeder-sim twin``: a scenario, the streams, the estimator's settings.

A twin file is a YAML mapping::

    scenario: base.yaml        # the machine, the product prior (model.d, model.mu_C), the
                               # solver; its particles and rotation are not used
    detections: detections.csv # columns t, x, y[, z, track_id, mass] (s, m, m, m, -, kg),
                               # or an MCAP file (a PointCloud2 topic: detections_topic,
                               # default /detections, else /particle_states)
    cone: cone.csv             # columns t, omega (s, rad/s), or an MCAP file (a JointState
                               # topic: cone_topic, default /cone_state; joint cone)
    exits: exits.csv           # optional, measured exits: columns t, channel[, mass] (s,
                               # 1-based, kg: a load cell's step; empty: not weighed), or
                               # an MCAP file (a PointCloud2 topic: exits_topic, default
                               # /exit_events; fields channel, optionally exit_time, mass)
    # defaults:
    members: 8                 # the ensemble's size
    sigma: 0.002               # the detections' noise (m)
    horizons: [0.5, 1.0, 2.0]  # forecast horizons (s)
    every: 0.1                 # forecast every (s)
    seed: 0
    # and the estimator's other settings (estimator.TwinSettings, its defaults): d_spread,
    # mu_C_spread, drift, inflation, death_after, loosen, window, confirm, tentative_after,
    # localize_below, particles, smoother_pieces

The settings are twin_node's parameters of the same names, so that a twin_node recording
run again headless with the node's settings gives the node's estimates (seeded; checked in
test/ros/test_twin_node.py).

Paths are relative to the twin file. Errors name the key, the file and the row. A
detection that is not finite (nan, inf) is read, and its frame refused when the twin gets
to it: the rest of the stream goes on.
"""

import csv
from dataclasses import dataclass, field
import math
from pathlib import Path
from typing import Any

import numpy as np

from .estimator import TUNING, TwinSettings
from .streams import mcap_cone, mcap_detections, mcap_exits
from ..errors import ConeFeederError, TwinError
from ..feeder.scenario import Scenario
from ..formats.parameter_file import read_yaml
from ..formats.scenario_file import load_scenario

__all__ = ['load_twin', 'TwinSpec', 'TWIN_KEYS']

TWIN_KEYS = ('scenario', 'detections', 'cone', 'exits', 'members', 'sigma', 'horizons',
             'every', 'seed', 'detections_topic', 'cone_topic', 'exits_topic', *TUNING)


@dataclass(frozen=True)
class TwinSpec:
    """
    A validated twin file.

    scenario: the machine and the product prior; detections: (k, 5) rows t (s), x, y (m),
    mass (kg), track_id (NaN: not given), sorted by t (z is not read); cone: (j, 2) rows
    t (s), omega (rad/s), sorted; members, sigma (m), horizons (s), every (s), seed as in the file;
    tuning: the other estimator settings the file sets (:data:`TUNING`); exits: (e, 3) rows
    t (s), channel, mass (kg) (NaN: not given; checked when the twin takes them), sorted,
    the measured exits (none without the key); refused: (t (s), what, why) of each MCAP
    message refused whole, as twin_node refuses it (:mod:`.streams`), sorted by t; what:
    'frame', 'cone' or 'exits'.
    """

    scenario: Scenario
    detections: np.ndarray
    cone: np.ndarray
    members: int = TwinSettings.members
    sigma: float = 0.002
    horizons: tuple[float, ...] = (0.5, 1.0, 2.0)
    every: float = 0.1
    seed: int = 0
    tuning: dict[str, float] = field(default_factory=dict)
    exits: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    refused: tuple[tuple[float, str, str], ...] = ()

    def settings(self) -> TwinSettings:
        """Return the estimator's settings: the file's, the scenario's product as the prior."""
        product = self.scenario.model.product
        return TwinSettings(members=self.members, sigma=self.sigma, d=product.d,
                            mu_C=product.mu_C, seed=self.seed, **self.tuning)


def _rows(path: Path, columns: tuple[str, ...], optional: tuple[str, ...]) -> np.ndarray:
    """Read a CSV's columns (missing optional ones and empty cells: NaN), sorted by t."""
    try:
        with path.open(newline='', encoding='utf-8') as stream:
            reader = csv.DictReader(stream)
            names = reader.fieldnames or []
            missing = [c for c in columns if c not in names]
            if missing:
                raise TwinError(f'{path}: missing column(s) {", ".join(missing)} '
                                f'(has {", ".join(names) or "none"})')
            rows = []
            for number, row in enumerate(reader, start=2):
                values = []
                for c in columns + optional:
                    cell = (row.get(c) or '').strip()
                    try:
                        values.append(float(cell) if cell else math.nan)
                    except ValueError:
                        raise TwinError(f'{path}, row {number}: {c} is not a number: '
                                        f'{cell!r}') from None
                if not math.isfinite(values[0]):
                    raise TwinError(f'{path}, row {number}: t must be a finite number, got '
                                    f'{row.get("t")!r}')
                rows.append(values)
    except OSError as exc:
        raise TwinError(f'{path}: cannot be read ({exc.strerror})') from None
    table = np.array(rows, dtype=float).reshape(len(rows), len(columns) + len(optional))
    return table[np.argsort(table[:, 0], kind='stable')]


def _number(content: dict, key: str, default: Any, low: float, integer: bool = False) -> Any:
    value = content.get(key, default)
    kind = int if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, kind) or not value >= low or (
            not math.isfinite(value)):
        raise TwinError(f'{key} must be {"an integer" if integer else "a number"} >= {low}, '
                        f'got {value!r}')
    return value


def load_twin(path: str | Path) -> TwinSpec:
    """Read and validate a twin file and its streams."""
    path = Path(path)
    try:
        content = read_yaml(path)
    except ConeFeederError as exc:
        raise TwinError(str(exc)) from exc
    if not isinstance(content, dict):
        raise TwinError(f'{path}: a twin file is a mapping, got {type(content).__name__}')
    unknown = sorted(set(content) - set(TWIN_KEYS))
    if unknown:
        raise TwinError(f'unknown twin key(s) {", ".join(map(repr, unknown))}; known: '
                        f'{", ".join(TWIN_KEYS)}')
    for key in ('scenario', 'detections', 'cone'):
        if not isinstance(content.get(key), str):
            raise TwinError(f'{key} must name a file, got {content.get(key)!r}')
    base = path.parent
    scenario = load_scenario(base / content['scenario'])
    if 'exits' in content and not isinstance(content['exits'], str):
        raise TwinError(f'exits must name a file, got {content["exits"]!r}')
    for key in ('detections_topic', 'cone_topic', 'exits_topic'):
        if content.get(key) is not None and not isinstance(content[key], str):
            raise TwinError(f'{key} must name a topic, got {content[key]!r}')
    found, speeds = base / content['detections'], base / content['cone']
    refused: dict[str, list] = {}
    if found.suffix == '.mcap':
        detections, refused['frame'] = mcap_detections(found, content.get('detections_topic'))
    else:
        detections = _rows(found, ('t', 'x', 'y'), ('mass', 'track_id'))
    if speeds.suffix == '.mcap':
        cone, refused['cone'] = mcap_cone(speeds, content.get('cone_topic'))
    else:
        cone = _rows(speeds, ('t', 'omega'), ())
    exits = np.zeros((0, 3))
    if 'exits' in content:
        measured = base / content['exits']
        if measured.suffix == '.mcap':
            exits, refused['exits'] = mcap_exits(measured, scenario.model.channels.count,
                                                 content.get('exits_topic'))
        else:
            exits = _rows(measured, ('t', 'channel'), ('mass',))
    horizons = content.get('horizons', [0.5, 1.0, 2.0])
    if (not isinstance(horizons, list) or not horizons or any(
            isinstance(h, bool) or not isinstance(h, (int, float)) or not 0 < h <= 60
            for h in horizons)):
        raise TwinError(f'horizons must be a list of numbers in (0, 60] s, got {horizons!r}')
    return TwinSpec(
        scenario=scenario, detections=detections, cone=cone, exits=exits,
        refused=tuple(sorted(((t, what, line) for what, rows in refused.items()
                             for t, line in rows), key=lambda row: row[0])),
        members=_number(content, 'members', TwinSettings.members, 2, integer=True),
        sigma=float(_number(content, 'sigma', 0.002, 1e-6)),
        horizons=tuple(sorted(float(h) for h in horizons)),
        every=float(_number(content, 'every', 0.1, 1e-3)),
        seed=_number(content, 'seed', 0, 0, integer=True),
        tuning={key: _number(content, key, None, low, integer=isinstance(low, int))
                for key, low in TUNING.items() if key in content})
