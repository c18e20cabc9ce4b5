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

"""Tests of formats.scenario_file: valid scenarios load, malformed ones are refused."""

from dataclasses import replace
import math
from pathlib import Path

from cone_feeder_sim.errors import ScenarioError
from cone_feeder_sim.feeder.runner import run_scenario
from cone_feeder_sim.feeder.scenario import MAX_OUTPUTS, output_count
from cone_feeder_sim.formats.scenario_file import load_scenario, scenario_from_mapping
from cone_feeder_sim.physics.model import activation
from cone_feeder_sim.physics.params import ModelParams, ProductParams
from cone_feeder_sim.physics.simulation import resting_height
import pytest

VALID = {
    'duration': 4.0,
    'model': {'d': 225.0},
    'rotation': [[0.0, 0.0], [0.4, -10.47], [2.0, 10.47]],
    'particles': [
        {'position': [0.11, -0.01, 0.03], 'velocity': [0.0, 0.0, 0.0], 'd': 135.0},
        {'position': [0.05, 0.05, 0.0], 'on_surface': True, 'm': 0.2},
    ],
}


def test_valid_scenario() -> None:
    sc = scenario_from_mapping(VALID)
    assert sc.duration == 4.0 and sc.model.product.d == 225.0
    assert sc.particles[0].product.d == 135.0 and sc.particles[0].velocity == (0.0, 0.0, 0.0)
    assert sc.particles[1].product.m == 0.2 and sc.particles[1].product.d == 225.0
    assert sc.particles[1].velocity is None
    assert sc.rotation.omega(1.2) == pytest.approx(0.0)


def test_on_surface_places_the_piece_at_its_resting_gap() -> None:
    model = ModelParams()
    product = ProductParams(m=0.2)
    z = resting_height(model, product, 0.05, 0.05)
    gap = z - model.h * (1.0 - math.hypot(0.05, 0.05) / model.r)
    # at rest R_a r_f / 2 = m g cos^2(tilt)
    expected = 0.2 * 9.81 * math.cos(math.radians(7.5)) ** 2 / 60.0
    assert activation(gap, product.r_t, product.r_c) == pytest.approx(expected, rel=1e-12)
    assert scenario_from_mapping(VALID).particles[1].position[2] == pytest.approx(z)


@pytest.mark.parametrize('change, fragment', [
    ({'duration': -1.0}, 'duration must be a positive number'),
    ({'duration': float('nan')}, 'duration must be a positive number'),
    ({'speed': 3}, "unknown scenario key(s) 'speed'"),
    ({'model': {'d': -3.0}}, "parameter 'd' = -3 is out of range"),
    ({'model': {'mu': 0.5}}, "unknown parameter(s) 'mu'"),
    ({'rotation': [[1.0, 0.0], [0.5, 1.0]]}, 'strictly increasing'),
    ({'rotation': 'fast'}, 'rotation must be a number'),
    ({'particles': []}, 'particles must be a non-empty list'),
    ({'particles': [{'position': [0.3, 0.0, 0.0]}]}, 'particles[0]: position[0]'),
    ({'particles': [{'position': [0.1, 0.0]}]}, 'particles[0].position must be a list of 3'),
    ({'particles': [{'position': [0.1, 0.0, 0.05], 'velocity': [0, 0, float('inf')]}]},
     'particles[0].velocity must be finite'),
    ({'particles': [{'position': [0.1, 0.0, 0.05], 'mass': 1.0}]},
     "particles[0]: unknown key(s) 'mass'"),
    ({'particles': [{'position': [0.1, 0.0, 0.05], 'm': 0.0}]},
     "particles[0]: parameter 'm' = 0 is out of range"),
    ({'particles': [{'velocity': [0.0, 0.0, 0.0]}]}, 'particles[0] has no position'),
    ({'solver': {'rtol': 2.0}}, "parameter 'rtol' = 2 is out of range"),
    ({'feed': {'rate': 2.0, 'speed': 1}}, "unknown feed key(s) 'speed'"),
    ({'feed': {'rate': -2.0}}, 'feed.rate'),
    ({'feed': {'rate': 2.0, 'rho_max': 0.3}}, 'feed.rho_max = 0.3 m must be inside the cone'),
    ({'feed': {'rate': 2.0, 'seed': -1}}, 'feed.seed'),
    ({'feed': {'d_values': 30.0}}, 'feed.d_values must be a list'),
    ({'feed': [2.0]}, 'feed must be a mapping'),
])
def test_malformed_scenarios_name_the_problem(change: dict, fragment: str) -> None:
    content = {**VALID, **change}
    with pytest.raises(ScenarioError) as info:
        scenario_from_mapping(content)
    assert fragment in str(info.value)


def test_a_run_asks_for_a_bounded_number_of_outputs() -> None:
    # 10^12 outputs would never end: refused with the key and the count; the interval
    # itself is not bounded (a millisecond of a hard collision at 54-ns outputs passes)
    with pytest.raises(ScenarioError) as info:
        scenario_from_mapping({**VALID, 'output_interval': 1e-12})
    message = str(info.value)
    assert message.startswith('output_interval: 1e-12 s') and '\n' not in message
    assert '4,000,000,000,000 outputs' in message and f'{MAX_OUTPUTS:,}' in message
    short = scenario_from_mapping({**VALID, 'duration': 1e-3, 'output_interval': 54e-9})
    assert output_count(short.duration, short.output_interval) == 18519
    at_bound = scenario_from_mapping({**VALID, 'output_interval': 4.0 / MAX_OUTPUTS})
    assert output_count(at_bound.duration, at_bound.output_interval) == MAX_OUTPUTS
    with pytest.raises(ScenarioError, match=f'{MAX_OUTPUTS + 1:,} outputs'):
        scenario_from_mapping({**VALID, 'output_interval': 4.0 / (MAX_OUTPUTS + 0.5)})
    # a scenario built in code is held to the same bound by the runner, before it runs
    with pytest.raises(ScenarioError, match='output_interval: 1e-12 s'):
        run_scenario(replace(at_bound, output_interval=1e-12))


