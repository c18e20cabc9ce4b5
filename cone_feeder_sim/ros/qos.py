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

"""The one conversion of the project's QoS profiles (rosbag2's vocabulary) to rclpy's."""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..formats.topics import QosProfile

__all__ = ['rclpy_qos']


def rclpy_qos(profile: QosProfile | None) -> QoSProfile:
    """
    Return rclpy's profile of ``profile``: history, depth, reliability and durability.

    The names are rosbag2's lower-case names of the same rmw policies, so every value
    (``system_default``, ``best_available`` and ``unknown`` included) maps to its own
    policy. ``None`` (a recording without usable QoS metadata) gives the defaults of
    :class:`QosProfile`: reliable, keep last 10, volatile. A depth of 0 (rosbag2 writes it
    for keep-all topics) becomes 1, the smallest depth rclpy accepts.
    """
    if profile is None:
        profile = QosProfile()
    return QoSProfile(
        history=HistoryPolicy[profile.history.upper()],
        depth=max(profile.depth, 1),
        reliability=ReliabilityPolicy[profile.reliability.upper()],
        durability=DurabilityPolicy[profile.durability.upper()])
