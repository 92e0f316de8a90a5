"""hac_node in-process: real rclpy, real DDS (localhost, this process's domain; see conftest.py).

Each test gets a fresh rclpy Context holding the node under test and a test node that plays a
simulated recording into it and records its outputs; one executor thread spins both.

The recordings and the harness here are what the other node modules import; the node run on
simulated walks (convergence, bad input, a SLAM reset, parameters) is in test_node_walk.py. This
module holds the raw CDR cloud reader against rclpy's, the parameters' docs and config, the spin
thread and the messages the middleware lost.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from scenes import QUICK_CONVERGENCE

rclpy = pytest.importorskip('rclpy')

from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message

from hac_ros.bridge.topics import NODE_TOPICS
from hac_ros.core.rules.params import HacParams, describe, names
from hac_ros.files.params_file import load_params
from hac_ros.ros.node import HacNode
from hac_ros.ros.spin_thread import SpinThread
from hac_ros.simulate import make_scenario
from msg_adapters import (
    cloud_to_xyz,
    intrinsics_to_camera_info,
    joints_to_pose_array,
    parse_cloud_cdr,
    rclpy_types,
    rt_to_pose_stamped,
    stamp_to_ns,
    xyz_from_buffer,
    xyz_to_cloud,
)

TYPES = rclpy_types()
REPO = Path(__file__).resolve().parents[1]
INPUTS = {  # kind -> (default topic, type)
    'pose': ('/slam/pose', 'geometry_msgs/msg/PoseStamped'),
    'joints': ('/hmr/joints', 'geometry_msgs/msg/PoseArray'),
    'camera_info': ('/camera/camera_info', 'sensor_msgs/msg/CameraInfo'),
    'cloud': ('/slam/cloud', 'sensor_msgs/msg/PointCloud2'),
}
# what the harness reads back (hac_ros.bridge.topics): every output but the latched map clouds,
# which the tests that want them subscribe to themselves (LATCHED)
OUTPUTS = {t.rooted: t.msgtype for t in NODE_TOPICS if not t.latched}
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
FRAME_PERIOD_S = 0.004  # wall time between played frames (~8x real time at 30 Hz)
SCALE_TOL = 0.02  # the issue: /hac/scale within 2 % of the true scale
# the played recordings' pose/joints publishers are reliable; the node must match them; they play
# faster than real time, and these tests compare every frame with the core's: no frame dropped
# for being late (the overload tests in test_faults_node.py drop them)
# the walk clips converge as quickly as QUICK_CONVERGENCE lets them (scenes.py)
TEST_PARAMS = {'input_qos': 'reliable', 'joints_backlog_max': 100_000,
               'converged_max_rel_sigma': QUICK_CONVERGENCE}


# ================================================================================ recordings
@dataclass
class Event:
    """One input message to publish: its stamp, its kind (a key of INPUTS) and the message."""

    stamp_ns: int
    kind: str
    msg: Any


@dataclass
class Recording:
    events: list[Event]
    pose_stamps: np.ndarray  # (T,) int ns
    joints_stamps: np.ndarray  # (F,) int ns
    true_scale: np.ndarray  # (T,) metres per SLAM unit at each pose stamp
    camera_frame: str

    def scale_at(self, stamp_ns: int) -> float:
        i = int(np.searchsorted(self.pose_stamps, stamp_ns, side='right')) - 1
        return float(self.true_scale[max(i, 0)])


def scenario_recording(name: str, duration: float, seed: int = 0, **kwargs: Any) -> Recording:
    """The simulator's scenario as rclpy messages in stamp order (maps, then poses, then joints)."""
    sc = make_scenario(name, seed=seed, duration=duration, hmr_bias=0.0, **kwargs)
    events: list[Event] = []
    first = int(min(sc.pose_stamps_ns[0], sc.joints_stamps_ns[0]))
    events.append(Event(first, 'camera_info', intrinsics_to_camera_info(
        sc.K, sc.width, sc.height, first, sc.camera_frame, TYPES)))
    for item in sc.maps:
        events.append(Event(int(item.stamp_ns), 'cloud', xyz_to_cloud(
            item.points_slam, int(item.stamp_ns), item.frame_id, TYPES)))
    for i, stamp in enumerate(sc.pose_stamps_ns):
        events.append(Event(int(stamp), 'pose', rt_to_pose_stamped(
            sc.slam_R_wc[i], sc.slam_c[i], int(stamp), sc.slam_frame_ids[i], TYPES)))
    for i, stamp in enumerate(sc.joints_stamps_ns):
        events.append(Event(int(stamp), 'joints', joints_to_pose_array(
            np.asarray(sc.joints_cam[i]), int(stamp), sc.camera_frame, TYPES)))
    order = {'camera_info': 0, 'cloud': 1, 'pose': 2, 'joints': 3}
    events.sort(key=lambda e: (e.stamp_ns, order[e.kind]))
    true_scale = np.broadcast_to(np.asarray(sc.true_scale, dtype=float),
                                 (len(sc.pose_stamps_ns),)).copy()
    return Recording(events, np.asarray(sc.pose_stamps_ns, dtype=np.int64),
                     np.asarray(sc.joints_stamps_ns, dtype=np.int64), true_scale, sc.camera_frame)


