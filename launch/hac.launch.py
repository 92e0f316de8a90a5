"""Launch hac_node with the installed parameters file, optionally with RViz.

    ros2 launch hac_ros hac.launch.py
    ros2 launch hac_ros hac.launch.py params_file:=/path/to/my.yaml rviz:=true
    ros2 launch hac_ros hac.launch.py pose_topic:=/orb_slam3/camera_pose joints_topic:=/hmr/joints
    ros2 launch hac_ros hac.launch.py dds_profile:=true   # Fast DDS profile for 1M-point maps

``dds_profile:=true`` loads config/fastdds_large_data.xml (Fast DDS only) into the processes this
launch file starts; the process publishing the map needs it too (see the file's comment).

Needs a full ROS 2 install (launch, launch_ros, rviz2): never imported by the tests.
"""
from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
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
        DeclareLaunchArgument('dds_profile', default_value='false',
                              description='load config/fastdds_large_data.xml (Fast DDS: large maps '
                                          'beside best-effort joints)'),
    ]
    profile = str(share / 'config' / 'fastdds_large_data.xml')
    # Fast DDS 2.x reads the first name, 3.x the second (as hac_ros.node.DDS_PROFILE_VARIABLES)
    dds_profile = [
        SetEnvironmentVariable(name, profile, condition=IfCondition(LaunchConfiguration('dds_profile')))
        for name in ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')]
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
    return LaunchDescription([*arguments, *dds_profile, node, rviz])
