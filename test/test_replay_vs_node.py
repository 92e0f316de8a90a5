"""``hac replay --mode online`` publishes what ``hac_node`` publishes, stamp by stamp.

The node is fed the same recording over DDS (this process's domain, localhost; see conftest.py):
reliable QoS, each message published only after the node has processed the previous one (a map
once the node has indexed it and handed it to its calibrator), so that both see the messages in
the same order. The node's odometry, pose, joints, scale and cloud must equal the replay's to 1e-9
(not /diagnostics: the node adds what only it knows, its latency and inputs; not the markers: a
view of the same joints).
"""
from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from injected import played, rewrite
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import Stores, get_typestore
from scenes import QUICK_CONVERGENCE, walking_scene
from test_replay import write_recording

from hac_ros.bridge.topics import BY_KEY
from hac_ros.core.rules.params import HacParams
from hac_ros.replay.feeder import tie_ordered
from hac_ros.replay.replayer import replay
from hac_ros.ros.node import HacNode
from hac_ros.ros.spin_thread import SpinThread
from msg_adapters import rclpy_types, stamp_to_ns

TYPES = rclpy_types()
JAZZY = get_typestore(Stores.ROS2_JAZZY)
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
COMPARED = {BY_KEY[key].rooted: BY_KEY[key].msgtype
            for key in ('odometry', 'pose', 'human_joints', 'scale', 'cloud')}
STAMPED = {'/hac/scale': '/hac/human_joints'}  # Float64 has no header: the joints' stamps
WAIT_S = 60.0  # at most (waiting returns once it has happened)


def wait_for(predicate: Callable[[], bool], timeout: float = WAIT_S) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.001)
    return predicate()


class CountingCalibrator:
    """Wraps the node's calibrator: counts the inputs it has finished processing."""

    def __init__(self, calibrator: Any) -> None:
        self._inner = calibrator
        self.done = 0

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._inner, name)
        if name in ('add_pose', 'add_joints', 'add_camera_info', 'add_map_index', 'reject'):
            def counted(*args: Any, **kwargs: Any) -> Any:
                result = attr(*args, **kwargs)
                self.done += 1
                return result
            return counted
        return attr


def play_to_node(recording: Path, max_rel_sigma: float) -> dict[str, list[Any]]:
    """Publish every input message of ``recording`` to a fresh hac_node (its
    converged_max_rel_sigma ``max_rel_sigma``); its outputs by topic."""
    from rosbags.highlevel import AnyReader

    context = Context()
    rclpy.init(context=context)
    node = HacNode(context=context, parameter_overrides=[
        Parameter('input_qos', value='reliable'),
        Parameter('converged_max_rel_sigma', value=max_rel_sigma)])
    counting = CountingCalibrator(node.calibrator)
    node.calibrator = counting
    io = rclpy.create_node('hac_replay_vs_node', context=context)
    received: dict[str, list[Any]] = {topic: [] for topic in COMPARED}
    for topic, msgtype in COMPARED.items():
        io.create_subscription(TYPES.get(msgtype), topic,
                               lambda msg, t=topic: received[t].append(msg), RELIABLE)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(io)
    spinner = SpinThread(executor)
    try:
        with AnyReader([recording]) as reader:
            inputs = {'/slam/pose', '/hmr/joints', '/slam/cloud', '/camera/camera_info'}
            connections = [c for c in reader.connections if c.topic in inputs]
            publishers = {c.topic: io.create_publisher(
                TYPES.get(c.msgtype), c.topic, LATCHED if c.topic == '/slam/cloud' else RELIABLE)
                for c in connections}
            assert wait_for(lambda: all(p.get_subscription_count() > 0
                                        for p in publishers.values())
                            and all(io.count_publishers(t) > 0 for t in COMPARED)), \
                'DDS discovery between the test and the node failed'
            assert wait_for(lambda: all(io.get_subscriptions_info_by_topic(t)
                                        for t in COMPARED))
            sent = 0
            kinds = {'/slam/pose': 'pose', '/hmr/joints': 'joints', '/slam/cloud': 'cloud',
                     '/camera/camera_info': 'camera_info'}
            types = {c.topic: c.msgtype for c in connections}
            messages = ((c.topic, t, raw) for c, t, raw in reader.messages(connections=connections))
            for topic, _, raw in tie_ordered(messages, kinds):  # the replay's order
                msg = deserialize_message(bytes(raw), TYPES.get(types[topic]))
                publishers[topic].publish(msg)
                sent += 1
                assert wait_for(lambda sent=sent: counting.done >= sent), \
                    f'the node did not process message {sent} ({topic})'
        # the outputs were published in the callbacks above; wait until the last ones arrived
        counts = [-1]

        def quiet() -> bool:
            now = sum(len(v) for v in received.values())
            settled, counts[0] = now == counts[0], now
            return settled
        while not quiet():
            time.sleep(0.3)
    finally:
        spinner.close()
        node.calibrator = counting._inner
        node.destroy_node()
        io.destroy_node()
        rclpy.shutdown(context=context)
    return received


