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
The Foxglove layout of the live view and of the node's recordings (needs ``foxglove-sdk``).

One layout serves both: the 3D panel shows the live view's ``/scene`` and the node's
``/markers`` (both in the frame ``feeder``); the plots read ``/cone_state`` and
``/channel_mass`` and ``/hopper_weights``, which the live view and a node in the root
namespace publish with the same fields; the log shows the live view's ``/events`` (exits
and packs) and, in its second tab, the node's own events (``/sim_node/events``).

``config/foxglove_layout.json`` is this layout; write it again after a change with
``python -m cone_feeder_sim.view.layout config/foxglove_layout.json``.
"""

import json
from pathlib import Path
import sys

import foxglove.layouts as fl

from .topics import FRAME, node_topic, VIEW_TOPICS
from ..physics.params import ModelParams

__all__ = ['build_layout', 'layout_json']


def _plot(title: str, series: list[tuple[str, str]]) -> fl.PlotPanel:
    return fl.PlotPanel(title=title, config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=value, label=label, enabled=True)
               for value, label in series],
        show_legend=True, legend_display='left', x_axis_val='timestamp'))


def build_layout(model: ModelParams | None = None) -> fl.Layout:
    """Return the layout: 3D scene left; ω, channel masses, hopper weights, log right."""
    channels = (model or ModelParams()).channels.count
    cone_state = VIEW_TOPICS['cone_state'].name
    channel_mass = VIEW_TOPICS['channel_mass'].name
    hoppers = VIEW_TOPICS['hopper_weights'].name
    scene = fl.ThreeDeePanel(title='cone feeder', config=fl.ThreeDeeConfig(
        follow_tf=FRAME,
        topics={VIEW_TOPICS['scene'].name: fl.BaseRendererSceneUpdateTopicSettings(
                    visible=True),
                node_topic('markers'): fl.BaseRendererRosMarkerTopicSettings(visible=True)},
        camera_state=fl.ThreeDeeCameraState(distance=0.9, perspective=True, phi=40.0,
                                            target=(0.0, 0.0, 0.0), theta_offset=0.0,
                                            fovy=45.0, near=0.01, far=100.0)))
    omega = _plot('cone speed (rad/s)', [(f'{cone_state}.velocity[0]', 'ω')])
    masses = _plot('channel mass (kg)', [(f'{channel_mass}.data[{k}]', f'channel {k + 1}')
                                         for k in range(channels)])
    weights = _plot('hopper weights (kg)', [(f'{hoppers}.data[{k}]', f'head {k + 1}')
                                            for k in range(channels)])
    log = fl.TabContainer(tabs=[
        fl.TabItem(title='exits and packs', content=fl.LogPanel(
            config=fl.LogConfig(topic_to_render=VIEW_TOPICS['events'].name))),
        fl.TabItem(title='node events', content=fl.RawMessagesPanel(
            config=fl.RawMessagesConfig(topic_path=node_topic('~/events'))))])
    side = fl.SplitContainer(direction='column', items=[
        fl.SplitItem(content=omega), fl.SplitItem(content=masses),
        fl.SplitItem(content=weights), fl.SplitItem(content=log)])
    return fl.Layout(content=fl.SplitContainer(direction='row', items=[
        fl.SplitItem(proportion=3, content=scene), fl.SplitItem(proportion=2, content=side)]))


def layout_json(model: ModelParams | None = None) -> str:
    """Return the layout as the indented JSON text of config/foxglove_layout.json."""
    return json.dumps(json.loads(build_layout(model).to_json()), indent=2,
                      ensure_ascii=False) + '\n'


if __name__ == '__main__':
    Path(sys.argv[1]).write_text(layout_json(), encoding='utf-8')
