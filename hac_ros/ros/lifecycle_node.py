"""``hac_lifecycle_node``: hac_node as a managed node (rclpy.lifecycle), for nav2-style bring-up.

The same shell as :class:`hac_ros.ros.node.HacNode` (:class:`hac_ros.ros.node.HacShell`), with
these transitions:

- configure: reads the parameters (an invalid one fails the transition with the reason logged);
- activate: subscribes, publishes, offers ``~/reset`` and ``~/freeze`` and TF;
- deactivate: stops all of those and keeps the state (the estimate, the map, the segments):
  activated again, it continues where it stopped;
- cleanup: drops the state (the next configure starts afresh); shutdown: cleans up from any state.

Parameters are declared at construction, so ``ros2 param set`` works in every state; a change
before configure is simply read by configure. ``autostart`` (default false, the convention of
nav2's lifecycle manager) configures and activates the node as it starts; the plain
``hac_node`` accepts the parameter and ignores it (it is always active), so one parameters file
serves both. nav2's ``lifecycle_manager`` expects a bond (bondcpp) from the nodes it manages,
which rclpy lacks: give the manager ``bond_timeout: 0.0`` (docs/node.md).

Run: ``ros2 run hac_ros hac_lifecycle_node --ros-args --params-file config/hac.yaml``, then
``hac lifecycle /hac_node configure`` and ``... activate`` (:mod:`hac_ros.ros.lifecycle_client`;
``ros2 lifecycle set`` does the same), or ``-p autostart:=true``.
"""
from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from hac_ros.core.basics.errors import ParameterError
from hac_ros.core.basics.printable import printable
from hac_ros.core.rules.params import NODE_NAME
from hac_ros.ros.arguments import run
from hac_ros.ros.node import HacShell

SUCCESS = TransitionCallbackReturn.SUCCESS
FAILURE = TransitionCallbackReturn.FAILURE


class HacLifecycleNode(HacShell, LifecycleNode):
    """The managed hac_node (module docstring). Its name is ``hac_node`` unless given another, so
    the same parameters file serves both."""

    PROGRAM = 'hac_lifecycle_node'
    SUMMARY = ('hac_node as a managed (rclpy.lifecycle) node: configure reads the parameters, '
               'activate\nsubscribes and publishes.')

    def __init__(self, node_name: str = NODE_NAME, params_files: Sequence[str] = (),
                 **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self._declare(params_files)
        if self.get_parameter('autostart').value:
            self._autostart()

    def _autostart(self) -> None:
        """``autostart``: configure, then activate, as a lifecycle manager would; a transition
        that fails leaves the node in the state it reached, said in the log."""
        if self.trigger_configure() != SUCCESS:
            self.get_logger().error('autostart: configure failed (the reason above): the node '
                                    'stays unconfigured')
            return
        if self.trigger_activate() != SUCCESS:
            self.get_logger().error('autostart: activate failed: the node stays inactive')
            return
        self.get_logger().info('autostart: configured and activated')

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self._configure()
        except ParameterError as exc:
            self.get_logger().error(f'configure failed: invalid parameter: {printable(exc)}')
            self.calibrator = None
            return FAILURE
        self.get_logger().info('configured')
        return SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._activate()
        return SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._deactivate()
        self.get_logger().info('deactivated: inputs and outputs stopped, the state is kept')
        return SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._cleanup()
        self.get_logger().info('cleaned up: the state is dropped')
        return SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._teardown()
        return SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._teardown()
        return SUCCESS

    def destroy_node(self) -> None:
        self._teardown()
        super().destroy_node()

    def _teardown(self) -> None:
        """From any state: deactivate if active, then drop the state."""
        if self.active:
            self._deactivate()
        self._cleanup()


def main(args: list[str] | None = None) -> int:
    """``hac_lifecycle_node``: unconfigured until a manager, ``hac lifecycle`` or ``autostart``
    moves it; clean shutdown on SIGINT/SIGTERM (exit code 0), 2 on an invalid parameter value at
    start-up (hac_ros.ros.node.run)."""
    return run(HacLifecycleNode, args)


if __name__ == '__main__':
    sys.exit(main())