def replay_outputs(out: Path) -> dict[str, list[Any]]:
    from rosbags.highlevel import AnyReader

    got: dict[str, list[Any]] = {topic: [] for topic in COMPARED}
    with AnyReader([out]) as reader:
        for conn, log_ns, raw in reader.messages(
                connections=[c for c in reader.connections if c.topic in COMPARED]):
            got[conn.topic].append((log_ns, bytes(raw)))
    return got


def canonical(cdr: bytes, msgtype: str) -> bytes:
    """A message's CDR with zero padding."""
    return bytes(JAZZY.serialize_cdr(JAZZY.deserialize_cdr(bytes(cdr), msgtype), msgtype))


def odometry_array(msg: Any) -> np.ndarray:
    """Every number of an Odometry: pose, quaternion, covariances and twist."""
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
    return np.concatenate([[p.x, p.y, p.z, q.x, q.y, q.z, q.w],
                           np.asarray(msg.pose.covariance, dtype=float),
                           [lin.x, lin.y, lin.z, ang.x, ang.y, ang.z],
                           np.asarray(msg.twist.covariance, dtype=float)])


def simulated(name: str, duration: float, path: Path) -> Path:
    from hac_ros.simulate import make_scenario
    from hac_ros.simulate import write_recording as write_simulated

    return write_simulated(make_scenario(name, seed=3, duration=duration), path)


@pytest.mark.parametrize('kind', ['scene', 'walk', 'reset', 'looped'])
def test_online_replay_equals_the_node_stamp_by_stamp(tmp_path, kind):
    """scene: exact constructed walk; walk: simulated (noisy HMR and SLAM, CameraInfo, map every
    2 s); reset: simulated SLAM re-initialisation (new map frame and scale, re-anchoring);
    looped: the walk played twice (header time jumps back: a new stream, calibrated afresh)."""
    if kind == 'scene':
        source = write_recording(tmp_path / 'in', walking_scene(frames=60), cloud_every=20)
    elif kind == 'looped':
        source = rewrite(simulated('walk', 6.0, tmp_path / 'once'), tmp_path / 'in', played(2))
    else:
        source = simulated(kind, 6.0, tmp_path / 'in')
    # the simulated 6 s clips converge as quickly as QUICK_CONVERGENCE lets them (scenes.py);
    # the exact scene under the default
    max_rel_sigma = HacParams().converged_max_rel_sigma if kind == 'scene' else QUICK_CONVERGENCE
    replay(source, tmp_path / 'out', HacParams(converged_max_rel_sigma=max_rel_sigma),
           mode='online')
    ours = replay_outputs(tmp_path / 'out')
    node = play_to_node(source, max_rel_sigma)

    # every output topic, message by message: the same stamps, every field bit for bit (the CDR
    # bytes, re-serialised by rosbags: Fast CDR leaves its alignment padding unset)
    # (looped: the replay's log times are the stamps, which go back, so its recording reads the
    # two loops interleaved; the messages are then compared as sorted lists)
    ordered = sorted if kind == 'looped' else list
    for topic, msgtype in COMPARED.items():
        node_bytes = [canonical(serialize_message(m), msgtype) for m in node[topic]]
        assert len(ours[topic]) == len(node_bytes), topic
        assert ordered(canonical(raw, msgtype) for _, raw in ours[topic]) == ordered(node_bytes), \
            topic
        if topic not in STAMPED:
            assert ordered(stamp_to_ns(m.header.stamp) for m in node[topic]) == \
                [log_ns for log_ns, _ in ours[topic]], topic
    assert len(ours['/hac/odometry']) > 30 and len(ours['/hac/human_joints']) > 30
    if kind == 'looped':  # both calibrated the second loop
        stamps = [stamp_to_ns(m.header.stamp) for m in node['/hac/human_joints']]
        back = [k for k in range(1, len(stamps)) if stamps[k] < stamps[k - 1]]
        assert len(back) == 1 and min(back[0], len(stamps) - back[0]) > 30
    assert len(ours['/hac/pose']) == len(ours['/hac/odometry'])  # both wait for a scale
    assert ours['/hac/cloud'], 'the metric map is published'
    assert all(np.isfinite(odometry_array(m)).all() for m in node['/hac/odometry'])
