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
Seeing the feeder without ROS.

``frame`` draws a top view of the cone as an RGB array with numpy alone (no display, no
matplotlib): what the RL environment's ``render_mode="rgb_array"`` returns. ``live`` serves
a run on a Foxglove WebSocket (:class:`LiveView`, the optional extra ``[view]``:
foxglove-sdk): ``cone-feeder-sim run --view``, the RL environment's ``"human"`` mode.
``snapshot`` takes what a view shows from the runner or the engine; ``scene`` builds the
Foxglove messages; ``topics`` is the view's topic table; ``layout`` its Foxglove layout.
"""

from .frame import top_view
from .live import LiveView
from .snapshot import Snapshot

__all__ = ['LiveView', 'Snapshot', 'top_view']
