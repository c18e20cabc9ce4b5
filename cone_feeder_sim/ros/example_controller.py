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
``example_controller``: a simple feedback controller that spreads product over the channels.

Run it beside the simulator::

    ros2 run cone_feeder_sim sim_node --ros-args --params-file config/sim_node.yaml
    ros2 run cone_feeder_sim example_controller

It subscribes ``exit_events`` (sensor_msgs/PointCloud2, fields channel and mass) and
``channel_mass`` (std_msgs/Float64MultiArray, cumulative kg per channel) and publishes
``rotation_cmd`` (std_msgs/Float64, rad/s) at ``command_rate`` Hz, which also keeps the
simulator's ``cmd_timeout`` from stopping the cone.

Strategy (deliberately simple): the cone turns at ``speed`` rad/s, clockwise or
counter-clockwise; every ``period`` seconds the controller chooses the direction.
For each direction it learns where product leaves: an exponentially weighted histogram of
the mass per channel of the exits seen while that direction was commanded (weight
``learning_rate`` per period). The deficit of a channel is how far its cumulative mass is
below the mean over channels; the controller takes the direction whose learned histogram
(normalised) puts most product into the deficit, i.e. maximises sum_c h_dir[c] deficit[c].
A direction without data, or not used for ``explore_after`` periods, is tried next, so
both histograms stay current. Each decision is logged with the imbalance
(max - min) / mean of the channel masses.

With ``objective: hoppers`` the masses evened out are the weigh hoppers' readings
(``hopper_weights`` of the weigher below the cone) instead of the cumulative channel
masses: the controller turns the cone to keep the weigh hoppers fed evenly.

Its authority depends on the feed: where product is dropped evenly around the cone, both
directions spread it about evenly and the controller mainly corrects random imbalance;
where product arrives on one side, the direction moves it to different channels.
Timers follow the node's clock, so with ``use_sim_time`` (and ``publish_clock`` on the
simulator) periods are in simulated time.
"""

import sys
from typing import Any

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Float64, Float64MultiArray

from .guarded_node import run_node
from .parameters import declare, ParamSpec, warn_unknown_parameters
from .qos import rclpy_qos
from ..errors import ParameterError
from ..formats.pointcloud import cloud_points
from ..formats.topics import TOPICS
from ..physics.params import Limit

__all__ = ['DirectionLearner', 'ExampleController', 'choose_direction', 'main']

#: The controller's parameters.
PARAMETERS = (
    ParamSpec('speed', 8.0, 'cone speed (rad/s)', limit=Limit(0.1, 100.0, 'rad/s')),
    ParamSpec('period', 2.0, 'seconds between direction decisions',
              limit=Limit(0.1, 3600.0, 's')),
    ParamSpec('command_rate', 10.0, 'rotation_cmd messages per second',
              limit=Limit(0.5, 1000.0, '1/s')),
    ParamSpec('learning_rate', 0.3, 'weight of the newest period in the learned exit '
              'histograms', limit=Limit(0.0, 1.0, '')),
    ParamSpec('explore_after', 3, 'periods after which an unused direction is tried',
              limit=Limit(1, 1000, '')),
    ParamSpec('objective', 'channel_mass', 'what the controller evens out: channel_mass '
              "(the cumulative mass per channel) or hoppers (the weigher's weigh hoppers, "
              'from hopper_weights)', constraints='channel_mass or hoppers'),
)

#: Values of the ``objective`` parameter: the topic whose values are evened out.
OBJECTIVES = {'channel_mass': 'channel_mass', 'hoppers': 'hopper_weights'}


def choose_direction(histograms: dict[int, np.ndarray], masses: np.ndarray,
                     unused: dict[int, int], explore_after: int, last: int) -> int:
    """
    Return +1 (counter-clockwise) or -1 (clockwise) for the next period.

    histograms: learned exit mass per channel for each direction; masses: cumulative mass
    per channel; unused: periods since each direction was last commanded.
    """
    for direction in (last * -1, last):
        if histograms[direction].sum() <= 0.0 or unused[direction] >= explore_after:
            return direction
    deficit = np.maximum(masses.mean() - masses, 0.0) if masses.size else masses
    if not deficit.size or deficit.sum() <= 0.0:
        return -last
    scores = {d: float(np.dot(h / h.sum(), deficit)) for d, h in histograms.items()}
    if scores[1] == scores[-1]:
        return -last
    return 1 if scores[1] > scores[-1] else -1


class DirectionLearner:
    """
    The controller's state without ROS: learned exit histograms and the commanded direction.

    ``add_exits`` during a period, ``decide`` at its end (see the module documentation);
    the node feeds it from its subscriptions, and a headless evaluation from the engine.
    """

    def __init__(self, learning_rate: float, explore_after: int, direction: int = -1) -> None:
        """Start with no data, turning in ``direction`` (+1 or -1)."""
        self.learning_rate = learning_rate
        self.explore_after = explore_after
        self.direction = direction
        self.histograms: dict[int, np.ndarray] = {1: np.zeros(0), -1: np.zeros(0)}
        self.current = np.zeros(0)
        self.unused = {1: 0, -1: 0}

    def _resize(self, count: int) -> None:
        """Grow the histograms to ``count`` channels, keeping what was learned."""
        if self.current.size < count:
            grow = count - self.current.size
            self.current = np.pad(self.current, (0, grow))
            self.histograms = {d: np.pad(h, (0, grow)) for d, h in self.histograms.items()}

    def add_exits(self, channels: np.ndarray, masses: np.ndarray) -> None:
        """Add exits (channels 1-based, masses kg) to this period's histogram."""
        channels = np.asarray(channels, dtype=int)
        if channels.size:
            self._resize(int(channels.max()))
            np.add.at(self.current, channels - 1, masses)

    def decide(self, masses: np.ndarray) -> int:
        """Learn from the period that ended and return the next direction."""
        self._resize(masses.size)
        if self.current.size:
            learned = self.histograms[self.direction]
            self.histograms[self.direction] = ((1.0 - self.learning_rate) * learned
                                               + self.learning_rate * self.current)
            self.current = np.zeros_like(self.current)
        self.unused[self.direction] = 0
        self.unused[-self.direction] += 1
        self.direction = choose_direction(self.histograms, masses, self.unused,
                                          self.explore_after, self.direction)
        return self.direction


