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
The project's data formats: files, ROS 2 messages and MCAP runs; no rclpy.

Parameter and scenario files, the events CSV, ROS 2 messages as CDR (message definitions,
topics, point layouts, message building), and MCAP runs (writing, reading, run metadata).
The headless runner, the recorder and the report use them without ROS installed.
"""
