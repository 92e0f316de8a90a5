"""What a caller changes in a running hac_node: its services and its parameters.

Mixed into :class:`hac_ros.ros.node.HacShell`, whose state it works on (every access to the
calibrator holds the shell's lock):

- ``~/reset`` (Trigger) and ``~/freeze`` (SetBool): requests the calibrator takes at the next SLAM
  pose (docs/node.md, "Services");
- a runtime parameter change (``ros2 param set``, ``set_parameters_atomically``): validated as a
  whole first, then it re-subscribes, takes effect at once or rebuilds the estimator
  (:func:`hac_ros.ros.parameters.judge_change`; docs/node.md, "Parameters at runtime").
"""
from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.parameter import Parameter

from hac_ros.bridge.messages import OutputMessages
from hac_ros.core.basics.errors import ParameterError
from hac_ros.core.basics.outputs import Output
from hac_ros.core.basics.printable import printable
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.rules.params import HacParams, PoseSource
from hac_ros.ros.intake import Inbox
from hac_ros.ros.map_intake import MapIntake
from hac_ros.ros.parameters import judge_change, our_values
from hac_ros.ros.story import Story
from hac_ros.ros.tf_broadcast import TfSender
from hac_ros.ros.tf_input import transform_listener_class

if TYPE_CHECKING:  # mixed into an rclpy Node through HacShell
    from rclpy.node import Node as _NodeMixinBase
else:
    _NodeMixinBase = object


class RuntimeControl(_NodeMixinBase):
    """The services and runtime parameters of :class:`hac_ros.ros.node.HacShell` (module
    docstring); the attributes below are the shell's."""

    params: HacParams
    calibrator: Calibrator | None
    active: bool
    lock: threading.RLock
    outputs: OutputMessages
    story: Story
    maps: MapIntake
    notices: Counter[str]
    tf: TfSender | None
    _inbox: Inbox
    _camera_info: tuple[Any, int, int] | None

    @property
    def core(self) -> Calibrator:
        """The calibrator; callbacks run only between configure and cleanup, when it exists."""
        if self.calibrator is None:
            raise RuntimeError('hac_node is not configured')
        return self.calibrator

    def _subscribe(self, kind: str) -> None:
        raise NotImplementedError  # the shell's

    def _emit(self, outputs: Sequence[Output]) -> None:
        raise NotImplementedError  # the shell's

    # ------------------------------------------------------------------ services
    def _on_reset(self, request: Any, response: Any) -> Any:
        """``~/reset`` (Trigger): a new segment at the next SLAM pose (docs/node.md, Services)."""
        with self.lock:
            self.core.request_reset()
        response.success = True
        response.message = 'a new segment starts at the next SLAM pose (map and ground normal kept)'
        return response

    def _on_freeze(self, request: Any, response: Any) -> Any:
        """``~/freeze`` (SetBool): hold the scale (true) or resume with a fresh window (false)."""
        with self.lock:
            self.core.request_freeze(bool(request.data))
        response.success = True
        response.message = ('the scale is held from the next SLAM pose' if request.data else
                            'the scale is released at the next SLAM pose: a fresh window converges')
        return response

    # ------------------------------------------------------------------ parameters
    def _validate_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """All or nothing: the whole set is checked by HacParams.replace before anything changes
        (before configure, against the defaults: configure reads and checks them all)."""
        try:
            change = judge_change(self.params if self.calibrator is not None else HacParams(),
                                  our_values(parameters))
            if change.params.pose_source == PoseSource.TF:
                transform_listener_class()  # ParameterError naming what to install
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: list[Parameter]) -> None:
        """A runtime change (ros.parameters.judge_change: re-subscribes, takes effect at once or
        rebuilds the estimator). Unconfigured, nothing: configure reads the parameters; inactive,
        the new subscriptions and TF wait for activate."""
        values = our_values(parameters)
        if not values or self.calibrator is None:
            return
        with self.lock:
            change = judge_change(self.params, values)  # validated in _validate_parameters
            if not change.changed:
                return
            self.params = self.outputs.params = change.params
            self._inbox.backlog_max = change.params.joints_backlog_max
            self._inbox.coalesce_s = change.params.pose_coalesce_s
            if self.active:
                for kind in change.resubscribe:
                    self._subscribe(kind)
                if change.tf:
                    self._update_tf()
            if change.estimator:
                self._rebuild_calibrator(change.estimator)
            else:
                self.core.params = change.params  # fields the calibrator does not read
            self.get_logger().info('parameters changed: ' + printable(', '.join(
                f'{k}={getattr(change.params, k)!r}' for k in sorted(change.changed))))

    def _rebuild_calibrator(self, changed: list[str]) -> None:
        """Estimator parameters: a new calibrator, given the current map and CameraInfo.

        The map handed over is the old calibrator's map in use (in ``accumulate`` mode, everything
        accumulated), else the last one the node handed to it. When the thinning
        (``index_max_points``) changed, the last cloud received is indexed again as well.
        """
        old = self.core
        self.calibrator = Calibrator(self.params)
        if self._camera_info is not None:
            self._emit(self.calibrator.add_camera_info(*self._camera_info))
        current_map = old.map if old.map is not None else self.maps.last_index
        if current_map is not None:
            self._emit(self.calibrator.add_map_index(current_map))
        if 'index_max_points' in changed and self.maps.last_cloud is not None:
            self.maps.submit(self.maps.last_cloud, self.params.cloud_mode)
        self.notices.clear()
        self.story.reset()
        self.get_logger().warning(
            f'estimator parameter(s) {", ".join(changed)} changed: the estimator was rebuilt and '
            f'its estimate restarts (metric outputs resume after {self.params.min_samples} '
            'samples)')

    def _update_tf(self) -> None:
        """TF when publish_tf or publish_odom_tf is set and tf2_ros is importable (a warning
        otherwise); hac_ros.ros.tf_broadcast keeps tf2_ros out of everything else."""
        from hac_ros.ros.tf_broadcast import make_tf_sender

        self.tf = make_tf_sender(self, self.params)
