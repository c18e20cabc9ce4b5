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
The deterministic feeder: a cone drive, a feed of pieces and inputs applied at tick boundaries.

:class:`~cone_feeder_sim.feeder.engine.FeederEngine` is what ``sim_node`` ticks;
:func:`~cone_feeder_sim.feeder.runner.run_scenario` is the headless loop of a scenario.
Built on :mod:`cone_feeder_sim.physics`; no rclpy, no mcap, no file I/O.
"""
