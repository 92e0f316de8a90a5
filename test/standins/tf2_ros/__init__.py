"""A stand-in for tf2_ros (not installable from the wheels) for the tests: its
TransformBroadcaster publishes each geometry_msgs/TransformStamped on ``/tf_standin`` (the real one
wraps them in a tf2_msgs/TFMessage on ``/tf``). Put this directory first on PYTHONPATH."""
from __future__ import annotations

from typing import Any

from rclpy.qos import QoSProfile, ReliabilityPolicy


class TransformBroadcaster:
    def __init__(self, node: Any, qos: Any = None) -> None:
        from geometry_msgs.msg import TransformStamped

        self._publisher = node.create_publisher(
            TransformStamped, '/tf_standin',
            QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))

    def sendTransform(self, transform: Any) -> None:
        for t in transform if isinstance(transform, list) else [transform]:
            self._publisher.publish(t)
