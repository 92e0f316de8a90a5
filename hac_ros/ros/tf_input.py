"""``pose_source: tf`` in the node: the SLAM pose from TF, when tf2_ros is importable.

Kept apart from the node, as the TF output (:mod:`hac_ros.ros.tf_broadcast`) is, because
``tf2_ros`` is not in the rclpy wheels. tf2_ros' own ``TransformListener`` subscribes to ``/tf``
and ``/tf_static`` (with their usual QoS: ``/tf_static`` transient local) and hands every
``TransformStamped`` to a buffer's ``set_transform`` / ``set_transform_static``; the buffer given
to it here is :class:`TfPoseInput`, which passes each transform (through the node's inbox, on its
processing thread, in arrival order with the other inputs) through the same
:func:`hac_ros.bridge.inputs.add_transform` and :class:`hac_ros.core.stream.tf_tree.TfPoses` as the
replay: a pose at the stamp of every message of the SLAM's own transform, rejections counted
in ``/diagnostics``. A chain through a second dynamic transform is logged as an error (once per
chain) and counted as ``tf_chain_dynamic``: the node never stops.

Without tf2_ros, ``pose_source: tf`` is refused with a :class:`ParameterError` naming what to
install (at start-up ``hac_node`` exits 2 with it; at runtime the parameter change is refused).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from hac_ros.bridge.inputs import add_transform
from hac_ros.core.basics.errors import ParameterError
from hac_ros.core.basics.outputs import Output
from hac_ros.core.basics.printable import printable
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.rules.params import HacParams
from hac_ros.core.stream.tf_tree import TfPoses

TF_MISSING = ('pose_source tf needs tf2_ros, which cannot be imported here ({reason}): install '
              'ROS 2 tf2_ros (apt: ros-jazzy-tf2-ros, then source /opt/ros/jazzy/setup.bash), '
              'or take the SLAM pose from a topic (pose_source topic, pose_topic)')


def transform_listener_class() -> Any:
    """tf2_ros' TransformListener; ParameterError naming what to install when it is missing."""
    try:
        from tf2_ros import TransformListener
    except ImportError as exc:
        raise ParameterError(TF_MISSING.format(reason=exc)) from exc
    return TransformListener


class TfPoseInput:
    """The buffer a tf2_ros TransformListener feeds (``set_transform``, ``set_transform_static``):
    every transform into the calibrator of the moment (``core()``), the outputs to ``emit``.

    node: the rclpy node the listener subscribes with; guard: wraps a callback so that an
    unexpected error is counted and logged, never raised into the executor (the node's own)."""

    def __init__(self, node: Any, params: HacParams, core: Callable[[], Calibrator],
                 emit: Callable[[list[Output]], None],
                 guard: Callable[[str, Callable[[Any], None]], Callable[[Any], None]]) -> None:
        listener = transform_listener_class()
        self.poses = TfPoses(params.slam_map_frame, params.slam_pose_frame)
        self._node, self._core, self._emit = node, core, emit
        self._errors: set[str] = set()
        self._dynamic = guard('tf', lambda t: self._take(t, False))
        self._static = guard('tf', lambda t: self._take(t, True))
        self.listener = listener(self, node, spin_thread=False)

    # the buffer interface tf2_ros' TransformListener calls
    def set_transform(self, transform: Any, authority: str) -> None:
        self._dynamic(transform)

    def set_transform_static(self, transform: Any, authority: str) -> None:
        self._static(transform)

    def _take(self, transform: Any, static: bool) -> None:
        taken = add_transform(self._core(), self.poses, transform, static)
        self._emit(taken.outputs)
        for error in taken.errors:
            if error not in self._errors:
                self._errors.add(error)
                self._node.get_logger().error(f'{printable(error)} (further ones are counted '
                                              'as rejected.tf_chain_dynamic)')

    def close(self) -> None:
        """Stop listening (the listener's subscriptions are destroyed)."""
        self.listener.unregister()
