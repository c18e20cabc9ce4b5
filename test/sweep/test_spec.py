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


"""Tests of sweep files: expansion into jobs, dotted keys, errors that name the key."""

from pathlib import Path

from cone_feeder_sim.errors import SweepError
from cone_feeder_sim.formats.scenario_file import load_scenario
from cone_feeder_sim.sweep.job import write_job_files
from cone_feeder_sim.sweep.spec import load_sweep, set_dotted, sweep_from_mapping
import numpy as np
import pytest
import yaml

BASE = {
    'duration': 2.0,
    'rotation': [[0.0, 0.0], [0.4, -10.47]],
    'particles': [{'position': [0.11, -0.01, 0.03], 'd': 225.0},
                  {'position': [0.14, 0.06, 0.03]}],
}


def sweep(tmp_path: Path, **content: object):
    return sweep_from_mapping({'scenario': BASE, **content}, tmp_path, 'test')


def scenario_of(job, tmp_path: Path):
    directory = tmp_path / job.name
    directory.mkdir()
    return load_scenario(write_job_files(job, directory))


def test_grid_is_the_full_product_in_order(tmp_path: Path) -> None:
    result = sweep(tmp_path, grid={'model.d': [30.0, 750.0], 'rotation.1.1': [-5.0, 5.0, 8.0],
                                   'particles.0.d': [135.0]})
    assert result.keys == ('model.d', 'rotation.1.1', 'particles.0.d')
    assert [j.name for j in result.jobs] == [f'{i:05d}' for i in range(6)]
    assert [(j.values['model.d'], j.values['rotation.1.1']) for j in result.jobs] == [
        (30.0, -5.0), (30.0, 5.0), (30.0, 8.0), (750.0, -5.0), (750.0, 5.0), (750.0, 8.0)]
    scenario = scenario_of(result.jobs[4], tmp_path)
    assert scenario.model.product.d == 750.0
    assert scenario.particles[0].product.d == 135.0  # the piece's own override
    assert scenario.particles[1].product.d == 750.0
    assert scenario.rotation.omega(1.0) == 5.0
    assert scenario.duration == 2.0


def test_random_samples_are_seeded_and_within_their_ranges(tmp_path: Path) -> None:
    spec = {'samples': 40, 'seed': 7, 'keys': {
        'model.mu_C': {'uniform': [0.6, 0.95]}, 'model.d': {'loguniform': [30.0, 750.0]},
        'weigher.min_heads': {'integers': [1, 3]}, 'duration': {'choice': [1.0, 2.0]}}}
    first = sweep(tmp_path, random=spec, grid={'model.m': [0.1, 0.2]})
    again = sweep(tmp_path, random=spec, grid={'model.m': [0.1, 0.2]})
    other = sweep(tmp_path, random={**spec, 'seed': 8}, grid={'model.m': [0.1, 0.2]})
    assert len(first.jobs) == 80
    assert first.digest == again.digest and first.digest != other.digest
    values = [j.values for j in first.jobs]
    assert values[:40] == [{**v, 'model.m': 0.1} for v in values[40:]]  # product with grid
    mu = np.array([v['model.mu_C'] for v in values[:40]])
    d = np.array([v['model.d'] for v in values[:40]])
    assert np.all((0.6 <= mu) & (mu < 0.95)) and np.all((30.0 <= d) & (d < 750.0))
    assert {v['weigher.min_heads'] for v in values} == {1, 2, 3}
    assert {v['duration'] for v in values} == {1.0, 2.0}
    # the values reach the scenario exactly (YAML round trip of the floats)
    job = first.jobs[5]
    scenario = scenario_of(job, tmp_path)
    assert scenario.model.product.mu_C == job.values['model.mu_C']
    assert scenario.model.product.d == job.values['model.d']
    assert scenario.weigher is not None  # weigher.* adds the default machine
    assert scenario.weigher.min_heads == job.values['weigher.min_heads']


def test_seeds_set_the_weigher_seed_of_every_point(tmp_path: Path) -> None:
    result = sweep_from_mapping({'scenario': {**BASE, 'weigher': None},
                                 'grid': {'model.d': [30.0, 750.0]}, 'seeds': 3}, tmp_path)
    assert [(j.values['model.d'], j.values['weigher.seed']) for j in result.jobs] == [
        (30.0, 0), (30.0, 1), (30.0, 2), (750.0, 0), (750.0, 1), (750.0, 2)]
    assert scenario_of(result.jobs[5], tmp_path).weigher.seed == 2
    with pytest.raises(SweepError, match='seeds: the scenario has neither a feed'):
        sweep(tmp_path, seeds=[0, 1])