def test_pieces_that_touch_do_not_start_inside_each_other() -> None:
    pieces = [{'position': [0.1, 0.0, 0.03]}, {'position': [0.1, 0.03, 0.03]}]
    content = {**VALID, 'particles': pieces, 'interactions': {'enabled': True}}
    with pytest.raises(ScenarioError, match=r'particles\[1\] .* is pressed 20.0 mm into '
                                            r'particles\[0\] \(at most 10.0 mm'):
        scenario_from_mapping(content)
    assert len(scenario_from_mapping({**content, 'interactions': {'enabled': False}})
               .particles) == 2  # the paper's model: they pass through each other


def test_a_feed_makes_the_particles_optional() -> None:
    content = {k: v for k, v in VALID.items() if k != 'particles'}
    with pytest.raises(ScenarioError, match="missing the key 'particles'"):
        scenario_from_mapping(content)
    sc = scenario_from_mapping({**content, 'feed': {'rate': 3.0, 'd_values': [30, 750],
                                                    'seed': 5}})
    assert sc.particles == () and sc.feed.rate == 3.0 and sc.feed_seed == 5
    assert sc.feed.d_values == (30.0, 750.0)
    assert scenario_from_mapping({**content, 'feed': {}, 'particles': []}).feed.rate == 0.0
    assert scenario_from_mapping(VALID).feed is None


def test_missing_keys_and_files(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="missing the key 'rotation'"):
        scenario_from_mapping({'duration': 1.0, 'particles': [{'position': [0, 0, 0.1]}]})
    with pytest.raises(ScenarioError, match='cannot read'):
        load_scenario(tmp_path / 'nope.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('duration: [1\n')
    with pytest.raises(ScenarioError, match='bad.yaml'):
        load_scenario(bad)


@pytest.mark.parametrize('text, message', [
    ('', 'the scenario is empty: it needs the keys duration, rotation, particles'),
    ('# only a comment\n', 'the scenario is empty'),
    ('- 1\n- 2\n', 'a scenario must be a mapping with keys duration, rotation, particles, '
                   'got list [1, 2]'),
    ('just text\n', "got str 'just text'"),
])
def test_an_empty_file_or_one_that_is_not_a_mapping(tmp_path: Path, text: str,
                                                    message: str) -> None:
    path = tmp_path / 'scenario.yaml'
    path.write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert str(info.value).startswith(f'{path}: ') and message in str(info.value)
    assert '\n' not in str(info.value)


def test_parameter_file_relative_to_the_scenario(tmp_path: Path) -> None:
    (tmp_path / 'p.yaml').write_text('d: 30.0\nmu_C: 0.5\n')
    (tmp_path / 's.yaml').write_text(
        'duration: 1.0\nparameters: p.yaml\nrotation: 2.0\n'
        'particles:\n  - position: [0.1, 0.0, 0.05]\n')
    sc = load_scenario(tmp_path / 's.yaml')
    assert sc.model.product.d == 30.0 and sc.model.product.mu_C == 0.5
    assert sc.model.product.mu_S == 0.99  # the rest from Table II defaults


def test_interactions_are_off_unless_the_scenario_turns_them_on() -> None:
    assert scenario_from_mapping(VALID).model.interactions.enabled is False  # paper's model
    sc = scenario_from_mapping({**VALID, 'interactions': {'enabled': True, 'pull_off': 0.2}})
    assert sc.model.interactions.enabled is True and sc.model.interactions.pull_off == 0.2
    sc = scenario_from_mapping({**VALID, 'interactions': {'enabled': True}})
    assert sc.model.interactions.pull_off == 0.05  # the parameter file's


@pytest.mark.parametrize('value, fragment', [
    ({'enabled': 'yes'}, "'interactions.enabled' must be true or false"),
    ({'pull_off': -1.0}, "'interactions.pull_off' = -1 is out of range"),
    ({'stickiness': 1.0}, "unknown interactions key(s) 'stickiness'"),
    ([True], 'interactions must be a mapping'),
])
def test_bad_interactions_name_the_problem(value: object, fragment: str) -> None:
    with pytest.raises(ScenarioError) as info:
        scenario_from_mapping({**VALID, 'interactions': value})
    assert fragment in str(info.value)


def test_weigher_section() -> None:
    from cone_feeder_sim.weigher.machine import WeigherParams
    assert scenario_from_mapping(VALID).weigher is None  # no section: no weigher
    assert scenario_from_mapping({**VALID, 'weigher': {}}).weigher == WeigherParams()
    assert scenario_from_mapping({**VALID, 'weigher': None}).weigher == WeigherParams()
    sc = scenario_from_mapping({**VALID, 'weigher': {'target': 0.5, 'max_heads': 4}})
    assert (sc.weigher.target, sc.weigher.max_heads) == (0.5, 4)
    for bad, name in [({'target': -1.0}, 'weigher.target'), ({'colour': 1}, 'colour'),
                      ({'max_heads': 'many'}, 'weigher.max_heads'), ([1, 2], 'mapping'),
                      ({'heads': 10}, 'heads')]:
        with pytest.raises(ScenarioError, match=name):
            scenario_from_mapping({**VALID, 'weigher': bad})