# ================================================================================ harness
@dataclass
class Harness:
    """The node under test (``node_class``, in ``namespace``) and a player/recorder node in a
    fresh Context, spun by one thread. Inputs and outputs use relative names, so a namespace
    moves them; ``wait``: wait until every input and output is connected (not for an
    unconfigured lifecycle node, which offers none)."""

    overrides: dict[str, Any] = field(default_factory=dict)
    node_class: type = HacNode
    namespace: str = ''
    wait: bool = True

    def __post_init__(self) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        params = {**TEST_PARAMS, **self.overrides}
        self.node = self.node_class(context=self.context, namespace=self.namespace,
                                    parameter_overrides=[Parameter(k, value=v)
                                                         for k, v in params.items()])
        self.io = rclpy.create_node('hac_test_io', namespace=self.namespace, context=self.context)
        self.publishers = {kind: self.io.create_publisher(
            TYPES.get(msgtype), topic.lstrip('/'), LATCHED if kind == 'cloud' else RELIABLE)
            for kind, (topic, msgtype) in INPUTS.items()}
        self.received: dict[str, list[tuple[float, Any]]] = {topic: [] for topic in OUTPUTS}
        for topic, msgtype in OUTPUTS.items():
            self.io.create_subscription(TYPES.get(msgtype), _relative(topic),
                                        lambda msg, t=topic: self.received[t].append(
                                            (time.monotonic(), msg)), RELIABLE)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.io)
        self.spinner = SpinThread(self.executor)
        self.clouds_published = 0
        if self.wait:
            assert wait_for(self._connected, PATIENCE_S), \
                'DDS discovery between the test and the node failed'

    def connected(self) -> bool:
        """Every input publisher has the node as a subscriber."""
        return all(pub.get_subscription_count() > 0 for pub in self.publishers.values())

    def _connected(self) -> bool:
        outputs = all(self.io.count_publishers(_relative(topic)) > 0
                      and self.node.count_subscribers(_relative(topic)) > 0 for topic in OUTPUTS)
        return self.connected() and outputs

    def close(self) -> None:
        """Stop and destroy everything (once: a test may close it before the fixture does)."""
        if not self.context.ok():
            return
        self.spinner.close()
        self.node.destroy_node()
        self.io.destroy_node()
        rclpy.shutdown(context=self.context)

    # ------------------------------------------------------------------ playing
    def publish(self, event: Event, topic: str | None = None) -> None:
        if topic is None:
            self.publishers[event.kind].publish(event.msg)
        else:  # a re-mapped input topic (runtime parameter change)
            pub = self._extra_publisher(topic, INPUTS[event.kind][1])
            pub.publish(event.msg)
        if event.kind == 'cloud':
            self.clouds_published += 1
            assert wait_for(lambda: self.node.maps.done >= self.clouds_published, PATIENCE_S), \
                'the node did not take the map cloud'

    def _extra_publisher(self, topic: str, msgtype: str) -> Any:
        cache = self.__dict__.setdefault('_extra', {})
        if topic not in cache:
            cache[topic] = self.io.create_publisher(TYPES.get(msgtype), topic, RELIABLE)
            assert wait_for(lambda: cache[topic].get_subscription_count() > 0, PATIENCE_S)
        return cache[topic]

    def play(self, events: list[Event], topics: dict[str, str] | None = None,
             frame_period_s: float = FRAME_PERIOD_S) -> None:
        """Publish in order; a map is waited for (indexed), frames are paced by
        ``frame_period_s``."""
        for event in events:
            self.publish(event, (topics or {}).get(event.kind))
            if event.kind == 'joints':
                time.sleep(frame_period_s)

    def settle(self, timeout: float = 10.0, quiet_s: float = 0.5) -> None:
        """Wait until no output has arrived for ``quiet_s`` (the node has caught up)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            last = max((r[-1][0] for r in self.received.values() if r), default=0.0)
            if time.monotonic() - last > quiet_s:
                return
            time.sleep(0.05)

    # ------------------------------------------------------------------ reading outputs
    def stamps(self, topic: str) -> list[int]:
        return [stamp_to_ns(m.header.stamp) for _, m in self.received[topic]]

    def scales(self) -> list[float]:
        return [m.data for _, m in self.received['/hac/scale']]

    def diagnostics(self) -> dict[str, str]:
        """The key-values of the last /diagnostics message."""
        assert self.received['/diagnostics'], 'no /diagnostics received'
        status = self.received['/diagnostics'][-1][1].status[0]
        return {kv.key: kv.value for kv in status.values}

    def messages(self, topic: str) -> list[Any]:
        """The messages received on output ``topic`` (a key of OUTPUTS), in order."""
        return [m for _, m in self.received[topic]]

    def settle_to(self, last_stamp_ns: int) -> None:
        """Wait until /hac/pose has reached ``last_stamp_ns`` (within 0.1 s), then a little."""
        assert wait_for(lambda: self.received['/hac/pose'] and stamp_to_ns(
            self.received['/hac/pose'][-1][1].header.stamp) >= last_stamp_ns - 100_000_000,
            10.0), 'the node did not catch up'
        time.sleep(0.2)

    def call(self, srv: str, name: str, **fields: Any) -> Any:
        """Call service ``name`` of type ``srv`` with ``fields``; its response."""
        client = self.io.create_client(TYPES.get(srv), name)
        assert client.wait_for_service(timeout_sec=10.0), f'{name} is not offered'
        request = TYPES.get(srv).Request()
        for key, value in fields.items():
            setattr(request, key, value)
        future = client.call_async(request)
        self.executor.wake()  # the spinning executor waits on entities it had before the client
        assert wait_for(future.done, PATIENCE_S), f'{name} did not answer'
        self.io.destroy_client(client)
        return future.result()


def _relative(topic: str) -> str:
    """An output topic as the node names it: relative, but /diagnostics is absolute (REP)."""
    return topic if topic == '/diagnostics' else topic.lstrip('/')


# how long a test waits for what must happen (an upper bound: waiting returns as soon as it has
# happened, so it costs nothing when things go well; generous for a loaded 2-core machine)
PATIENCE_S = 60.0


def wait_for(predicate: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


@pytest.fixture
def harness():
    made: list[Harness] = []

    def make(node_class: type = HacNode, namespace: str = '', wait: bool = True,
             **overrides: Any) -> Harness:
        h = Harness(overrides, node_class, namespace, wait)
        made.append(h)
        return h
    yield make
    for h in made:
        h.close()


def frames_after(recording: Recording, fraction: float) -> int:
    """Index of the first event at or after ``fraction`` of the recording's joints stamps."""
    stamp = recording.joints_stamps[int(fraction * (len(recording.joints_stamps) - 1))]
    return next(i for i, e in enumerate(recording.events) if e.stamp_ns >= stamp)


