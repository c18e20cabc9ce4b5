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
``policy_controller``: a policy trained on the RL environment turns the cone of ``sim_node``.

Run it beside the simulator (``pip install cone_feeder_sim[rl]``; the policy and the
environment's configuration as ``examples/train_ppo.py`` writes them)::

    ros2 run cone_feeder_sim sim_node --ros-args --params-file config/sim_node.yaml
    ros2 run cone_feeder_sim policy_controller --ros-args -p policy:=results/ppo/policy.zip

Every ``control_period`` of the environment (on the node's clock: with ``use_sim_time``, in
simulated time) it rebuilds the environment's observation from the simulator's topics
(``cone_state``: angle and omega; ``channel_mass``; ``particle_states``, turned into the
cone's frame; ``hopper_weights`` where the environment has the weigher), asks the policy and
publishes the target on ``rotation_cmd`` (std_msgs/Float64, rad/s), and the feed amplitudes on
``channel_feed`` where the policy sets them. Its episode starts at the first control period
after the first ``cone_state`` and ``channel_mass``: the deficits count from there, as in the
environment after a reset. The simulator's ``max_angular_acceleration`` and ``feed`` should be
the environment's, which is what the policy learned on (the node warns where the drive's
limits differ from what it reads in the environment's configuration; it cannot see them).
"""

from pathlib import Path
import sys
from typing import Any

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import JointState, PointCloud2
from std_msgs.msg import Float64, Float64MultiArray

from .guarded_node import run_node
from .parameters import declare, ParamSpec, warn_unknown_parameters
from .qos import rclpy_qos
from ..errors import ParameterError
from ..formats.pointcloud import cloud_points
from ..formats.topics import TOPICS
from ..physics.simulation import cone_from_world

try:  # the optional extra [rl]: gymnasium and stable-baselines3
    from ..rl.config import EnvConfig, load_env_config
    from ..rl.sb3 import ALGORITHMS, load_policy
    from ..rl.spaces import action_space, decode_action, observation
    MISSING = ''
except ModuleNotFoundError as exc:  # main() says what to install
    MISSING = exc.name or str(exc)
    ALGORITHMS = ('PPO',)

__all__ = ['PolicyController', 'main', 'observe']

#: The controller's parameters.
PARAMETERS = (
    ParamSpec('policy', '', 'the saved stable-baselines3 policy (.zip)',
              constraints='a file'),
    ParamSpec('config', '', "the environment's configuration the policy was trained on "
              '(empty: env_config.yaml beside the policy)'),
    ParamSpec('algorithm', 'PPO', 'the stable-baselines3 algorithm of the policy',
              constraints=', '.join(ALGORITHMS)),
    ParamSpec('deterministic', True, "take the policy's most likely action"),
)


def observe(config: 'EnvConfig', angle: float, omega: float, deficit: np.ndarray,
            hoppers: np.ndarray | None, points: np.ndarray) -> Any:
    """
    Return the environment's observation from the simulator's topics.

    angle (rad) and omega (rad/s) from ``cone_state``; deficit (channels,) kg;
    hoppers (heads,) kg or None; points: the ``particle_states`` rows (world frame).
    """
    q = np.stack([points['x'], points['y'], points['z']], axis=1).astype(np.float64)
    qdot = np.stack([points['vx'], points['vy'], points['vz']], axis=1).astype(np.float64)
    order = np.argsort(points['id'], kind='stable')
    states = cone_from_world(q[order], qdot[order], np.zeros_like(q), angle, omega)[:, 0:6]
    return observation(config, omega, angle, deficit, hoppers, states,
                       np.asarray(points['mass'], dtype=np.float64)[order])


class PolicyController(Node):
    """Turn the cone as a trained policy says; see the module documentation."""

    def __init__(self, **kwargs: Any) -> None:
        """Load the policy and its environment; create the subscriptions and the timer."""
        super().__init__(kwargs.pop('node_name', 'policy_controller'), **kwargs)
        values = {spec.name: declare(self, spec).value for spec in PARAMETERS}
        warn_unknown_parameters(self)
        if not values['policy']:
            raise ParameterError("parameter 'policy' is needed: the saved policy (.zip)")
        policy = Path(values['policy'])
        self.policy = load_policy(str(policy), values['algorithm'])
        config_path = Path(values['config'] or policy.parent / 'env_config.yaml')
        self.config = load_env_config(config_path)
        self.deterministic = bool(values['deterministic'])
        self.action_space = action_space(self.config)
        self.targets = np.array(self.config.channel_targets)
        self.cone: tuple[float, float] | None = None
        self.masses: np.ndarray | None = None
        self.hoppers: np.ndarray | None = None
        self.points: np.ndarray | None = None
        self.start: tuple[float, np.ndarray] | None = None
        self.commands = 0
        self.last_omega = 0.0
        self.pub = self.create_publisher(Float64, 'rotation_cmd',
                                         rclpy_qos(TOPICS['rotation_cmd'].qos))
        self.feed_pub = (self.create_publisher(Float64MultiArray, 'channel_feed',
                                               rclpy_qos(TOPICS['channel_feed'].qos))
                         if self.config.feed_amplitudes else None)
        self.create_subscription(JointState, 'cone_state', self.on_cone,
                                 rclpy_qos(TOPICS['cone_state'].qos))
        self.create_subscription(Float64MultiArray, 'channel_mass', self.on_masses,
                                 rclpy_qos(TOPICS['channel_mass'].qos))
        self.create_subscription(PointCloud2, 'particle_states', self.on_points,
                                 rclpy_qos(TOPICS['particle_states'].qos))
        if self.config.engine.weigher is not None:
            self.create_subscription(Float64MultiArray, 'hopper_weights', self.on_hoppers,
                                     rclpy_qos(TOPICS['hopper_weights'].qos))
        self.create_timer(self.config.control_period, self.act)
        self.get_logger().info(f'policy {policy} ({values["algorithm"]}), environment '
                               f'{config_path}, every {self.config.control_period:g} s')

    def on_cone(self, msg: JointState) -> None:
        """Keep the cone's angle and omega."""
        if msg.position and msg.velocity:
            self.cone = (float(msg.position[0]), float(msg.velocity[0]))

    def on_masses(self, msg: Float64MultiArray) -> None:
        """Keep the cumulative mass per channel (kg)."""
        self.masses = np.array(msg.data, dtype=float)

    def on_hoppers(self, msg: Float64MultiArray) -> None:
        """Keep the weigh hoppers' readings (kg)."""
        self.hoppers = np.array(msg.data, dtype=float)

    def on_points(self, msg: PointCloud2) -> None:
        """Keep the pieces on the cone."""
        self.points = np.array(cloud_points(msg))

    def act(self) -> None:
        """Observe, ask the policy and publish its command."""
        if self.cone is None or self.masses is None:
            return
        if self.masses.size != self.targets.size:
            self.get_logger().error(f'channel_mass has {self.masses.size} channels, the '
                                    f'environment {self.targets.size}: no command')
            return
        now = self.get_clock().now().nanoseconds * 1e-9
        if self.start is None:
            self.start = (now, self.masses.copy())
        deficit = self.targets * (now - self.start[0]) - (self.masses - self.start[1])
        points = self.points if self.points is not None else np.zeros(
            0, dtype=[(n, 'f8') for n in ('x', 'y', 'z', 'vx', 'vy', 'vz', 'mass', 'id')])
        hoppers = self.hoppers
        if self.config.engine.weigher is not None and hoppers is None:
            hoppers = np.zeros(self.config.engine.model.channels.count)
        obs = observe(self.config, *self.cone, deficit, hoppers, points)
        action, _ = self.policy.predict(obs, deterministic=self.deterministic)
        omega, amplitudes = decode_action(self.config, self.action_space, action)
        self.pub.publish(Float64(data=omega))
        if amplitudes is not None and self.feed_pub is not None:
            self.feed_pub.publish(Float64MultiArray(data=list(amplitudes)))
        self.commands += 1
        self.last_omega = omega


def main(args: list[str] | None = None) -> int:
    """Run the controller until shut down; return the process exit status."""
    if MISSING:
        print(f'policy_controller needs the RL extra (missing module {MISSING!r}): pip '
              "install 'cone_feeder_sim[rl]'", file=sys.stderr)
        return 1
    return run_node(PolicyController, 'policy_controller', args)


if __name__ == '__main__':
    sys.exit(main())
