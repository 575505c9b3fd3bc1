# Copyright 2026 epp_ros developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
Launch the UWB driver and the posture estimator of one pump, optionally with RViz.

    ros2 launch epp_ros epp.launch.py [config:=/path/pump.yaml] [namespace:=pump7] [rviz:=true]
                                      [use_sim_time:=true]

robot_state_publisher, where installed, turns the estimator's joint_states into /tf with
the pump's URDF (epp_urdf of the same config), for RViz's RobotModel and TF displays.
"""
import os

from ament_index_python.packages import (get_package_prefix, get_package_share_directory,
                                         PackageNotFoundError)
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, LogInfo
from launch.conditions import IfCondition
from launch.substitutions import Command, LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def installed(package):
    try:
        get_package_share_directory(package)
    except PackageNotFoundError:
        return False
    return True


def robot_state_publisher(config, namespace, clock):
    """/tf of the boom from joint_states, with the URDF epp_urdf makes of ``config``."""
    if not installed('robot_state_publisher'):
        return LogInfo(msg='robot_state_publisher is not installed: no /tf of the boom '
                           '(joint_states and robot_description are still published)')
    epp_urdf = os.path.join(get_package_prefix('epp_ros'), 'lib', 'epp_ros', 'epp_urdf')
    description = ParameterValue(Command([epp_urdf, ' ', config]), value_type=str)
    return Node(package='robot_state_publisher', executable='robot_state_publisher',
                name='robot_state_publisher', namespace=namespace, output='screen',
                parameters=[{'robot_description': description}, clock])


def rviz(share, namespace, clock):
    """rviz2 with the boom view, in the pump's namespace (its topics are relative)."""
    wanted = IfCondition(LaunchConfiguration('rviz'))
    if not installed('rviz2'):     # the nodes still start; say why no window opens
        return LogInfo(msg='rviz:=true, but rviz2 is not installed', condition=wanted)
    return Node(package='rviz2', executable='rviz2', name='rviz2', namespace=namespace,
                arguments=['-d', os.path.join(share, 'rviz', 'epp.rviz')], condition=wanted,
                parameters=[clock])


def generate_launch_description():
    share = get_package_share_directory('epp_ros')
    config = LaunchConfiguration('config')
    namespace = LaunchConfiguration('namespace')
    # Every node on /clock or on wall time alike (a bag played with --clock).
    clock = {'use_sim_time': LaunchConfiguration('use_sim_time')}
    return LaunchDescription([
        DeclareLaunchArgument('config', default_value=os.path.join(share, 'config',
                                                                   'pump.yaml'),
                              description='Pump description (a ROS parameters file).'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='Namespace of this pump, e.g. pump7.'),
        DeclareLaunchArgument('rviz', default_value='false',
                              description='Also start rviz2 with the boom view.'),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='Run every node on /clock (epp_bag play --clock).'),
        Node(package='epp_ros', executable='uwb_driver', name='uwb_driver',
             namespace=namespace, parameters=[config, clock], output='screen'),
        Node(package='epp_ros', executable='posture_estimator', name='posture_estimator',
             namespace=namespace, parameters=[config, clock], output='screen'),
        robot_state_publisher(config, namespace, clock),
        rviz(share, namespace, clock),
    ])