# ================================================================================ raw cloud
@pytest.mark.parametrize('frame_id', ['', 'm', 'map', 'odom_ab', 'a_longer_frame_name_12'])
@pytest.mark.parametrize('layout', ['xyz32', 'xyz64', 'padded'])
def test_cdr_cloud_header_matches_rclpy_deserialization(frame_id, layout):
    rng = np.random.default_rng(1)
    points = rng.normal(size=(37, 3))
    msg = xyz_to_cloud(points, 1_234_567_890_123, frame_id, TYPES,
                       dtype=np.float64 if layout == 'xyz64' else np.float32)
    if layout == 'padded':  # intensity before x, 4 bytes padding after z, two rows
        PointField = TYPES.get('sensor_msgs/msg/PointField')
        step = 20
        buf = np.zeros((37, step), dtype=np.uint8)
        buf[:, 4:16] = np.frombuffer(points.astype('<f4').tobytes(), np.uint8).reshape(37, 12)
        msg.fields = [PointField(name='intensity', offset=0, datatype=7, count=1)] + [
            PointField(name=n, offset=4 + 4 * i, datatype=7, count=1) for i, n in enumerate('xyz')]
        msg.point_step, msg.row_step = step, step * 37
        msg.data = buf.tobytes()
    raw = serialize_message(msg)
    cloud = parse_cloud_cdr(raw)
    ref = deserialize_message(raw, TYPES.get('sensor_msgs/msg/PointCloud2'))
    assert cloud.stamp_ns == stamp_to_ns(ref.header.stamp) and cloud.frame_id == frame_id
    assert (cloud.height, cloud.width, cloud.point_step, cloud.row_step) == (
        ref.height, ref.width, ref.point_step, ref.row_step)
    assert [(f.name, f.offset, f.datatype, f.count) for f in cloud.fields] == [
        (f.name, f.offset, f.datatype, f.count) for f in ref.fields]
    assert bytes(cloud.data) == bytes(ref.data)
    xyz = xyz_from_buffer(cloud.data, cloud.fields, cloud.point_step, cloud.width, cloud.height,
                          cloud.row_step, cloud.is_bigendian)
    np.testing.assert_array_equal(xyz, cloud_to_xyz(ref))


