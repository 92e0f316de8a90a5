"""Optional TF broadcast of ``metric_frame`` → camera (or ``base_frame``) for planners (``publish_tf``).

Kept apart from the node because ``tf2_ros`` is not always installed (it is not in the rclpy
wheels): without it the node logs one warning and carries on; ``/hac/odometry`` holds the same
pose. The transform is exactly the published odometry's pose: rotation child → metric_frame and the
child's origin in metres in metric_frame, stamped with the SLAM pose's stamp.
"""
from __future__ import annotations

from typing import Any

from hac_ros.core.outputs import OdometryOut
from msg_adapters import rclpy_types, rt_to_transform_stamped


class TfBroadcast:
    """Sends one TransformStamped per OdometryOut on /tf (tf2_ros.TransformBroadcaster)."""

    def __init__(self, node: Any, broadcaster: Any) -> None:
        self.node = node
        self.broadcaster = broadcaster

    def send(self, odometry: OdometryOut, metric_frame: str) -> None:
        msg = rt_to_transform_stamped(odometry.rotation_metric, odometry.position_metric,
                                      odometry.stamp_ns, metric_frame, odometry.child_frame_id,
                                      rclpy_types())
        self.broadcaster.sendTransform(msg)


def make_tf_broadcast(node: Any) -> TfBroadcast | None:
    """A broadcaster for ``node``, or None (after a warning) when tf2_ros cannot be imported."""
    try:
        from tf2_ros import TransformBroadcaster
    except ImportError as exc:
        node.get_logger().warning(
            f'publish_tf is true but tf2_ros is not available ({exc}): no TF is broadcast. '
            'Install ROS 2 tf2_ros (apt: ros-jazzy-tf2-ros) or read the metric pose from '
            '/hac/odometry.')
        return None
    return TfBroadcast(node, TransformBroadcaster(node))