def test_seeds_set_the_feed_seed_and_the_weigher_seed_together(tmp_path: Path) -> None:
    base = {**BASE, 'particles': [], 'feed': {'rate': 5.0}, 'weigher': {}}
    result = sweep_from_mapping({'scenario': base, 'seeds': [4, 9]}, tmp_path)
    assert result.keys == ('feed.seed', 'weigher.seed')
    assert [j.values for j in result.jobs] == [{'feed.seed': 4, 'weigher.seed': 4},
                                               {'feed.seed': 9, 'weigher.seed': 9}]
    scenario = scenario_of(result.jobs[1], tmp_path)
    assert (scenario.feed_seed, scenario.weigher.seed, scenario.feed.rate) == (9, 9, 5.0)
    feed_only = sweep_from_mapping({'scenario': {**base, 'weigher': None, 'feed': {'rate': 1.0}},
                                    'seeds': 2}, tmp_path)
    assert feed_only.keys == ('feed.seed', 'weigher.seed')  # weigher: null is the default one
    no_weigher = {k: v for k, v in base.items() if k != 'weigher'}
    assert sweep_from_mapping({'scenario': no_weigher, 'seeds': 2}, tmp_path).keys == (
        'feed.seed',)


def test_interactions_and_weigher_keys(tmp_path: Path) -> None:
    result = sweep(tmp_path, grid={'interactions.enabled': [False, True],
                                   'interactions.pull_off': [0.02],
                                   'weigher.target': [0.3]})
    scenarios = [scenario_of(j, tmp_path) for j in result.jobs]
    assert [s.model.interactions.enabled for s in scenarios] == [False, True]
    assert {s.model.interactions.pull_off for s in scenarios} == {0.02}
    assert {s.weigher.target for s in scenarios} == {0.3}


def test_the_parameter_file_travels_with_the_job(tmp_path: Path) -> None:
    params = tmp_path / 'params' / 'mine.yaml'
    params.parent.mkdir()
    table2 = Path(__file__).resolve().parents[2] / 'config' / 'table2.yaml'
    params.write_text(table2.read_text().replace('mu_C: 0.85', 'mu_C: 0.8'))
    base = tmp_path / 'runs' / 'base.yaml'
    base.parent.mkdir()
    base.write_text(yaml.safe_dump({**BASE, 'parameters': '../params/mine.yaml'}))
    path = tmp_path / 'sweep.yaml'
    path.write_text('scenario: runs/base.yaml\ngrid: {model.d: [30.0]}\n')
    result = load_sweep(path)
    job = result.jobs[0]
    assert job.parameters == params.read_text()
    assert yaml.safe_load(job.scenario)['parameters'] == 'parameters.yaml'
    assert scenario_of(job, tmp_path).model.product.mu_C == 0.8
    # the same sweep written otherwise computes the same jobs; another parameter file not
    other = tmp_path / 'other.yaml'
    other.write_text('grid:\n  model.d:\n  - 30.0\nscenario: runs/base.yaml\n')
    assert load_sweep(other).digest == result.digest
    params.write_text(params.read_text().replace('mu_C: 0.8', 'mu_C: 0.75'))
    assert load_sweep(path).digest != result.digest


def test_set_dotted_copies_and_reaches_lists() -> None:
    changed = set_dotted(BASE, 'particles.1.position.2', 0.05)
    assert changed['particles'][1]['position'] == [0.14, 0.06, 0.05]
    assert BASE['particles'][1]['position'] == [0.14, 0.06, 0.03]  # the base is untouched
    assert set_dotted(BASE, 'solver.rtol', 1e-6)['solver'] == {'rtol': 1e-6}


