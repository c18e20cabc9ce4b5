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
Sweep files: a base scenario and what varies in it, expanded into jobs before anything runs.

A sweep is a YAML mapping::

    scenario: base.yaml           # a scenario file (relative to the sweep file) or a mapping
    grid:                         # dotted scenario keys -> lists of values (full product)
      model.d: [30.0, 225.0, 750.0]
      rotation.1.1: [-10.47, 10.47]   # list items by index: row 1 of the table, its omega
    random:                       # optional: samples drawn with a seed (product with the grid)
      samples: 20
      seed: 7
      keys:
        model.mu_C: {uniform: [0.6, 0.95]}       # also loguniform: [a, b] (0 < a),
        particles.0.m: {choice: [0.1, 0.125]}    # integers: [a, b] (both included)
    seeds: 3                      # optional: 0, 1, 2 (or a list) as feed.seed and
                                  # weigher.seed of each point (the sections it has)

A dotted key names a scenario key (``duration``, ``model.d``, ``interactions.enabled``,
``weigher.target``, ``solver.rtol``), going into lists by index (``rotation.1.1``,
``particles.2.position``); not ``parameters``, the file every job carries. A key of a
section the base scenario leaves out adds it (so ``weigher.target`` adds a weigher). One
job is one parameter point and seed: grid point × random sample × seed, in that order
(the last varies fastest).

