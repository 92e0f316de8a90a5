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
  while it is there;
- more than one publisher of the subscribed type on the pose, joints or map topic (two SLAMs on
  one topic: two robots in one domain without namespaces), whose messages interleave: WARN
  ``many_publishers`` while it lasts, logged when it starts and when it ends (looked at with the
  types, every GRAPH_CHECK_S).
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from typing import Any

from rclpy.qos import qos_policy_name_from_kind

from hac_ros.bridge.topics import InputKind, input_msgtype
from hac_ros.core.basics.printable import printable
from hac_ros.core.rules.health import Finding
from hac_ros.core.rules.params import POSE_MSGTYPES
from hac_ros.ros.qos import qos_hint

GRAPH_CHECK_S = 2.0  # wall seconds between checks of the input topics' publisher types
# the inputs one source each must publish
SINGLE_PUBLISHER = (InputKind.POSE, InputKind.JOINTS, InputKind.CLOUD)
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
        self.crowded: dict[str, list[str]] = {}  # input topic -> its publishers' nodes (>= 2)

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
        crowded: dict[str, list[str]] = {}
        for kind, subscription in subscriptions.items():
            topic, expected = subscription.topic_name, input_msgtype(kind, pose_type)
            publishers = self.node.get_publishers_info_by_topic(topic)
            nodes = [f'{info.node_namespace.rstrip("/")}/{info.node_name}' for info in publishers
                     if info.topic_type == expected]
            if kind in SINGLE_PUBLISHER and len(nodes) > 1:
                crowded[topic] = nodes
            for info in publishers:
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
        self._say_crowded(crowded)

    def _say_crowded(self, crowded: dict[str, list[str]]) -> None:
        """Log each input topic that gained a second publisher, or lost it."""
        log = self.node.get_logger()
        for topic, nodes in crowded.items():
            if topic not in self.crowded:
                log.warning(f'{len(nodes)} publishers on {printable(topic)} '
                            f'({printable(", ".join(nodes))}): their messages interleave as if '
                            'one source jumped back and forth (two SLAMs or two robots in one '
                            'domain without namespaces?); give each robot its own namespace, '
                            'or remap the topics')
        for topic in self.crowded.keys() - crowded.keys():
            log.info(f'one publisher on {printable(topic)} again')
        self.crowded = crowded

    def finding(self) -> Finding | None:
        """The /diagnostics finding while an input topic has several publishers."""
        if not self.crowded:
            return None
        return Finding('many_publishers', '; '.join(
            f'{len(nodes)} publishers on {printable(topic)}' for topic, nodes in
            sorted(self.crowded.items())))


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
