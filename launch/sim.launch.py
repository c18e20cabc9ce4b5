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
Launch the cone feeder simulator ``sim_node``, optionally with ``example_controller``.

In a ROS 2 Jazzy workspace, after ``colcon build`` and sourcing ``install/setup.bash``::

    ros2 launch cone_feeder_sim sim.launch.py
    ros2 launch cone_feeder_sim sim.launch.py with_controller:=true namespace:=line1
    ros2 launch cone_feeder_sim sim.launch.py params_file:=my_sim.yaml use_sim_time:=true
    ros2 launch cone_feeder_sim sim.launch.py --show-args

The launch arguments:

- ``namespace`` (default ``''``): namespace of both nodes (their topics are relative).
- ``use_sim_time`` (default ``false``): ``use_sim_time`` of both nodes; ``true`` also sets
  ``sim_node``'s ``publish_clock``, so the simulator publishes ``/clock`` (its own ticks run
  on the steady clock either way; the controller's timers then run in simulated time).
  The launch sets ``publish_clock`` to this value over what ``params_file`` says.
- ``params_file`` (default: the package's installed ``config/sim_node.yaml``): parameters of
  ``sim_node``; its key ``/**/sim_node`` matches the node in any namespace. Recording
  (``record_path``) is set there; relative paths start in the directory of ``ros2 launch``.
- ``with_controller`` (default ``false``): also start ``example_controller``.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

PACKAGE = 'cone_feeder_sim'


def generate_launch_description() -> LaunchDescription:
    """Return the launch description: sim_node and, if asked, example_controller."""
    namespace = LaunchConfiguration('namespace')
    use_sim_time = LaunchConfiguration('use_sim_time')
    params_file = LaunchConfiguration('params_file')
    with_controller = LaunchConfiguration('with_controller')

    return LaunchDescription([
        DeclareLaunchArgument(
            'namespace', default_value='',
            description='namespace of the simulator and the controller'),
        DeclareLaunchArgument(
            'use_sim_time', default_value='false', choices=['true', 'false'],
            description='use_sim_time of both nodes; true also makes sim_node publish /clock '
                        '(its publish_clock parameter)'),
        DeclareLaunchArgument(
            'params_file',
            default_value=PathJoinSubstitution(
                [FindPackageShare(PACKAGE), 'config', 'sim_node.yaml']),
            description='parameter file of sim_node'),
        DeclareLaunchArgument(
            'with_controller', default_value='false', choices=['true', 'false'],
            description='also start example_controller'),
        Node(
            package=PACKAGE,
            executable='sim_node',
            name='sim_node',
            namespace=namespace,
            parameters=[params_file,
                        {'use_sim_time': use_sim_time, 'publish_clock': use_sim_time}],
            output='screen'),
        Node(
            package=PACKAGE,
            executable='example_controller',
            name='example_controller',
            namespace=namespace,
            parameters=[{'use_sim_time': use_sim_time}],
            output='screen',
            condition=IfCondition(with_controller)),
    ])
