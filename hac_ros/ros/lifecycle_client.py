"""``hac lifecycle NODE TRANSITION``: any managed node driven through its lifecycle services.

The ROS 2 wheels have no ``ros2 lifecycle set``; this is the same, over the services every
managed node offers (``<node>/get_state``, ``<node>/change_state``,
``<node>/get_available_transitions``, ``lifecycle_msgs``), for ``hac_lifecycle_node`` and for
any other managed node (C++ or Python). The transitions are named as ``ros2 lifecycle set`` names
them: ``configure``, ``activate``, ``deactivate``, ``cleanup``, and ``shutdown``, which is the
shutdown transition of the node's current state (``unconfigured_shutdown``,
``inactive_shutdown`` or ``active_shutdown``).
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Any

from hac_ros.core.basics.errors import ArgumentError, HacError
from hac_ros.core.basics.printable import printable

TRANSITIONS = ('configure', 'activate', 'deactivate', 'cleanup', 'shutdown')
# lifecycle_msgs' transition labels, and the state each leads to when it succeeds
GOALS = {'configure': 'inactive', 'activate': 'active', 'deactivate': 'inactive',
         'cleanup': 'unconfigured', 'shutdown': 'finalized'}
WAIT_S = 10.0  # how long the node's lifecycle services may take to appear (DDS discovery)
CALL_S = 60.0  # how long a transition may take (configure reads parameters, makes the state)
RETRY_S = 2.0  # a query unanswered for this long is sent again (see LifecycleClient._call)


@dataclass
class Outcome:
    """One transition asked of ``node``: the state before and after, and whether the node took
    it (a transition the node refused, e.g. a configure with an invalid parameter, is
    ``success`` False)."""

    node: str
    transition: str
    before: str
    after: str
    success: bool

    def text(self) -> str:
        what = 'done' if self.success else 'refused by the node'
        return (f'{printable(self.node)}: {self.transition} {what}: {printable(self.before)} -> '
                f'{printable(self.after)}')


def node_name(name: str) -> str:
    """The node's fully qualified name (``hac_node`` -> ``/hac_node``); ArgumentError naming
    ``node`` for an empty one."""
    name = name.strip()
    if not name.strip('/'):
        raise ArgumentError('node: the name of a managed node, e.g. /hac_node')
    return name if name.startswith('/') else '/' + name


def transition_id(transition: str, state: str) -> int:
    """The lifecycle_msgs Transition id of ``transition`` from ``state`` (``shutdown``: the one
    of that state); ArgumentError naming ``transition`` for a name not in TRANSITIONS."""
    from lifecycle_msgs.msg import Transition

    ids = {'configure': Transition.TRANSITION_CONFIGURE,
           'activate': Transition.TRANSITION_ACTIVATE,
           'deactivate': Transition.TRANSITION_DEACTIVATE,
           'cleanup': Transition.TRANSITION_CLEANUP}
    shutdown = {'unconfigured': Transition.TRANSITION_UNCONFIGURED_SHUTDOWN,
                'inactive': Transition.TRANSITION_INACTIVE_SHUTDOWN,
                'active': Transition.TRANSITION_ACTIVE_SHUTDOWN}
    if transition not in TRANSITIONS:
        raise ArgumentError(f'transition: {transition!r} is not one of {", ".join(TRANSITIONS)}')
    if transition == 'shutdown':
        if state not in shutdown:
            raise HacError(f'shutdown: no shutdown transition from state {state!r}')
        return shutdown[state]
    return ids[transition]


class LifecycleClient:
    """The lifecycle services of the managed node ``name``, called from a node of its own in
    ``context`` (an initialised rclpy Context). HacError when they do not appear within
    ``wait_s``."""

    def __init__(self, name: str, context: Any, wait_s: float = WAIT_S) -> None:
        import rclpy
        from lifecycle_msgs.srv import ChangeState, GetAvailableTransitions, GetState
        from rclpy.executors import SingleThreadedExecutor

        self.name = node_name(name)
        self.node = rclpy.create_node('hac_lifecycle_client', context=context,
                                      start_parameter_services=False)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._get = self.node.create_client(GetState, f'{self.name}/get_state')
        self._change = self.node.create_client(ChangeState, f'{self.name}/change_state')
        self._available = self.node.create_client(
            GetAvailableTransitions, f'{self.name}/get_available_transitions')
        if not all(client.wait_for_service(timeout_sec=wait_s)
                   for client in (self._get, self._change, self._available)):
            domain = os.environ.get('ROS_DOMAIN_ID', '0')
            self.close()
            raise HacError(f'no managed node {printable(self.name)}: its lifecycle services '
                           f'({printable(self.name)}/change_state) did not appear within '
                           f'{wait_s:g} s (is it running, managed, in ROS_DOMAIN_ID {domain}?)')

    def _call(self, client: Any, request: Any, retry: bool = True) -> Any:
        """``client``'s answer to ``request``; HacError after CALL_S. A query (``retry``) is sent
        again every RETRY_S: an answer can be lost while DDS is still matching the node's reply
        writer with this process's new reader (seen after another node of the same name left
        the graph)."""
        deadline = time.monotonic() + CALL_S
        while True:
            future = client.call_async(request)
            wait = min(RETRY_S, deadline - time.monotonic()) if retry else CALL_S
            self.executor.spin_until_future_complete(future, timeout_sec=max(wait, 0.0))
            if future.done() and future.result() is not None:
                return future.result()
            client.remove_pending_request(future)
            if not retry or time.monotonic() >= deadline:
                raise HacError(f'{printable(self.name)}: no answer from {client.srv_name} within '
                               f'{CALL_S:g} s')

    def state(self) -> str:
        """The node's current state (its label: unconfigured, inactive, active, finalized)."""
        from lifecycle_msgs.srv import GetState

        return str(self._call(self._get, GetState.Request()).current_state.label)

    def available(self) -> list[str]:
        """The labels of the transitions available from the current state."""
        from lifecycle_msgs.srv import GetAvailableTransitions

        answer = self._call(self._available, GetAvailableTransitions.Request())
        return [str(t.transition.label) for t in answer.available_transitions]

    def change(self, transition: str) -> Outcome:
        """Take ``transition`` (one of TRANSITIONS); HacError naming the transitions available
        when it is not one of them from the current state.

        An unanswered request is not sent blindly again: the state tells whether the node took
        it (its answer lost: see :meth:`_call`), and only a request the node did not take is
        sent again (a transition that failed leaves the state where it was and fails again)."""
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import ChangeState

        before = self.state()
        wanted = transition_id(transition, before)
        available = self.available()  # labels: each shutdown transition's is 'shutdown'
        if transition not in available:
            raise HacError(f'{printable(self.name)} is {printable(before)}: {transition} is not '
                           f'one of its transitions from there '
                           f'({", ".join(sorted(set(available))) or "none"})')
        request = ChangeState.Request(transition=Transition(id=wanted))
        deadline = time.monotonic() + CALL_S
        while True:
            future = self._change.call_async(request)
            self.executor.spin_until_future_complete(future, timeout_sec=RETRY_S)
            if future.done() and future.result() is not None:
                return Outcome(self.name, transition, before, self.state(),
                               bool(future.result().success))
            self._change.remove_pending_request(future)
            after = self.state()  # served once the node is done with the transition
            if after != before:  # taken, its answer lost
                return Outcome(self.name, transition, before, after, after == GOALS[transition])
            if time.monotonic() >= deadline:
                raise HacError(f'{printable(self.name)}: no answer from {self._change.srv_name} '
                               f'within {CALL_S:g} s')

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()


def change_state(name: str, transition: str, context: Any, wait_s: float = WAIT_S) -> Outcome:
    """Take ``transition`` on the managed node ``name`` (:class:`LifecycleClient`)."""
    client = LifecycleClient(name, context, wait_s)
    try:
        return client.change(transition)
    finally:
        client.close()