Malformed sweeps fail here, naming the key: every value of every key is tried on the base
scenario alone, then every job's whole scenario is validated. A job's scenario is YAML text
that ``cone-feeder-sim run`` reads as it is; its parameter file (the one the base scenario
names, else the package's default) travels with it as text (``parameters.yaml`` beside
it), so that a job runs the same on any worker.
"""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
import hashlib
import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..errors import ConeFeederError, ScenarioError, SweepError
from ..formats.parameter_file import (
    config_dir, DEFAULT_PARAMETER_FILE, DEFAULT_WEIGHER_FILE, read_yaml)
from ..formats.scenario_file import scenario_from_mapping, set_scenario_key

SWEEP_KEYS = ('scenario', 'grid', 'random', 'seeds')
RANDOM_KEYS = ('samples', 'seed', 'keys')
#: The distributions of random keys and what each takes.
DISTRIBUTIONS = {'uniform': '[a, b] with a < b', 'loguniform': '[a, b] with 0 < a < b',
                 'integers': '[a, b] with integer a <= b (both included)',
                 'choice': 'a non-empty list of values'}
#: The scenario keys that a sweep's seeds set, each where the scenario has its section:
#: the feed's draws (pieces, masses, products) and the weigher's load-cell noise.
SEED_KEYS = ('feed.seed', 'weigher.seed')
#: The file name of a job's parameter file, beside its scenario.
PARAMETERS_NAME = 'parameters.yaml'


@dataclass(frozen=True)
class Job:
    """
    One run of a sweep: a parameter point and seed, as a scenario ready to run.

    name: the job's name (its index, zero-padded: ``00003``); values: the value of every
    varied key at this job (``feed.seed`` and/or ``weigher.seed`` too when the sweep has
    seeds); scenario: the
    YAML text of the scenario; parameters: the text of its parameter file (``parameters:
    parameters.yaml``: the base scenario's, or the package's default); digest: SHA-256 of
    both texts and of the package's default weigher file (what the job computes).
    """

    index: int
    name: str
    values: Mapping[str, Any]
    scenario: str
    parameters: str
    digest: str


@dataclass(frozen=True)
class Sweep:
    """
    A validated sweep: its jobs, the varied keys (summary columns) and its digest.

    digest: SHA-256 of the jobs' digests in order; two sweep files with the same digest
    compute the same jobs.
    """

    source: str
    keys: tuple[str, ...]
    jobs: tuple[Job, ...]
    digest: str


def _plain(value: Any) -> Any:
    """Return value with numpy scalars as Python ones (YAML writes them exactly)."""
    if isinstance(value, np.generic):
        return value.item()
    return value


def set_dotted(root: Any, key: str, value: Any) -> Any:
    """Return a deep copy of the scenario mapping ``root`` with the dotted ``key`` set."""
    try:
        return set_scenario_key(root, key, value)
    except ScenarioError as exc:
        raise SweepError(str(exc)) from None


def _check_key(key: Any, where: str) -> str:
    if not isinstance(key, str) or not key:
        raise SweepError(f'{where}: keys must be dotted scenario keys, got {key!r}')
    if key.split('.')[0] == 'parameters':
        raise SweepError(f'{where}: {key} cannot be varied (a job carries one parameter '
                         'file); vary its values instead, as model.<key>')
    return key


def _check_overlap(keys: Sequence[str]) -> None:
    for a, b in itertools.permutations(keys, 2):
        if a == b or b.startswith(a + '.'):
            raise SweepError(f'{b} is varied twice (also as {a})')


def _grid(content: Any) -> dict[str, list[Any]]:
    if content is None:
        return {}
    if not isinstance(content, Mapping):
        raise SweepError(f'grid must be a mapping of dotted key: list of values, got {content!r}')
    grid = {}
    for key, values in content.items():
        key = _check_key(key, 'grid')
        if not isinstance(values, list) or not values:
            raise SweepError(f'grid.{key} must be a non-empty list of values, got {values!r}')
        grid[key] = values
    return grid


def _number(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(
            value):
        raise SweepError(f'{where} must hold finite numbers, got {value!r}')
    return value


def _integer(where: str, value: Any, low: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise SweepError(f'{where} must be an integer >= {low}, got {value!r}')
    return value


def _distribution(key: str, spec: Any) -> tuple[str, Any]:
    where = f'random.keys.{key}'
    if not isinstance(spec, Mapping) or len(spec) != 1:
        raise SweepError(f'{where} must be one of {{uniform: [a, b]}}, {{loguniform: [a, b]}}, '
                         f'{{integers: [a, b]}}, {{choice: [...]}}; got {spec!r}')
    (kind, arg), = spec.items()
    if kind not in DISTRIBUTIONS:
        raise SweepError(f'{where}: unknown distribution {kind!r}; known: '
                         f'{", ".join(DISTRIBUTIONS)}')
    where = f'{where}.{kind}'
    if kind == 'choice':
        if not isinstance(arg, list) or not arg:
            raise SweepError(f'{where} takes {DISTRIBUTIONS[kind]}, got {arg!r}')
        return kind, arg
    if not isinstance(arg, list) or len(arg) != 2:
        raise SweepError(f'{where} takes {DISTRIBUTIONS[kind]}, got {arg!r}')
    a, b = (_number(where, v) for v in arg)
    if kind == 'integers':
        if not all(isinstance(v, int) for v in (a, b)) or a > b:
            raise SweepError(f'{where} takes {DISTRIBUTIONS[kind]}, got {arg!r}')
    elif not a < b or (kind == 'loguniform' and a <= 0):
        raise SweepError(f'{where} takes {DISTRIBUTIONS[kind]}, got {arg!r}')
    return kind, (a, b)


def _random(content: Any) -> tuple[dict[str, tuple[str, Any]], list[dict[str, Any]]]:
    """Return the random keys' distributions and the samples (one mapping per sample)."""
    if content is None:
        return {}, [{}]
    if not isinstance(content, Mapping):
        raise SweepError(f'random must be a mapping with samples, seed, keys; got {content!r}')
    unknown = sorted(str(k) for k in set(content) - set(RANDOM_KEYS))
    if unknown:
        raise SweepError(f'random: unknown key(s) {", ".join(map(repr, unknown))}; known: '
                         f'{", ".join(RANDOM_KEYS)}')
    for name in RANDOM_KEYS:
        if name not in content:
            raise SweepError(f'random is missing the key {name!r}')
    samples = _integer('random.samples', content['samples'], 1)
    seed = _integer('random.seed', content['seed'])
    keys = content['keys']
    if not isinstance(keys, Mapping) or not keys:
        raise SweepError('random.keys must be a mapping of dotted key: distribution')
    dists = {_check_key(key, 'random.keys'): _distribution(key, spec)
             for key, spec in keys.items()}
    rng = np.random.default_rng(seed)
    drawn = []
    for _ in range(samples):
        point = {}
        for key, (kind, arg) in dists.items():  # as written: the draws' order is the file's
            if kind == 'uniform':
                point[key] = float(rng.uniform(*arg))
            elif kind == 'loguniform':
                point[key] = float(math.exp(rng.uniform(math.log(arg[0]), math.log(arg[1]))))
            elif kind == 'integers':
                point[key] = int(rng.integers(arg[0], arg[1], endpoint=True))
            else:
                point[key] = _plain(arg[int(rng.integers(len(arg)))])
        drawn.append(point)
    return dists, drawn


def _seeds(content: Any) -> list[int] | None:
    if content is None:
        return None
    if isinstance(content, int) and not isinstance(content, bool):
        return list(range(_integer('seeds', content, 1)))
    if not isinstance(content, list) or not content:
        raise SweepError(f'seeds must be a count or a non-empty list of seeds, got {content!r}')
    seeds = [_integer('seeds', s) for s in content]
    if len(set(seeds)) != len(seeds):
        raise SweepError(f'seeds must be distinct, got {content!r}')
    return seeds


def _text(mapping: Any) -> str:
    return yaml.safe_dump(mapping, sort_keys=False, default_flow_style=None, width=99)


