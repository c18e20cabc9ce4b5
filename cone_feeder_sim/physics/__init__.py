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
The model of the paper and its integration: no rclpy, no mcap, no file I/O.

Parameters (Table II, validated), the equations (eqs. 2-38, compiled), the RODAS4
Rosenbrock method and its step control, rotation profiles, and the simulation state with a
pure ``advance``. Everything else in the package is built on this.
"""
