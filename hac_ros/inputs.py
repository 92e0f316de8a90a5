"""Input messages into the calibrator, for the node and the replay.

SLAM poses and HMR joints come as CDR bytes (a raw subscription's, or a recording's), CameraInfo as
a message object (rclpy's or rosbags'), so that the same message gives the same calibrator call
online and replayed. A message that does not decode is a counted rejection with its kind's reason
(stamp −1 when its stamp could not be read).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from hac_ros.core.calibrator import Calibrator
from hac_ros.core.outputs import Output
from msg_adapters import (MessageError, RawPose, camera_info_to_intrinsics, parse_joints_cdr,
                          parse_pose_cdr, stamp_to_ns)


def add_pose_cdr(calibrator: Calibrator, data: bytes | memoryview, msgtype: str
                 ) -> tuple[list[Output], RawPose | None]:
    """A serialized SLAM pose of ROS type ``msgtype`` → the calibrator's outputs, and the pose
    read (None when it did not decode: rejected as ``pose_nonfinite``)."""
    try:
        pose = parse_pose_cdr(data, msgtype)
    except MessageError:
        return calibrator.reject('pose_nonfinite', -1), None
    return calibrator.add_pose(pose.stamp_ns, pose.R_wc, pose.c_map, pose.frame_id,
                               pose.child_frame_id), pose


def add_joints_cdr(calibrator: Calibrator, data: bytes | memoryview) -> list[Output]:
    """A serialized PoseArray of HMR joints → the calibrator's outputs (rejected as
    ``joints_malformed`` when it does not decode)."""
    try:
        stamp, frame_id, joints_cam = parse_joints_cdr(data)
    except MessageError:
        return calibrator.reject('joints_malformed', -1)
    return calibrator.add_joints(stamp, joints_cam, frame_id)


def add_camera_info_msg(calibrator: Calibrator, msg: Any
                        ) -> tuple[list[Output], tuple[np.ndarray, int, int] | None]:
    """A sensor_msgs/CameraInfo → the calibrator's outputs, and the intrinsics read (K (3, 3)
    pixels, width, height) or None when they are invalid (rejected as ``camera_info_invalid``)."""
    stamp = -1
    try:
        stamp = stamp_to_ns(msg.header.stamp)
        K, width, height = camera_info_to_intrinsics(msg)
    except MessageError:
        return calibrator.reject('camera_info_invalid', stamp), None
    return calibrator.add_camera_info(K, width, height, msg.header.frame_id), (K, width, height)