class ExampleController(Node):
    """Choose the cone's direction from the channel deficits; see the module documentation."""

    def __init__(self, **kwargs: Any) -> None:
        """Declare the parameters and create the subscriptions, publisher and timers."""
        super().__init__(kwargs.pop('node_name', 'example_controller'), **kwargs)
        values = {spec.name: declare(self, spec).value for spec in PARAMETERS}
        warn_unknown_parameters(self)
        self.speed = values['speed']
        self.period = values['period']
        rate = values['command_rate']
        if values['objective'] not in OBJECTIVES:
            raise ParameterError(f"parameter 'objective' must be one of "
                                 f"{', '.join(OBJECTIVES)}, got {values['objective']!r}")
        self.learner = DirectionLearner(values['learning_rate'], values['explore_after'])
        self.masses = np.zeros(0)
        self.exits = 0
        self.pub = self.create_publisher(Float64, 'rotation_cmd',
                                         rclpy_qos(TOPICS['rotation_cmd'].qos))
        self.create_subscription(PointCloud2, 'exit_events', self.on_exits,
                                 rclpy_qos(TOPICS['exit_events'].qos))
        topic = OBJECTIVES[values['objective']]
        self.create_subscription(Float64MultiArray, topic, self.on_channel_mass,
                                 rclpy_qos(TOPICS[topic].qos))
        self.create_timer(1.0 / rate, self.send)
        self.create_timer(self.period, self.decide)
        self.send()

    @property
    def direction(self) -> int:
        """Return the commanded direction: +1 counter-clockwise, -1 clockwise."""
        return self.learner.direction

    def on_channel_mass(self, msg: Float64MultiArray) -> None:
        """Keep the masses to even out (index 0 = channel 1): cumulative, or in hoppers."""
        self.masses = np.array(msg.data, dtype=float)

    def on_exits(self, msg: PointCloud2) -> None:
        """Add the exits to this period's histogram of the commanded direction."""
        rows = cloud_points(msg)
        self.learner.add_exits(rows['channel'], rows['mass'])
        self.exits += rows.size

    def send(self) -> None:
        """Publish the current command."""
        self.pub.publish(Float64(data=float(self.direction * self.speed)))

    def decide(self) -> None:
        """Learn from the last period and choose the next direction."""
        new = self.learner.decide(self.masses)
        imbalance = 0.0
        if self.masses.size and self.masses.mean() > 0.0:
            imbalance = float((self.masses.max() - self.masses.min()) / self.masses.mean())
        self.get_logger().info(
            f'{self.exits} exits, {self.masses.sum():.3f} kg, imbalance {imbalance:.2f}; '
            f'next: {"counter-clockwise" if new > 0 else "clockwise"}')
        self.send()


def main(args: list[str] | None = None) -> int:
    """Run the controller until shut down; return the process exit status."""
    return run_node(ExampleController, 'example_controller', args)


if __name__ == '__main__':
    sys.exit(main())
