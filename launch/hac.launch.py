"""Launch hac_node with the installed parameters file, optionally with RViz.

    ros2 launch hac_ros hac.launch.py
    ros2 launch hac_ros hac.launch.py params_file:=/path/to/my.yaml rviz:=true
    ros2 launch hac_ros hac.launch.py pose_topic:=/orb_slam3/camera_pose joints_topic:=/hmr/joints

Needs a full ROS 2 install (launch, launch_ros, rviz2): never imported by the tests.
"""
from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = 'hac_ros'


def generate_launch_description() -> LaunchDescription:
    share = Path(get_package_share_directory(PACKAGE))
    arguments = [
        DeclareLaunchArgument('params_file', default_value=str(share / 'config' / 'hac.yaml'),
                              description='hac_node parameters (hac_node: ros__parameters: ...)'),
        DeclareLaunchArgument('rviz', default_value='false', description='start RViz as well'),
        DeclareLaunchArgument('pose_topic', default_value='/slam/pose',
                              description='SLAM camera pose (remapped onto the node\'s input)'),
        DeclareLaunchArgument('cloud_topic', default_value='/slam/cloud',
                              description='SLAM map cloud'),
        DeclareLaunchArgument('joints_topic', default_value='/hmr/joints',
                              description='HMR joints (PoseArray, camera optical frame)'),
        DeclareLaunchArgument('log_level', default_value='info', description='ROS log level'),
    ]
    node = Node(
        package=PACKAGE, executable='hac_node', name='hac_node', output='screen',
        parameters=[LaunchConfiguration('params_file'), {
            'pose_topic': LaunchConfiguration('pose_topic'),
            'cloud_topic': LaunchConfiguration('cloud_topic'),
            'joints_topic': LaunchConfiguration('joints_topic'),
        }],
        arguments=['--ros-args', '--log-level', LaunchConfiguration('log_level')],
    )
    rviz = Node(
        package='rviz2', executable='rviz2', name='hac_rviz', output='screen',
        arguments=['-d', str(share / 'rviz' / 'hac.rviz')],
        condition=IfCondition(LaunchConfiguration('rviz')),
    )
    return LaunchDescription([*arguments, node, rviz])
