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
Tests of cone_feeder_sim.ros.parameters: one table of limits for files and ROS parameters.

For every parameter whose range comes from a validation table, a ``sim_node`` started with
the value and the validation that parameter files, scenarios and the engine use must accept
and refuse the same values at the edges of the range (and just inside and outside them).
"""

from collections.abc import Callable, Iterator
import math
from typing import Any

from cone_feeder_sim.errors import ConeFeederError
from cone_feeder_sim.feeder.engine import DriveParams, ENGINE_LIMITS, EngineConfig, FeedParams
from cone_feeder_sim.physics.params import (
    INTERACTION_LIMITS, InteractionParams, Limit, MODEL_LIMITS, model_params_from_mapping,
    PRODUCT_LIMITS, SOLVER_LIMITS, solver_params_from_mapping)
from cone_feeder_sim.ros.parameters import parameter_specs, table_i_pieces
from cone_feeder_sim.ros.sim_node import SimNode
from cone_feeder_sim.weigher.machine import WEIGHER_LIMITS, WeigherParams
import pytest
from rclpy.parameter import Parameter
import sim_process


def _drive(key: str) -> Callable[[Any], object]:
    return lambda value: DriveParams(**{key: value})


def _feed(key: str) -> Callable[[Any], object]:
    # the engine also checks the annulus against the cone (default model, as the node's)
    return lambda value: EngineConfig(feed=FeedParams(**{key: value}))


#: The validation a value goes through outside ROS, by parameter name.
VALIDATION: dict[str, Callable[[Any], object]] = {
    **{f'model.{key}': (lambda value, key=key: model_params_from_mapping({key: value}))
       for key in (*PRODUCT_LIMITS, *MODEL_LIMITS)},
    **{f'solver.{key}': (lambda value, key=key: solver_params_from_mapping({key: value}))
       for key in SOLVER_LIMITS},
    **{f'interactions.{key}': (lambda value, key=key: InteractionParams(**{key: value}))
       for key in INTERACTION_LIMITS},
    'max_angular_velocity': _drive('max_angular_velocity'),
    'max_angular_acceleration': _drive('max_angular_acceleration'),
    'cmd_timeout': _drive('cmd_timeout'),
    'feed.rate': _feed('rate'),
    'feed.rho_min': _feed('rho_min'),
    'feed.rho_max': _feed('rho_max'),
    'feed.drop_height': _feed('drop_height'),
    'feed.mass_rel_std': _feed('mass_rel_std'),
    'feed.max_pieces': _feed('max_pieces'),
    'feed.seed': lambda value: EngineConfig(seed=value),
    'spawn.max_height': lambda value: EngineConfig(spawn_max_height=value),
    **{f'weigher.{key}': (lambda value, key=key: EngineConfig(
        weigher=WeigherParams(**{key: value}))) for key in WEIGHER_LIMITS},
}

#: The tables the node's ranges must come from.
TABLES = (PRODUCT_LIMITS, MODEL_LIMITS, SOLVER_LIMITS, ENGINE_LIMITS, WEIGHER_LIMITS,
          INTERACTION_LIMITS)


def edges(limit: Limit, integer: bool) -> list[Any]:
    """Return values at, just inside and just outside both ends of a range."""
    if integer:
        lo, hi = int(limit.lo), int(limit.hi)
        return [lo - 1, lo, lo + 1, hi - 1, hi, hi + 1]
    lo, hi = float(limit.lo), float(limit.hi)
    outside = 1e-3 * (hi - lo)
    return [lo - outside, lo, math.nextafter(lo, math.inf), math.nextafter(hi, -math.inf), hi,
            hi + outside]


def validation_accepts(name: str, value: Any) -> bool:
    try:
        VALIDATION[name](value)
    except ConeFeederError:
        return False
    return True


@pytest.fixture(scope='module')
def harness() -> Iterator[sim_process.InProcess]:
    with sim_process.InProcess('test_parameters', timeout=20.0, spin_step=0.02) as ros:
        yield ros


def node_accepts(harness: sim_process.InProcess, name: str, value: Any) -> bool:
    """
    Start a node with ``value``; tell whether it was accepted.

    The node starts without initial pieces (a piece that no longer fits a changed cone would
    be refused for another reason than the value); for model parameters the feed annulus is
    shrunk to the cone's axis and the weigher is off (with many channels its combinations
    are refused) for the same reason.
    """
    base = {'record_path': '', 'initial_pieces.positions': [], 'initial_pieces.d': []}
    if name.startswith('model.'):  # (and the weigher has a head per channel)
        base.update({'feed.rho_min': 0.0, 'feed.rho_max': 0.0, 'weigher.enabled': False})
    base[name] = value
    overrides = [Parameter(k) if v == [] else Parameter(k, value=v) for k, v in base.items()]
    try:
        node = SimNode(context=harness.context, parameter_overrides=overrides)
    except Exception:  # noqa: B902 - a refused value raises rclpy's or the package's error
        return False
    node.destroy_node()
    return True


def test_every_range_of_the_node_comes_from_a_validation_table() -> None:
    specs = {spec.name: spec for spec in parameter_specs()}
    shared = {name for name, spec in specs.items()
              if spec.limit is not None and any(spec.limit in t.values() for t in TABLES)}
    assert shared == set(VALIDATION)


@pytest.mark.parametrize('name', sorted(VALIDATION))
def test_node_and_validation_accept_the_same_values(harness: sim_process.InProcess,
                                                    name: str) -> None:
    spec = next(spec for spec in parameter_specs() if spec.name == name)
    integer = spec.type_() == Parameter.Type.INTEGER
    for value in edges(spec.limit, integer):
        if integer and not -2 ** 63 <= value < 2 ** 63:
            continue  # no int64 ROS parameter can hold it
        expected = validation_accepts(name, value)
        assert node_accepts(harness, name, value) == expected, (name, value, expected)


def test_seeds_stay_integers_end_to_end() -> None:
    seed = 2 ** 53 + 1  # not a float: float(seed) == 2 ** 53
    assert EngineConfig(seed=seed).seed == seed
    with pytest.raises(ConeFeederError, match='integer'):
        EngineConfig(seed=float(2 ** 53))


def test_default_pieces_are_those_of_table_i() -> None:
    pieces = table_i_pieces()
    assert [d for _, d in pieces] == [225.0, 135.0, 750.0, 750.0, 30.0]
    assert pieces[0][0] == (0.11, -0.01, 0.03)
