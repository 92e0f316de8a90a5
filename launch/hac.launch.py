"""Launch hac_node with the installed parameters file, optionally with RViz.

    ros2 launch hac_ros hac.launch.py
    ros2 launch hac_ros hac.launch.py params_file:=/path/to/my.yaml rviz:=true
    ros2 launch hac_ros hac.launch.py pose_topic:=/orb_slam3/camera_pose joints_topic:=/hmr/joints
    ros2 launch hac_ros hac.launch.py namespace:=robot1   # robot1/slam/pose -> robot1/hac/pose
    ros2 launch hac_ros hac.launch.py lifecycle:=true     # hac_lifecycle_node (nav2 bring-up)
    ros2 launch hac_ros hac.launch.py dds_profile:=true   # Fast DDS profile for 1M-point maps

Topic defaults are relative (docs/interface.md): in ``namespace:=robot1`` the node reads
``/robot1/slam/pose`` and writes ``/robot1/hac/...``; ``/diagnostics`` stays absolute.
``lifecycle:=true`` starts the managed node unconfigured: a lifecycle manager (nav2's, with
``bond_timeout: 0.0``) or ``ros2 lifecycle set /robot1/hac_node configure`` / ``activate`` brings it
up.

``dds_profile:=true`` loads config/fastdds_large_data.xml (Fast DDS only) into the processes this
launch file starts; the process publishing the map needs it too (see the file's comment).

Needs a full ROS 2 install (launch, launch_ros, rviz2): never imported by the tests.
"""
from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription

PACKAGE = 'hac_ros'


def generate_launch_description() -> LaunchDescription:
    share = Path(get_package_share_directory(PACKAGE))
    arguments = [
        DeclareLaunchArgument('params_file', default_value=str(share / 'config' / 'hac.yaml'),
                              description='hac_node parameters (hac_node: ros__parameters: ...)'),
        DeclareLaunchArgument('rviz', default_value='false', description='start RViz as well'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of the node and of its relative topics'),
        DeclareLaunchArgument('lifecycle', default_value='false',
                              description='start hac_lifecycle_node (managed) instead of hac_node'),
        DeclareLaunchArgument('pose_topic', default_value='slam/pose',
                              description='SLAM camera pose (relative: inside the namespace)'),
        DeclareLaunchArgument('cloud_topic', default_value='slam/cloud',
                              description='SLAM map cloud'),
        DeclareLaunchArgument('joints_topic', default_value='hmr/joints',
                              description='HMR joints (PoseArray, camera optical frame)'),
        DeclareLaunchArgument('log_level', default_value='info', description='ROS log level'),
        DeclareLaunchArgument('dds_profile', default_value='false',
                              description='load config/fastdds_large_data.xml (Fast DDS: large '
                                          'maps beside best-effort joints)'),
    ]
    profile = str(share / 'config' / 'fastdds_large_data.xml')
    # Fast DDS 2.x reads the first name, 3.x the second (as hac_ros.ros.node.DDS_PROFILE_VARIABLES)
    dds_profile = [
        SetEnvironmentVariable(name, profile,
                               condition=IfCondition(LaunchConfiguration('dds_profile')))
        for name in ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')]
    common = dict(
        package=PACKAGE, name='hac_node', namespace=LaunchConfiguration('namespace'),
        output='screen',
        parameters=[LaunchConfiguration('params_file'), {
            'pose_topic': LaunchConfiguration('pose_topic'),
            'cloud_topic': LaunchConfiguration('cloud_topic'),
            'joints_topic': LaunchConfiguration('joints_topic'),
        }],
        arguments=['--ros-args', '--log-level', LaunchConfiguration('log_level')],
    )
    lifecycle = LaunchConfiguration('lifecycle')
    node = Node(executable='hac_node', condition=UnlessCondition(lifecycle), **common)
    managed = Node(executable='hac_lifecycle_node', condition=IfCondition(lifecycle), **common)
    rviz = Node(
        package='rviz2', executable='rviz2', name='hac_rviz', output='screen',
        namespace=LaunchConfiguration('namespace'),
        arguments=['-d', str(share / 'rviz' / 'hac.rviz')],
        condition=IfCondition(LaunchConfiguration('rviz')),
    )
    return LaunchDescription([*arguments, *dds_profile, node, managed, rviz])