class _Base:
    """The base scenario: its mapping and where its parameter file is."""

    def __init__(self, content: Any, sweep_dir: Path) -> None:
        where = 'scenario'
        base_dir = sweep_dir
        if isinstance(content, str):
            path = Path(content) if Path(content).is_absolute() else sweep_dir / content
            try:
                content = read_yaml(path)
            except ConeFeederError as exc:
                raise SweepError(f'scenario: {exc}') from exc
            where, base_dir = f'scenario ({path})', path.parent
        if not isinstance(content, Mapping):
            raise SweepError(f'{where} must be a scenario file name or a scenario mapping')
        self.mapping = dict(content)
        # the parameter file, the package's default one where the scenario names none, so
        # that every job carries the file it runs with (and its digest covers it)
        self.parameters = config_dir() / DEFAULT_PARAMETER_FILE
        if self.mapping.get('parameters') is not None:
            path = Path(str(self.mapping['parameters']))
            self.parameters = path if path.is_absolute() else base_dir / path
        self.mapping['parameters'] = str(self.parameters)
        self.validate(self.mapping, where)

    def validate(self, mapping: Any, where: str) -> None:
        try:
            scenario_from_mapping(mapping)
        except ConeFeederError as exc:
            raise SweepError(f'{where}: {exc}') from exc


def load_sweep(path: str | Path) -> Sweep:
    """Read, validate and expand a sweep file; raise SweepError naming the problem."""
    path = Path(path)
    try:
        content = read_yaml(path)
    except ConeFeederError as exc:
        raise SweepError(str(exc)) from exc
    try:
        return sweep_from_mapping(content, path.parent, str(path))
    except SweepError as exc:
        raise SweepError(f'{path}: {exc}') from exc


def _has_section(mapping: Mapping[str, Any], section: str, varied: list[str]) -> bool:
    """Tell whether a scenario has a section (feed: null is none; weigher: null the default)."""
    present = (mapping.get(section) is not None if section == 'feed' else section in mapping)
    return present or any(k.startswith(section + '.') for k in varied)


def sweep_from_mapping(content: Any, sweep_dir: Path, source: str = '') -> Sweep:
    """Validate a parsed sweep (relative paths from ``sweep_dir``) and expand its jobs."""
    if not isinstance(content, Mapping):
        raise SweepError('a sweep must be a mapping with the keys scenario and grid or random')
    unknown = sorted(str(k) for k in set(content) - set(SWEEP_KEYS))
    if unknown:
        raise SweepError(f'unknown sweep key(s) {", ".join(map(repr, unknown))}; known: '
                         f'{", ".join(SWEEP_KEYS)}')
    if 'scenario' not in content:
        raise SweepError('a sweep needs a scenario: a file name or a mapping')
    base = _Base(content['scenario'], sweep_dir)
    grid = _grid(content.get('grid'))
    dists, samples = _random(content.get('random'))
    seeds = _seeds(content.get('seeds'))
    keys = list(grid) + list(dists)
    seed_keys: list[str] = []
    if seeds is not None:
        seed_keys = [key for key in SEED_KEYS
                     if _has_section(base.mapping, key.split('.')[0], [*grid, *dists])]
        if not seed_keys:
            raise SweepError('seeds: the scenario has neither a feed: nor a weigher: section; '
                             f'seeds set {" and ".join(SEED_KEYS)}, the seeds of its only '
                             'random parts')
        keys.extend(seed_keys)
    if not keys:
        raise SweepError('a sweep varies something: give grid, random or seeds')
    _check_overlap(keys)
    # every value of every key alone on the base, so that an error names its key
    for key in keys:
        if key in seed_keys:
            tried = seeds[:1]
        elif key in grid:
            tried = grid[key]
        else:
            kind, arg = dists[key]
            tried = arg if kind == 'choice' else list(arg)
        for value in tried:
            base.validate(set_dotted(base.mapping, key, _plain(value)),
                          f'{key} = {value!r}')
    try:
        parameters = base.parameters.read_text(encoding='utf-8')
        # the default weigher is the installed file's: its text is part of every digest
        weigher = (config_dir() / DEFAULT_WEIGHER_FILE).read_text(encoding='utf-8')
    except OSError as exc:
        raise SweepError(f'cannot read a configuration file: {exc}') from exc
    points = [dict(zip(grid, combo)) for combo in itertools.product(*grid.values())]
    all_values = [{**point, **sample, **dict.fromkeys(seed_keys, seed)}
                  for point in points for sample in samples
                  for seed in (seeds if seeds is not None else [None])]
    width = max(5, len(str(len(all_values) - 1)))
    jobs = []
    for index, values in enumerate(all_values):
        mapping = base.mapping
        for key, value in values.items():
            mapping = set_dotted(mapping, key, _plain(value))
        point = ', '.join(f'{k} = {v!r}' for k, v in values.items())
        base.validate(mapping, f'job {index} ({point})')
        mapping['parameters'] = PARAMETERS_NAME
        text = _text(mapping)
        digest = hashlib.sha256('\0'.join((text, parameters, weigher)).encode()).hexdigest()
        jobs.append(Job(index=index, name=f'{index:0{width}d}', values=values, scenario=text,
                        parameters=parameters, digest=digest))
    digest = hashlib.sha256(''.join(j.digest for j in jobs).encode()).hexdigest()
    return Sweep(source=source, keys=tuple(keys), jobs=tuple(jobs), digest=digest)
