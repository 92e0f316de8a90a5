"""SLAM poses and HMR joints from their CDR bytes into the calibrator, for the node and the replay.

Both shells hand the serialized message (a raw subscription's bytes, or a recording's) to these
functions, so that the same message gives the same calibrator call online and replayed. A message
that does not decode is a counted rejection with its kind's reason (stamp −1: it was not read).
"""
from __future__ import annotations

from hac_ros.core.calibrator import Calibrator
from hac_ros.core.outputs import Output
from msg_adapters import MessageError, RawPose, parse_joints_cdr, parse_pose_cdr


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
