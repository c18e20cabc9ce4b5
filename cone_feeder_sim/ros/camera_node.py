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
``camera_node``: a camera standing in for the real one, between a plant and its twin.

Run it beside ``sim_node`` (the plant) and ``twin_node``::

    ros2 run cone_feeder_sim camera_node

It subscribes ``particle_states`` (sim_node's true pieces, sensor_msgs/PointCloud2) and
publishes ``detections`` (PointCloud2 of :data:`~..formats.pointcloud.DETECTION_DTYPE`:
x, y, z, track_id; the frame's stamp and frame_id kept, the time it was taken) as a camera
over the feeder gives them (:mod:`..twin.camera`): noise on x and y, pieces missed, false
detections, track ids swapped, every frame ``delay`` plus up to ``jitter`` seconds late (so
that frames arrive out of order, as the twin must take them; wall-clock seconds, as a
camera's network delays them, whatever sim_node's real_time_factor). The settings are read
at the start; a frame that cannot be read is logged in one line and the camera goes on.
"""

import heapq
import itertools
import sys
import time
from typing import Any

import numpy as np

from .guarded_node import GuardedNode, run_node
from .outputs import Outputs
from .parameters import declare, ParamSpec, warn_unknown_parameters
from ..errors import ConeFeederError
from ..formats.cdr import CdrCodec
from ..formats.messages import cloud_message
from ..formats.pointcloud import cloud_points, DETECTION_DTYPE
from ..formats.topics import CAMERA_TOPICS
from ..twin.camera import CAMERA_LIMITS, CameraSettings, observe

__all__ = ['CameraNode', 'main']

_DESCRIPTIONS = {
    'sigma': 'the noise of x and y (m, each)',
    'miss': 'the probability that a piece is not detected in a frame',
    'false_rate': 'the probability of a false detection in a frame',
    'radius': 'false detections are uniform over the disc of this radius (m) about the axis',
    'swap': 'the probability that two detections exchange their track ids in a frame',
    'delay': 'every frame is passed on this late (s)',
    'jitter': 'and up to this much later again (s, uniform; frames then come out of order)',
    'seed': "the camera's random numbers",
}
#: The node's parameters: :class:`~..twin.camera.CameraSettings`, with its defaults and ranges.
CAMERA_PARAMETERS = tuple(
    ParamSpec(name, getattr(CameraSettings, name), _DESCRIPTIONS[name], limit=limit)
    for name, limit in CAMERA_LIMITS.items())
#: How often (s) the held frames are looked at.
RELEASE_PERIOD = 0.002


class CameraNode(GuardedNode):
    """Turn a plant's true pieces into a camera's detections; see the module documentation."""

    def __init__(self, **kwargs: Any) -> None:
        """Declare the parameters, create the topics and the timer that passes frames on."""
        super().__init__('camera_node', **kwargs)

    def _setup(self) -> None:
        values = {spec.name: declare(self, spec).value for spec in CAMERA_PARAMETERS}
        warn_unknown_parameters(self)
        self.settings = CameraSettings(**values)
        self._rng = np.random.default_rng(self.settings.seed)
        self._codec = CdrCodec()
        self._outputs = Outputs(self, self._codec, CAMERA_TOPICS)
        self._pub = self._outputs.publisher('detections')
        self._outputs.subscription('particle_states', self._on_states)
        self._held: list[tuple[float, int, dict[str, Any], int]] = []  # a heap, by time due
        self._order = itertools.count()
        self.taken = self.frames = 0  # the frames taken in and passed on
        self._timer = self.create_timer(RELEASE_PERIOD, self._release)
        self._timer.cancel()  # runs while frames are held
        s = self.settings
        self.get_logger().info(
            f'camera: {1e3 * s.sigma:g} mm of noise, {100 * s.miss:g} % missed, false '
            f'detections in {100 * s.false_rate:g} % of the frames, {1e3 * s.delay:g}-'
            f'{1e3 * (s.delay + s.jitter):g} ms late')

    def _on_states(self, data: bytes) -> None:
        """Take the plant's frame; hold its detections until they are due."""
        try:
            msg = self._codec.decode('sensor_msgs/msg/PointCloud2', data, strict=False)
            points = cloud_points(msg)
            names = points.dtype.names or ()
            if not {'x', 'y', 'z'} <= set(names):
                raise ConeFeederError('particle_states refused: it has no fields x, y, z')
            truth = np.column_stack([points['x'], points['y'], points['z']]).astype(float)
            ids = points['id'] if 'id' in names else np.arange(len(points))
        except (ConeFeederError, ValueError, KeyError) as exc:
            self.get_logger().warning(str(exc), throttle_duration_sec=1.0)
            return
        self.taken += 1
        seen, track = observe(self.settings, self._rng, truth, ids)
        found = np.zeros(len(seen), dtype=DETECTION_DTYPE)
        found['x'], found['y'], found['z'] = seen[:, 0], seen[:, 1], seen[:, 2]
        found['track_id'] = track
        late = self.settings.delay + self.settings.jitter * self._rng.random()
        head = msg['header']
        ns = head['stamp']['sec'] * 1_000_000_000 + head['stamp']['nanosec']
        heapq.heappush(self._held, (time.monotonic() + late, next(self._order),
                                    cloud_message(head, found), ns))
        if self._timer.is_canceled():
            self._timer.reset()

    def _release(self) -> None:
        """Publish the held frames that are due, in the order they fall due."""
        now = time.monotonic()
        while self._held and self._held[0][0] <= now:
            _, _, message, ns = heapq.heappop(self._held)
            self._outputs.publish(self._pub, message, ns)
            self.frames += 1
        if not self._held:
            self._timer.cancel()


def main(args: list[str] | None = None) -> int:
    """Run camera_node until SIGINT or SIGTERM."""
    return run_node(CameraNode, 'camera_node', args)


if __name__ == '__main__':
    sys.exit(main())
