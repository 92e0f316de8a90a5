"""ROS messages ↔ numpy, for rclpy classes and rosbags dataclasses alike (same field names).

Readers are duck-typed; builders take a :class:`MessageTypes` (``rclpy_types()`` or
``rosbags_types()``) and give every field. Nothing here imports ROS at import time. Every malformed
input raises :class:`MessageError`. Poses are camera-to-map ``(R_wc, c)`` (hac_ros'
docs/interface.md, "Conventions").
"""
from msg_adapters.camera_info import camera_info_to_intrinsics, intrinsics_to_camera_info
from msg_adapters.cdr import RawCloud, cloud_points, parse_cloud_cdr
from msg_adapters.errors import MessageError
from msg_adapters.joints import JOINTS_PER_PERSON, joints_to_pose_array, pose_array_to_joints
from msg_adapters.pointcloud import cloud_to_xyz, xyz_from_buffer, xyz_to_cloud
from msg_adapters.poses import (
                                matrix_to_quat,
                                pose_msg_to_rt,
                                pose_to_rt,
                                quat_to_matrix,
                                rt_to_odometry,
                                rt_to_pose,
                                rt_to_pose_stamped,
                                rt_to_pose_with_covariance_stamped,
                                rt_to_transform_stamped,
                                transform_to_rt,
)
from msg_adapters.stamps import make_header, ns_to_stamp, stamp_to_ns
from msg_adapters.types import MessageTypes, rclpy_types, rosbags_types

__all__ = [
    'JOINTS_PER_PERSON', 'MessageError', 'MessageTypes', 'RawCloud', 'camera_info_to_intrinsics',
    'cloud_points', 'cloud_to_xyz', 'intrinsics_to_camera_info', 'joints_to_pose_array',
    'make_header', 'matrix_to_quat', 'ns_to_stamp', 'parse_cloud_cdr', 'pose_array_to_joints',
    'pose_msg_to_rt', 'pose_to_rt', 'quat_to_matrix', 'rclpy_types', 'rosbags_types',
    'rt_to_odometry', 'rt_to_pose', 'rt_to_pose_stamped', 'rt_to_pose_with_covariance_stamped',
    'rt_to_transform_stamped',
    'stamp_to_ns', 'transform_to_rt', 'xyz_from_buffer', 'xyz_to_cloud',
]
