"""A stand-in for tf2_ros (not installable from the wheels) for the tests. Put this directory
first on PYTHONPATH.

tf2_msgs is not in the wheels either, so the stand-ins carry single
geometry_msgs/TransformStamped messages where the real tf2_ros carries tf2_msgs/TFMessage:

- TransformBroadcaster publishes each TransformStamped on ``/tf_standin`` (the real one wraps
  them in a TFMessage on ``/tf``);
- TransformListener subscribes to ``/tf_standin`` and ``/tf_static_standin`` (transient local, as
  ``/tf_static``) and hands each transform to its buffer's ``set_transform`` /
  ``set_transform_static``, exactly as the real listener does with each transform of a TFMessage.
"""
from __future__ import annotations

from typing import Any

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

AUTHORITY = 'default_authority'


class TransformBroadcaster:
    def __init__(self, node: Any, qos: Any = None) -> None:
        from geometry_msgs.msg import TransformStamped

        self._publisher = node.create_publisher(
            TransformStamped, '/tf_standin',
            QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))

    def sendTransform(self, transform: Any) -> None:  # tf2_ros' name
        for t in transform if isinstance(transform, list) else [transform]:
            self._publisher.publish(t)


class TransformListener:
    def __init__(self, buffer: Any, node: Any, *, spin_thread: bool = False, qos: Any = None,
                 static_qos: Any = None) -> None:
        from geometry_msgs.msg import TransformStamped

        self.buffer, self.node = buffer, node
        self.tf_sub = node.create_subscription(
            TransformStamped, '/tf_standin', self.callback,
            QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        self.tf_static_sub = node.create_subscription(
            TransformStamped, '/tf_static_standin', self.static_callback,
            QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL))

    def callback(self, transform: Any) -> None:
        self.buffer.set_transform(transform, AUTHORITY)

    def static_callback(self, transform: Any) -> None:
        self.buffer.set_transform_static(transform, AUTHORITY)

    def unregister(self) -> None:
        self.node.destroy_subscription(self.tf_sub)
        self.node.destroy_subscription(self.tf_static_sub)
