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

"""Re-simulation plans: which recordings this version can re-simulate exactly."""

from cone_feeder_sim.ros.parameters import parameter_specs
from cone_feeder_sim.ros.resim import made_with_the_stiff_pair_law


def test_recordings_with_contact_under_the_old_pair_law_are_told_apart() -> None:
    today = {spec.name: spec.default for spec in parameter_specs()}
    assert today['interactions.enabled'] and not made_with_the_stiff_pair_law(today)
    old = {name: value for name, value in today.items()
           if name not in ('interactions.restitution', 'interactions.friction')}
    assert made_with_the_stiff_pair_law(old)
    # contact off: the pair law never acted, such a recording re-simulates exactly
    assert not made_with_the_stiff_pair_law({**old, 'interactions.enabled': False})
