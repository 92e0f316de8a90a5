"""What DDS tells hac_node about its input topics, and what it does not tell.

Faults of the ROS graph that no message shows, each in ``/diagnostics`` and logged once
(docs/node.md):

- a publisher whose QoS is incompatible with the subscription (rclpy's incompatible-QoS event):
  logged with what to change (:func:`hac_ros.ros.qos.qos_hint`);
- messages the middleware saw but that never reached the subscription (the message-lost event of
  best-effort input under load): ``<kind>_lost``;
- a publisher of another message type on an input topic: it gets no message through and this rmw
  reports no event, so the graph is looked at every GRAPH_CHECK_S: ``<kind>_wrong_type``, logged
  naming the parameter to change;
- another node with the same name and namespace (:class:`NameWatch`): WARN ``duplicate_name``
  while it is there.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from typing import Any

from rclpy.qos import qos_policy_name_from_kind

from hac_ros.bridge.messages import input_msgtype
from hac_ros.core.health import Finding
from hac_ros.core.params import POSE_MSGTYPES
from hac_ros.core.printable import printable
from hac_ros.ros.qos import qos_hint

GRAPH_CHECK_S = 2.0  # wall seconds between checks of the input topics' publisher types
# wall seconds between looks for another node of the same name: with DDS discovery on one host
# (well under a second) both warn within 2 s of the second appearing
NAME_CHECK_S = 0.25

# reject(reason, text): one rejection counted by the calibrator; ``text``, when given, is what its
# first notice says instead of the reason's own text
Reject = Callable[[str, str], None]


class GraphWatch:
    """The graph faults of ``node``'s inputs, counted through ``reject``."""

    def __init__(self, node: Any, reject: Reject) -> None:
        self.node = node
        self.reject = reject
        self.qos_incompatible: Counter[str] = Counter()  # topics with an incompatible publisher
        self._wrong_types: set[tuple[str, str, str, str]] = set()  # publishers reported

    def incompatible_qos(self, kind: str, topic: str, info: Any) -> None:
        """rclpy's incompatible-QoS event of the ``kind`` subscription to ``topic``."""
        policy = qos_policy_name_from_kind(info.last_policy_kind)
        topic = self.node.resolve_topic_name(topic)
        self.qos_incompatible[topic] += 1
        self.node.get_logger().warning(
            f'QoS mismatch on {printable(topic)}: a publisher offers an incompatible {policy} '
            f'policy, so no messages from it will arrive; {qos_hint(kind, policy)}')

    def message_lost(self, kind: str, info: Any) -> None:
        """rclpy's message-lost event of the ``kind`` subscription: one ``<kind>_lost`` each."""
        for _ in range(max(int(info.total_count_change), 0)):
            self.reject(f'{kind}_lost', '')

    def check_types(self, subscriptions: dict[str, Any], pose_type: str) -> None:
        """Each publisher of another type on the topic of a subscription (kind -> rclpy
        Subscription) is counted once as ``<kind>_wrong_type``."""
        for kind, subscription in subscriptions.items():
            topic, expected = subscription.topic_name, input_msgtype(kind, pose_type)
            for info in self.node.get_publishers_info_by_topic(topic):
                key = (topic, info.node_namespace, info.node_name, info.topic_type)
                if info.topic_type == expected or key in self._wrong_types:
                    continue
                self._wrong_types.add(key)
                hint = (f'set pose_type to {info.topic_type.rsplit("/", 1)[-1]!r}'
                        if kind == 'pose' and info.topic_type in POSE_MSGTYPES.values() else
                        f'{kind}_topic may name the wrong topic')
                self.reject(f'{kind}_wrong_type',
                            f'type mismatch on {topic}: {info.node_name} publishes '
                            f'{info.topic_type}, the node subscribes {expected}, so none of its '
                            f'messages arrive; {hint}')


class NameWatch:
    """Another node with ``node``'s name and namespace in the graph: every output would come
    twice and the services answer twice, and nothing else says so. Looked at every
    NAME_CHECK_S of steady time from the node's start (in every lifecycle state); each of the
    two nodes sees the other, so both warn, once each time the other appears, and say when it
    left. :attr:`others` is the number of other nodes of that name now (0: none)."""

    def __init__(self, node: Any) -> None:
        self.node = node
        self.others = 0

    @property
    def name(self) -> str:
        namespace = self.node.get_namespace().rstrip('/')
        return f'{namespace}/{self.node.get_name()}'

    def check(self) -> None:
        me = (self.node.get_name(), self.node.get_namespace())
        others = sum(1 for entry in self.node.get_node_names_and_namespaces()
                     if tuple(entry) == me) - 1
        if others > 0 and not self.others:
            self.node.get_logger().warning(
                f'another node named {printable(self.name)} is in the graph ({others + 1} with '
                'this name in this ROS domain): each would answer every input, publish every '
                'output and offer every service; give each its own name (--ros-args -r '
                '__node:=NAME) or namespace (-r __ns:=/NAME), or stop one of them')
        elif not others and self.others:
            self.node.get_logger().info(f'no other node named {printable(self.name)} in the '
                                        'graph any more')
        self.others = max(others, 0)

    def finding(self) -> Finding | None:
        """The /diagnostics finding while another node has this name."""
        if not self.others:
            return None
        return Finding('duplicate_name', f'{self.others + 1} nodes named {printable(self.name)}')
