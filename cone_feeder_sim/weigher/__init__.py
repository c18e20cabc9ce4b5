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
Downstream of the cone: the multihead weigher (no rclpy, no file I/O).

Combination selection today (:func:`select_combination`); the dosing channels, pool and
weigh hoppers and the machine cycle are the rest of issue 12.
"""

from .combination import MAX_SUBSETS, select_combination, subset_count

__all__ = ['MAX_SUBSETS', 'select_combination', 'subset_count']
