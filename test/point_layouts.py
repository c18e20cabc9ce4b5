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
The documented PointCloud2 layouts (doc/sim_node.md), written out for the tests.

Shared by the tests of the point layouts and of the report; deliberately not taken from the
package, so that a change of the package's layouts shows.
"""

UINT32, FLOAT32, FLOAT64 = 6, 7, 8
#: particle_states: (name, offset, datatype), 32 bytes per point.
STATE_FIELDS = [
    ('x', 0, FLOAT32), ('y', 4, FLOAT32), ('z', 8, FLOAT32), ('vx', 12, FLOAT32),
    ('vy', 16, FLOAT32), ('vz', 20, FLOAT32), ('id', 24, UINT32), ('mass', 28, FLOAT32)]
#: exit_events: (name, offset, datatype), 80 bytes per point.
EXIT_FIELDS = [
    ('x', 0, FLOAT64), ('y', 8, FLOAT64), ('z', 16, FLOAT64), ('vx', 24, FLOAT64),
    ('vy', 32, FLOAT64), ('vz', 40, FLOAT64), ('exit_time', 48, FLOAT64),
    ('angle', 56, FLOAT64), ('mass', 64, FLOAT64), ('id', 72, UINT32), ('channel', 76, UINT32)]
