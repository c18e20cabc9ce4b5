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


"""A scenario for the headless runner: start state, rotation table and duration, validated."""

from dataclasses import dataclass
import math

from .feed import FeedParams
from ..errors import ScenarioError
from ..physics.params import ModelParams, ProductParams, SolverParams
from ..physics.rotation import RotationProfile
from ..weigher.machine import WeigherParams


#: The most output intervals one run may ask for (duration / output_interval). An interval
#: costs the runner 0.2-1 ms even with nothing to do (measured on one piece at 0.1-0.01 ms
#: intervals), so this many is minutes; 10^12 (an interval of 1e-12 s) would never end. The
#: interval itself is not bounded: a millisecond of a hard collision at 54-ns outputs is
#: 18,519 of them.
MAX_OUTPUTS = 1_000_000


def output_count(duration: float, output_interval: float) -> int:
    """Return how many output intervals a run of ``duration`` (s) asks for."""
    return math.ceil(duration / output_interval - 1e-9)


def check_output_count(duration: float, output_interval: float) -> None:
    """Raise ScenarioError, naming output_interval and the count, past MAX_OUTPUTS."""
    count = output_count(duration, output_interval)
    if count > MAX_OUTPUTS:
        raise ScenarioError(
            f'output_interval: {output_interval:g} s over duration {duration:g} s asks for '
            f'{count:,} outputs, more than {MAX_OUTPUTS:,}; make output_interval at least '
            f'{duration / MAX_OUTPUTS:g} s or the duration shorter')


@dataclass(frozen=True)
class ParticleSpec:
    """One piece of a scenario: world position (m), velocity (m/s) or None, product."""

    position: tuple[float, float, float]
    velocity: tuple[float, float, float] | None
    product: ProductParams


@dataclass(frozen=True)
class Scenario:
    """
    A validated scenario.

    duration (s); particles placed at t = 0 (ids 0 .. len - 1); output_interval (s) of the
    runner's progress and output; weigher: the machine below the cone, or None (no
    weigher); feed: pieces dropped during the run (:mod:`~cone_feeder_sim.feeder.feed`,
    drawn once per output interval from a generator seeded with feed_seed; ids continue
    after the particles), or None (no feed).
    """

    duration: float
    model: ModelParams
    solver: SolverParams
    rotation: RotationProfile
    particles: tuple[ParticleSpec, ...]
    output_interval: float = 0.01
    weigher: WeigherParams | None = None
    feed: FeedParams | None = None
    feed_seed: int = 0
