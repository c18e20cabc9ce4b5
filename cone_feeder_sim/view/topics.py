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
The live view's topics, as one table, and the JSON layout of its time series.

The time series carry the names and fields of the node's topics (``cone_state``,
``channel_mass``, ``hopper_weights`` of :data:`~cone_feeder_sim.formats.topics.TOPICS`), so
that a plot of ``/cone_state.velocity[0]`` shows ω live and in a node's recording alike.
The scene (``/scene``, foxglove.SceneUpdate) is the live twin of the node's ``markers``;
exits and packs go to ``/events`` (foxglove.Log). Every entity is in the frame ``feeder``,
the node's frame.
"""

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..formats.parameter_file import config_dir
from ..formats.topics import TOPICS

__all__ = ['FRAME', 'JSON_SCHEMAS', 'layout_file', 'node_topic', 'VIEW_TOPICS', 'ViewTopic']

#: The Foxglove layout's file name in the package's config directory.
LAYOUT_FILE = 'foxglove_layout.json'

#: The frame of every entity: the node's (``frame_id`` parameter, default ``feeder``).
FRAME = 'feeder'


@dataclass(frozen=True)
class ViewTopic:
    """A topic of the live view: name, schema ('json' or a Foxglove schema) and content."""

    name: str
    schema: str
    what: str


def layout_file() -> Path:
    """Return the installed Foxglove layout (config/foxglove_layout.json of the package)."""
    return config_dir() / LAYOUT_FILE


def node_topic(name: str, node: str = 'sim_node') -> str:
    """Return the absolute name of one of the node's topics, the node in the root namespace."""
    if name not in TOPICS:
        raise KeyError(f'{name} is not a topic of the node')
    return '/' + name.replace('~', node) if name[0] != '/' else name


#: Every topic of the live view, by key.
VIEW_TOPICS: Mapping[str, ViewTopic] = {
    'scene': ViewTopic('/scene', 'foxglove.SceneUpdate',
                       'the cone, the channel sectors, a mark turning with the cone, the '
                       'pieces (spheres of s0, coloured by product) and their contacts'),
    'cone_state': ViewTopic(node_topic('cone_state'), 'json',
                            "the cone's angle position[0] (rad) and speed velocity[0] "
                            '(rad/s), as sensor_msgs/JointState'),
    'channel_mass': ViewTopic(node_topic('channel_mass'), 'json',
                              'data[i]: the mass channel i + 1 received (kg), as '
                              'std_msgs/Float64MultiArray'),
    'hopper_weights': ViewTopic(node_topic('hopper_weights'), 'json',
                                "data[i]: head i + 1's weigh hopper reading (kg, 0: empty); "
                                'with a weigher only'),
    'events': ViewTopic('/events', 'foxglove.Log', 'a line per exit and per pack'),
}


def _stamp() -> dict[str, Any]:
    return {'type': 'object', 'properties': {'sec': {'type': 'integer'},
                                             'nanosec': {'type': 'integer'}}}


_ARRAY = {'type': 'array', 'items': {'type': 'number'}}

#: JSON Schema of each JSON topic (what Foxglove offers in its message path completion).
JSON_SCHEMAS: Mapping[str, dict[str, Any]] = {
    'cone_state': {
        'type': 'object', 'title': 'sensor_msgs/JointState',
        'properties': {'header': {'type': 'object', 'properties': {
            'stamp': _stamp(), 'frame_id': {'type': 'string'}}},
            'name': {'type': 'array', 'items': {'type': 'string'}},
            'position': _ARRAY, 'velocity': _ARRAY, 'effort': _ARRAY}},
    'channel_mass': {'type': 'object', 'title': 'std_msgs/Float64MultiArray',
                     'properties': {'data': _ARRAY}},
    'hopper_weights': {'type': 'object', 'title': 'std_msgs/Float64MultiArray',
                       'properties': {'data': _ARRAY}},
}
