"""Input messages into the calibrator, for the node and the replay.

SLAM poses and HMR joints come as CDR bytes (a raw subscription's, or a recording's), CameraInfo as
a message object (rclpy's or rosbags'), so that the same message gives the same calibrator call
online and replayed. Map clouds come as CDR bytes too: the shell reads the header
(``parse_cloud_cdr``) where the message arrives and :func:`index_cloud` decodes and indexes the
points on a worker thread. A message that does not decode is a counted rejection with its kind's
reason (stamp −1 when its stamp could not be read).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from hac_ros.core.calibrator import Calibrator
from hac_ros.core.outputs import Output
from hac_ros.core.reference import MapIndex
from msg_adapters import (MessageError, RawPose, camera_info_to_intrinsics, parse_joints_cdr,
                          parse_pose_cdr, stamp_to_ns)
from msg_adapters.cdr import RawCloud, cloud_points

# Calibrator.build_index: (stamp_ns, points_map (N, 3) SLAM units, frame_id) -> MapIndex
IndexBuilder = Callable[[int, Any, str], MapIndex]


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


@dataclass
class MapBuilt:
    """A map index ready for the calibrator, or the reason its cloud could not be decoded
    (index None: the shell rejects it as ``cloud_malformed`` at ``stamp_ns``, −1 if unread)."""

    stamp_ns: int
    index: MapIndex | None
    error: str = ''
    build_s: float = 0.0  # wall seconds spent decoding and indexing


def index_cloud(cloud: RawCloud, build_index: IndexBuilder, previous: MapIndex | None = None,
                normal: np.ndarray | None = None) -> MapBuilt:
    """Decode one cloud's points and index them with the calibrator's own (thread-safe)
    ``build_index``, then compute ahead what the first frame on the map will likely ask
    (:meth:`MapIndex.prepare` with ``previous``, the map in use when the cloud arrived, and
    ``normal``, (3,) the ground normal then: results unchanged, only computed earlier).

    For a worker thread: touches no calibrator state. Points: (N, 3) float64, SLAM units, the
    cloud's (map) frame.
    """
    start = time.perf_counter()
    try:
        points_map = cloud_points(cloud)
    except MessageError as exc:
        return MapBuilt(cloud.stamp_ns, None, str(exc), time.perf_counter() - start)
    index = build_index(cloud.stamp_ns, points_map, cloud.frame_id)
    index.prepare(previous, normal)
    return MapBuilt(cloud.stamp_ns, index, '', time.perf_counter() - start)
