"""Launch the UWB driver and the posture estimator of one pump.

    ros2 launch epp_ros epp.launch.py [config:=/path/pump.yaml] [namespace:=pump7]
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    default_config = os.path.join(get_package_share_directory('epp_ros'), 'config',
                                  'pump.yaml')
    config = LaunchConfiguration('config')
    namespace = LaunchConfiguration('namespace')
    return LaunchDescription([
        DeclareLaunchArgument('config', default_value=default_config,
                              description='Pump description (a ROS parameters file).'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='Namespace of this pump, e.g. pump7.'),
        Node(package='epp_ros', executable='uwb_driver', name='uwb_driver',
             namespace=namespace, parameters=[config], output='screen'),
        Node(package='epp_ros', executable='posture_estimator', name='posture_estimator',
             namespace=namespace, parameters=[config], output='screen'),
    ])
