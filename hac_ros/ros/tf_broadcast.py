"""Optional TF (docs/interface.md, "Topics"): ``publish_tf`` and ``publish_odom_tf``, when tf2_ros
is importable.

Kept apart from the node because ``tf2_ros`` is not in the rclpy wheels: without it the node logs
one warning and carries on (``/hac/pose`` and ``/hac/odometry`` hold the same poses).

- ``publish_tf``: ``metric_frame`` → ``odom_frame``, the correction that composes
  ``/hac/odometry`` into ``/hac/pose``: T_metric_odom = T_metric_child · T_odom_child⁻¹ from the
  pose and the odometry of the same stamp (REP-105's map → odom). Leave it off when an EKF such
  as robot_localization publishes map → odom from these outputs.
- ``publish_odom_tf``: ``odom_frame`` → the child frame, the odometry's own pose.

Stamps are the SLAM pose's header stamps. The replay writes neither.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from hac_ros.core.basics.outputs import OdometryOut, PoseOut
from hac_ros.core.rules.params import HacParams
from msg_adapters import rclpy_types, rt_to_transform_stamped


def correction(R_metric: np.ndarray, p_metric: np.ndarray, R_odom: np.ndarray,
               p_odom: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """T_metric_odom (rotation (3, 3) odom to metric, translation (3,) metres) from one frame's
    pose in both: R_metric, p_metric in metric_frame; R_odom, p_odom in odom_frame."""
    R = np.asarray(R_metric) @ np.asarray(R_odom).T
    return R, np.asarray(p_metric) - R @ np.asarray(p_odom)


class TfSender:
    """Turns OdometryOut and PoseOut into TransformStamped for a broadcaster with
    ``sendTransform(msg)`` (tf2_ros.TransformBroadcaster, or a stand-in in the tests)."""

    def __init__(self, broadcaster: Any, params: HacParams) -> None:
        self.broadcaster = broadcaster
        self.params = params
        self._odometry: OdometryOut | None = None  # the last one: the pose of its stamp follows

    def send(self, output: OdometryOut | PoseOut) -> None:
        p = self.params
        if isinstance(output, OdometryOut):
            self._odometry = output
            if p.publish_odom_tf:
                self._send(output.rotation_metric, output.position_metric, output.stamp_ns,
                           p.odom_frame, output.child_frame_id)
            return
        odometry = self._odometry
        if p.publish_tf and odometry is not None and odometry.stamp_ns == output.stamp_ns:
            R, t = correction(output.rotation_metric, output.position_metric,
                              odometry.rotation_metric, odometry.position_metric)
            self._send(R, t, output.stamp_ns, p.metric_frame, p.odom_frame)

    def _send(self, R: np.ndarray, t: np.ndarray, stamp_ns: int, parent: str, child: str) -> None:
        self.broadcaster.sendTransform(
            rt_to_transform_stamped(R, t, stamp_ns, parent, child, rclpy_types()))


def make_tf_sender(node: Any, params: HacParams) -> TfSender | None:
    """A sender for ``node`` when publish_tf or publish_odom_tf is set, else None; None after a
    warning when tf2_ros cannot be imported."""
    if not (params.publish_tf or params.publish_odom_tf):
        return None
    try:
        from tf2_ros import TransformBroadcaster
    except ImportError as exc:
        wanted = ' and '.join(name for name in ('publish_tf', 'publish_odom_tf')
                              if getattr(params, name))
        node.get_logger().warning(
            f'{wanted} set but tf2_ros is not available ({exc}): no TF is broadcast. Install '
            'ROS 2 tf2_ros (apt: ros-jazzy-tf2-ros), or use /hac/pose and /hac/odometry.')
        return None
    return TfSender(TransformBroadcaster(node), params)