@pytest.mark.parametrize('content, message', [
    ({'grid': {'modle.d': [1.0]}}, r"modle.d: 'modle' is not a scenario key "
                                   r"\(did you mean 'model'\?\)"),
    ({'grid': {'model.d': [30.0, -1.0]}}, "model.d = -1.0: .*'d' = -1 is out of range"),
    ({'grid': {'model.mu_c': [0.7]}}, "model.mu_c = 0.7: .*unknown parameter.*'mu_c'"),
    ({'grid': {'rotation.5.1': [1.0]}}, 'rotation.5.1: rotation has 2 items'),
    ({'grid': {'rotation.1.x': [1.0]}}, "rotation.1.x: rotation.1 is a list; 'x' is not"),
    ({'grid': {'duration.x': [1.0]}}, 'duration.x: duration is a value'),
    ({'grid': {'duration': []}}, 'grid.duration must be a non-empty list'),
    ({'grid': {'duration': 2.0}}, 'grid.duration must be a non-empty list'),
    ({'grid': {'duration': [0.0]}}, 'duration = 0.0: duration must be a positive'),
    ({'grid': {'interactions.pull_of': [0.1]}}, 'interactions.pull_of = 0.1: unknown '
                                                "interactions key.*'pull_of'"),
    ({'grid': {'model.d': [1.0]}, 'random': {'samples': 2, 'seed': 1, 'keys': {
        'model.d': {'uniform': [1.0, 2.0]}}}}, 'model.d is varied twice'),
    ({'grid': {'model': [{}], 'model.d': [1.0]}}, 'model.d is varied twice'),
    ({'random': {'samples': 2, 'seed': 1, 'keys': {'model.d': {'normal': [1.0, 2.0]}}}},
     "random.keys.model.d: unknown distribution 'normal'"),
    ({'random': {'samples': 2, 'seed': 1, 'keys': {'model.d': {'uniform': [2.0, 1.0]}}}},
     r'random.keys.model.d.uniform takes \[a, b\] with a < b'),
    ({'random': {'samples': 2, 'seed': 1, 'keys': {'model.d': {'uniform': [-5.0, 1.0]}}}},
     'model.d = -5.0: .*out of range'),
    ({'random': {'samples': 0, 'seed': 1, 'keys': {'model.d': {'uniform': [1.0, 2.0]}}}},
     'random.samples must be an integer >= 1'),
    ({'random': {'seed': 1, 'keys': {'model.d': {'uniform': [1.0, 2.0]}}}},
     "random is missing the key 'samples'"),
    ({'grid': {'model.d': [1.0]}, 'seeds': [1, 1]}, 'seeds must be distinct'),
    ({'grids': {'model.d': [1.0]}}, "unknown sweep key.*'grids'"),
    ({}, 'a sweep varies something'),
])
def test_malformed_sweeps_fail_naming_the_key(tmp_path: Path, content: dict,
                                              message: str) -> None:
    with pytest.raises(SweepError, match=message):
        sweep(tmp_path, **content)


def test_a_combination_that_fails_names_the_job(tmp_path: Path) -> None:
    # each value is valid alone; together the piece starts outside the cone
    with pytest.raises(SweepError, match=r'job 1 \(model.cone_diameter = 0.32, '
                                         r'particles.1.position.0 = 0.2\): .*outside'):
        sweep(tmp_path, grid={'model.cone_diameter': [0.45, 0.32],
                              'particles.1.position.0': [0.2]})


def test_a_missing_scenario_file_is_named(tmp_path: Path) -> None:
    path = tmp_path / 'sweep.yaml'
    path.write_text('scenario: nowhere.yaml\ngrid: {duration: [1.0]}\n')
    with pytest.raises(SweepError, match='scenario: cannot read .*nowhere.yaml'):
        load_sweep(path)
    path.write_text('scenario: {duration: 1.0}\ngrid: {duration: [1.0]}\n')
    with pytest.raises(SweepError, match="scenario: scenario is missing the key 'rotation'"):
        load_sweep(path)


def test_a_whole_table_is_a_value(tmp_path: Path) -> None:
    result = sweep(tmp_path, grid={'rotation': [[[0.0, 1.0]], [[0.0, -1.0], [1.0, 2.0]]]})
    omega = [scenario_of(job, tmp_path).rotation.omega(2.0) for job in result.jobs]
    assert omega == [1.0, 2.0]


def test_the_default_parameter_file_travels_too(tmp_path: Path) -> None:
    job = sweep(tmp_path, grid={'duration': [1.0]}).jobs[0]
    table2 = Path(__file__).resolve().parents[2] / 'config' / 'table2.yaml'
    assert job.parameters == table2.read_text()
    with pytest.raises(SweepError, match='parameters cannot be varied'):
        sweep(tmp_path, grid={'parameters': ['a.yaml']})


def test_the_example_sweep_file_expands() -> None:
    example = Path(__file__).resolve().parents[2] / 'config' / 'sweep_example.yaml'
    result = load_sweep(example)
    assert result.keys == ('particles.0.d', 'model.mu_C', 'weigher.seed')
    assert len(result.jobs) == 36