def test_cdr_cloud_truncated_bytes_are_a_message_error():
    from msg_adapters import MessageError

    raw = serialize_message(xyz_to_cloud(np.ones((10, 3)), 5, 'map', TYPES))
    for cut in (0, 3, 10, 30, len(raw) - 60):
        with pytest.raises(MessageError):
            parse_cloud_cdr(raw[:cut])


# ================================================================================ docs and config
def test_docs_table_and_config_list_every_parameter_with_its_default():
    """The table (docs/node.md) and the config are made by `make docs` (test_docs holds them to
    it); the config is also read back as the defaults."""
    config = REPO / 'config' / 'hac.yaml'
    assert load_params(config) == HacParams()
    listed = yaml.safe_load(config.read_text(encoding='utf-8'))['hac_node']['ros__parameters']
    # the custom layout's index lists are comments: a ROS parameters file cannot hold []
    lists = [n for n in names() if describe(n)['kind'] == 'indices']
    assert list(listed) == [n for n in names() if n not in lists]
    assert all(f'# {n}: [' in config.read_text(encoding='utf-8') for n in lists)


def test_spin_thread_delivers_then_stops_before_its_executor_is_shut_down():
    """hac_ros.ros.spin_thread.SpinThread (the tests' and benchmarks' executor thread): callbacks
    run on it; close() ends the thread and shuts the executor down; a context shut down elsewhere
    ends the thread too."""
    float64 = TYPES.get('std_msgs/msg/Float64')
    context = Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('hac_test_spin', context=context)
        received: list[float] = []
        node.create_subscription(float64, '/hac_test/spin', lambda m: received.append(m.data),
                                 RELIABLE)
        publisher = node.create_publisher(float64, '/hac_test/spin', RELIABLE)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        spinner = SpinThread(executor)
        assert wait_for(lambda: publisher.get_subscription_count() > 0, PATIENCE_S)
        publisher.publish(float64(data=2.5))
        assert wait_for(lambda: received == [2.5], PATIENCE_S)
        assert spinner.close() and not spinner.alive
        assert executor.get_nodes() == []  # shut down: its nodes released

        second = SingleThreadedExecutor(context=context)
        second.add_node(node)
        other = SpinThread(second)
        assert other.alive
        node.destroy_node()
        rclpy.shutdown(context=context)
        assert wait_for(lambda: not other.alive, PATIENCE_S)
        assert other.close()
    finally:
        rclpy.try_shutdown(context=context)


def test_messages_the_middleware_lost_are_counted_in_diagnostics(harness):
    """Best-effort input can lose messages under load before they reach the node (measured:
    bench/node_latency.py at 1M points). Every input subscription listens for the middleware's
    message-lost event and counts ``<kind>_lost`` in the calibrator's status (/diagnostics).

    A real loss cannot be provoked on demand here, and rclpy's status struct has no public
    constructor: the handler rclpy registered is called with a stand-in carrying the one field
    it reads."""
    from types import SimpleNamespace

    from rclpy.event_handler import QoSSubscriptionEventType

    h = harness()
    node = h.node
    lost_type = QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST
    for kind in ('pose', 'joints', 'camera_info', 'cloud'):
        handlers = [e for e in node.subscription(kind).event_handlers
                    if e.event_type == lost_type]
        assert len(handlers) == 1, kind
    handler = next(e for e in node.subscription('joints').event_handlers
                   if e.event_type == lost_type)
    handler.callback(SimpleNamespace(total_count=2, total_count_change=2))
    handler.callback(SimpleNamespace(total_count=3, total_count_change=1))
    assert node.calibrator.status().rejected['joints_lost'] == 3
    assert node.notices['joints_lost'] == 1  # logged once
