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

from .feed import FeedParams
from ..physics.params import ModelParams, ProductParams, SolverParams
from ..physics.rotation import RotationProfile
from ..weigher.machine import WeigherParams


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
