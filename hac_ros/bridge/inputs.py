"""Input messages into the calibrator, the same way for the node and the replay.

SLAM poses (or, with ``pose_source: tf``, the transforms of /tf and /tf_static), HMR joints and
CameraInfo come as message objects (rclpy's in the node, rosbags' in the replay: the adapters read
both alike), so that the same message gives the same calibrator call
online and replayed; ``None`` stands for a message whose bytes did not deserialize. Map clouds come
as CDR bytes: the shell reads the header
(``parse_cloud_cdr``) where the message arrives and a :class:`MapBuilder` decodes and indexes the
points on a worker thread; the shell hands each :class:`MapBuilt` to the calibrator on its own
thread, in order. A message that does not decode is a counted rejection with its kind's reason
(stamp −1 when its stamp could not be read).
"""
from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from hac_ros.core.basics.outputs import Output
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.geometry.reference import MapIndex
from hac_ros.core.stream.tf_tree import TfPoses
from msg_adapters import (
    MessageError,
    RawCloud,
    camera_info_to_intrinsics,
    cloud_points,
    pose_array_to_joints,
    pose_msg_to_rt,
    stamp_to_ns,
    transform_to_rt,
)


@dataclass
class TfTaken:
    """What TF messages gave (``pose_source: tf``): the calibrator's outputs, the poses taken
    (stamp ns, R (3, 3) pose frame to map, c (3,) SLAM units, as read, before
    ``pose_to_optical``) and the errors (a chain through a second dynamic transform)."""

    outputs: list[Output]
    poses: list[tuple[int, np.ndarray, np.ndarray]]
    errors: list[str]


def add_tf_msg(calibrator: Calibrator, tf: TfPoses, msg: Any, static: bool,
               taken: TfTaken | None = None) -> TfTaken:
    """A ``tf2_msgs/TFMessage`` of /tf (or /tf_static: ``static``), or None when its bytes did not
    deserialize, through ``tf`` (:mod:`hac_ros.core.stream.tf_tree`) into the calibrator: each
    message of the SLAM's own transform is a pose at its stamp; rejections are counted by reason."""
    taken = taken or TfTaken([], [], [])
    if msg is None:
        taken.outputs += calibrator.reject('tf_invalid', -1)
        return taken
    for transform in msg.transforms:
        add_transform(calibrator, tf, transform, static, taken)
    return taken


def add_transform(calibrator: Calibrator, tf: TfPoses, transform: Any, static: bool,
                  taken: TfTaken | None = None) -> TfTaken:
    """One ``geometry_msgs/TransformStamped`` (what tf2_ros' listener hands a buffer), as
    :func:`add_tf_msg`."""
    taken = taken or TfTaken([], [], [])
    stamp = -1
    try:
        stamp = stamp_to_ns(transform.header.stamp)
        R, t = transform_to_rt(transform)
        parent, child = str(transform.header.frame_id), str(transform.child_frame_id)
    except (MessageError, AttributeError):
        taken.outputs += calibrator.reject('tf_invalid', stamp)
        return taken
    update = tf.add(parent, child, stamp, R, t, static)
    if update.rejected:
        taken.outputs += calibrator.reject(update.rejected, stamp)
    if update.error:
        taken.errors.append(update.error)
    if update.pose is not None:
        stamp, R_map_pose, c = update.pose
        taken.poses.append(update.pose)
        taken.outputs += calibrator.add_pose(stamp, R_map_pose, c, tf.map_frame, tf.pose_frame)
    return taken


# Calibrator.build_index: (stamp_ns, points_map (N, 3) SLAM units, frame_id) -> MapIndex
IndexBuilder = Callable[[int, Any, str], MapIndex]


def add_pose_msg(calibrator: Calibrator, msg: Any
                 ) -> tuple[list[Output], tuple[int, np.ndarray, np.ndarray] | None]:
    """A SLAM pose (PoseStamped or Odometry, or None) → the calibrator's outputs, and the pose read:
    (stamp ns, R_wc (3, 3) camera to map, c (3,) SLAM units, map frame), or None when it is not a
    valid pose (rejected as ``pose_nonfinite``)."""
    try:
        if msg is None:
            raise MessageError('the pose message did not deserialize')
        stamp = stamp_to_ns(msg.header.stamp)
        R_wc, c_map = pose_msg_to_rt(msg)
    except MessageError:
        return calibrator.reject('pose_nonfinite', -1), None
    outputs = calibrator.add_pose(stamp, R_wc, c_map, msg.header.frame_id,
                                  getattr(msg, 'child_frame_id', ''))
    return outputs, (stamp, R_wc, c_map)


def add_joints_msg(calibrator: Calibrator, msg: Any) -> list[Output]:
    """A PoseArray of HMR joints (or None) → the calibrator's outputs (rejected as
    ``joints_wrong_layout`` when it is not P blocks of the layout's K joints, ``joints_malformed``
    when it does not decode or has an invalid stamp)."""
    try:
        if msg is None:
            raise MessageError('the joints message did not deserialize')
        stamp = stamp_to_ns(msg.header.stamp)
        joints_cam = pose_array_to_joints(msg, 1)[:, 0]  # (P*K, 3): the calibrator checks K
    except MessageError:
        return calibrator.reject('joints_malformed', -1)
    return calibrator.add_joints(stamp, joints_cam, msg.header.frame_id)


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
    return calibrator.add_camera_info(K, width, height), (K, width, height)


@dataclass
class MapBuilt:
    """A map index ready for the calibrator, or the reason its cloud could not be decoded
    (index None: rejected as ``cloud_malformed`` at ``stamp_ns``, −1 if unread)."""

    stamp_ns: int
    index: MapIndex | None
    error: str = ''
    build_s: float = 0.0  # wall seconds spent decoding and indexing

    def hand_to(self, calibrator: Calibrator) -> list[Output]:
        """Give the map to ``calibrator`` (on the thread that owns it), or count the rejection."""
        if self.index is None:
            return calibrator.reject('cloud_malformed', self.stamp_ns)
        return calibrator.add_map_index(self.index)


def index_cloud(cloud: RawCloud, build_index: IndexBuilder) -> MapBuilt:
    """Decode one cloud's points ((N, 3) float64, SLAM units, the cloud's map frame) and index
    them with the calibrator's own ``build_index`` (thread-safe: it touches no calibrator state)."""
    start = time.perf_counter()
    try:
        points_map = cloud_points(cloud)
    except MessageError as exc:
        return MapBuilt(cloud.stamp_ns, None, str(exc), time.perf_counter() - start)
    index = build_index(cloud.stamp_ns, points_map, cloud.frame_id)
    return MapBuilt(cloud.stamp_ns, index, '', time.perf_counter() - start)


class MapBuilder:
    """Decodes and indexes map clouds on worker threads, off the thread that feeds the calibrator.

    :meth:`submit` returns the Future of a :class:`MapBuilt`; the shell hands the results to the
    calibrator on its own thread in the order it submitted them (the replay waits for each at its
    place in the recording, the node takes each as soon as it is done). scipy builds the k-d tree
    without the GIL, so a large map does not stall the frames.
    """

    def __init__(self, build_index: IndexBuilder, workers: int = 1) -> None:
        self._build_index = build_index
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix='hac_map')

    def submit(self, cloud: RawCloud) -> Future:
        return self._pool.submit(index_cloud, cloud, self._build_index)

    def close(self) -> None:
        """Drop the clouds not started, wait for the ones being built."""
        self._pool.shutdown(wait=True, cancel_futures=True)
