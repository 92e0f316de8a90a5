"""A managed hac_node that brings itself up (``autostart``), and ``hac lifecycle`` driving any
managed node through its lifecycle services without the ``ros2`` CLI (docs/node.md, "Managed
node")."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip('rclpy')

from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from test_node import PATIENCE_S, harness, scenario_recording, wait_for  # noqa: F401
from test_node_services import state

from hac_ros.core.basics.errors import HacError
from hac_ros.ros.lifecycle_client import change_state
from hac_ros.ros.lifecycle_node import HacLifecycleNode
from hac_ros.ros.node import HacNode
from hac_ros.ros.spin_thread import SpinThread

REPO = Path(__file__).resolve().parents[1]


def test_autostart_configures_and_activates_the_managed_node(harness, capfd):
    """``autostart: true``: hac_lifecycle_node is active as it starts and calibrates; without it
    (the default, nav2's convention) it waits unconfigured; hac_node takes the parameter without
    a word (one parameters file serves both)."""
    walk = scenario_recording('walk', duration=6.0)
    waiting = harness(HacLifecycleNode, namespace='/waiting', wait=False)
    assert waiting.call('lifecycle_msgs/srv/GetState', '/waiting/hac_node/get_state'
                        ).current_state.label == 'unconfigured'
    assert waiting.node.calibrator is None
    r = harness(HacLifecycleNode, wait=False, autostart=True, min_samples=5)
    assert state(r) == 'active' and r.node.active
    assert wait_for(r.connected, PATIENCE_S)
    r.play(walk.events)
    assert wait_for(lambda: len(r.messages('/hac/scale')) > 0, PATIENCE_S)
    plain = harness(HacNode, autostart=True)
    assert plain.node.active
    logged = capfd.readouterr().err
    assert 'autostart: configured and activated' in logged
    assert 'unknown parameter' not in logged and 'ignored' not in logged, logged


def hac_lifecycle(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'hac_ros.cli', 'lifecycle', *args], cwd=REPO,
                          capture_output=True, text=True, timeout=PATIENCE_S + 60)


@pytest.mark.slow
def test_hac_lifecycle_takes_hac_lifecycle_node_through_its_transitions(harness):
    """configure, activate, deactivate, cleanup, shutdown from the command line, each saying the
    state before and after; a transition the state does not offer exits 2 naming those it
    offers."""
    r = harness(HacLifecycleNode, wait=False)
    steps = [('configure', 'unconfigured', 'inactive'), ('activate', 'inactive', 'active'),
             ('deactivate', 'active', 'inactive'), ('cleanup', 'inactive', 'unconfigured')]
    for transition, before, after in steps:
        done = hac_lifecycle('/hac_node', transition)
        assert done.returncode == 0, done.stdout + done.stderr
        assert f'/hac_node: {transition} done: {before} -> {after}' in done.stdout
        assert state(r) == after
    wrong = hac_lifecycle('hac_node', 'activate')
    assert wrong.returncode == 2 and len(wrong.stderr.strip().splitlines()) == 1, wrong.stderr
    assert 'unconfigured' in wrong.stderr and 'configure, shutdown' in wrong.stderr
    done = hac_lifecycle('hac_node', 'shutdown')
    assert done.returncode == 0 and 'shutdown done: unconfigured -> finalized' in done.stdout


class CameraDriver(LifecycleNode):
    """A managed node that is not hac's: it counts its transitions; ``refuse`` fails
    configure."""

    def __init__(self, context: Context, refuse: bool = False) -> None:
        super().__init__('camera_driver', context=context)
        self.refuse = refuse
        self.taken: list[str] = []

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.taken.append('configure')
        return TransitionCallbackReturn.FAILURE if self.refuse else TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.taken.append('activate')
        return super().on_activate(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.taken.append('shutdown')
        return TransitionCallbackReturn.SUCCESS


@pytest.fixture
def camera_driver() -> Any:
    """A CameraDriver spun in a context of its own; made with ``refuse`` by the test."""
    made: list[tuple[Context, Any, SpinThread]] = []

    def make(refuse: bool = False) -> CameraDriver:
        context = Context()
        rclpy.init(context=context)
        node = CameraDriver(context, refuse)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        made.append((context, node, SpinThread(executor)))
        return node
    yield make
    for context, node, spinner in made:
        spinner.close()
        node.destroy_node()
        rclpy.shutdown(context=context)


@pytest.mark.slow
def test_hac_lifecycle_drives_a_managed_node_that_is_not_hacs(camera_driver):
    """The command knows nothing of hac_node: a plain rclpy managed node is configured,
    activated and shut down from active (the shutdown of its state)."""
    driver = camera_driver()
    for transition, after in (('configure', 'inactive'), ('activate', 'active'),
                              ('shutdown', 'finalized')):
        done = hac_lifecycle('/camera_driver', transition)
        assert done.returncode == 0, done.stdout + done.stderr
        assert done.stdout.strip().endswith(f'-> {after}'), done.stdout
    assert driver.taken == ['configure', 'activate', 'shutdown']


def test_a_transition_the_node_refuses_or_a_node_that_is_not_there(camera_driver):
    """Through the library: a configure the node's own callback fails is reported as refused
    (the command exits 1), the state unchanged; a node not in the graph is a HacError naming it
    and the domain."""
    camera_driver(refuse=True)
    context = Context()
    rclpy.init(context=context)
    try:
        outcome = change_state('camera_driver', 'configure', context, wait_s=PATIENCE_S)
        assert not outcome.success and (outcome.before, outcome.after) == ('unconfigured',
                                                                          'unconfigured')
        assert 'configure refused by the node' in outcome.text()
        with pytest.raises(HacError, match=r'no managed node /nobody_here: .*ROS_DOMAIN_ID'):
            change_state('/nobody_here', 'configure', context, wait_s=1.0)
    finally:
        rclpy.shutdown(context=context)
