"""hac_node's planner-facing interface over real DDS: ~/reset and ~/freeze, the latched metric map
(/hac/cloud) for a late subscriber, namespaces, the managed (lifecycle) variant, and TF through a
stand-in tf2_ros (test/standins: tf2_ros is not installable here)."""
from __future__ import annotations

import importlib.util
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
pytestmark = pytest.mark.ros

from rclpy.context import Context
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from test_node import (  # noqa: F401
    PATIENCE_S,
    RELIABLE,
    TEST_PARAMS,
    TYPES,
    Harness,
    frames_after,
    harness,
    scenario_recording,
    wait_for,
)
from test_node_process import STARTUP_S, Client, start_node, stop

from hac_ros.ros.lifecycle_node import HacLifecycleNode
from msg_adapters import cloud_to_xyz, pose_msg_to_rt, stamp_to_ns

REPO = Path(__file__).resolve().parents[1]
CLOUD_LATE = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
MIN_SAMPLES = {'min_samples': 10}


@pytest.fixture(scope='module')
def walk():
    return scenario_recording('walk', duration=12.0)


def test_freeze_and_reset_services_over_dds(harness, walk):
    r = harness(**MIN_SAMPLES)
    assert wait_for(r.connected, PATIENCE_S)
    a, b = frames_after(walk, 0.4), frames_after(walk, 0.7)
    r.play(walk.events[:a])
    r.settle_to(walk.events[a - 1].stamp_ns)
    answer = r.call('std_srvs/srv/SetBool', '/hac_node/freeze', data=True)
    assert answer.success and 'held' in answer.message
    held_from = len(r.messages('/hac/scale')) + 1  # taken at the next SLAM pose
    r.play(walk.events[a:b])
    r.settle_to(walk.events[b - 1].stamp_ns)
    held = [m.data for m in r.messages('/hac/scale')[held_from:]]
    assert len(held) > 20 and len(set(held)) == 1
    assert r.diagnostics()['frozen'] == 'true'
    assert r.call('std_srvs/srv/SetBool', '/hac_node/freeze', data=False).success
    assert r.call('std_srvs/srv/Trigger', '/hac_node/reset').success
    r.play(walk.events[b:])
    r.settle_to(walk.events[-1].stamp_ns)
    diag = r.diagnostics()
    assert diag['frozen'] == 'false' and diag['resets'] == '1'
    assert diag['service.reset'] == '1' and diag['service.freeze_true'] == '1'
    # the odometry never jumps: neither at the freeze, the release nor the reset
    odom = r.messages('/hac/odometry')
    positions = np.array([pose_msg_to_rt(m)[1] for m in odom])
    moving = [m.twist.twist.linear.x != 0 or m.twist.twist.linear.z != 0 for m in odom[1:]]
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)[np.array(moving)]
    assert steps.max() < 0.3  # a walk at 30 Hz: centimetres per pose


def test_a_late_subscriber_receives_the_metric_map(harness, walk):
    r = harness(**MIN_SAMPLES)
    assert wait_for(r.connected, PATIENCE_S)
    r.play(walk.events)
    r.settle_to(walk.events[-1].stamp_ns)
    late: list[Any] = []
    r.io.create_subscription(TYPES.get('sensor_msgs/msg/PointCloud2'), 'hac/cloud',
                             late.append, CLOUD_LATE)
    assert wait_for(lambda: late, PATIENCE_S), 'a late subscriber got no /hac/cloud'
    cloud = late[-1]
    assert cloud.header.frame_id == 'map_metric' and cloud.width > 1000
    points = cloud_to_xyz(cloud)
    assert np.isfinite(points).all()
    # gravity frame, metres: the floor of the simulated room near z = 0, the room metres wide
    assert abs(np.percentile(points[:, 2], 2)) < 0.1 and np.ptp(points[:, 0]) > 3.0


def test_a_namespace_moves_every_topic_and_service(harness, walk):
    r = harness(namespace='robot1', **MIN_SAMPLES)
    assert wait_for(r.connected, PATIENCE_S)
    assert r.node.resolve_topic_name(r.node.params.pose_topic) == '/robot1/slam/pose'
    r.play(walk.events[:frames_after(walk, 0.5)])
    assert wait_for(lambda: r.messages('/hac/odometry') and r.messages('/hac/pose'), PATIENCE_S)
    topics = dict(r.io.get_topic_names_and_types())
    for name in ('/robot1/hac/odometry', '/robot1/hac/pose', '/robot1/hac/cloud',
                 '/robot1/hac/scale', '/diagnostics'):
        assert name in topics, name
    assert '/hac/odometry' not in topics
    assert r.call('std_srvs/srv/Trigger', '/robot1/hac_node/reset').success


def lifecycle(r: Harness, transition: str) -> bool:
    ids = {'configure': 1, 'cleanup': 2, 'activate': 3, 'deactivate': 4}
    transition_msg = TYPES.get('lifecycle_msgs/msg/Transition')(id=ids[transition])
    return r.call('lifecycle_msgs/srv/ChangeState', '/hac_node/change_state',
                  transition=transition_msg).success


def state(r: Harness) -> str:
    return r.call('lifecycle_msgs/srv/GetState', '/hac_node/get_state').current_state.label


def test_the_lifecycle_node_publishes_only_while_active_and_keeps_its_state(harness, walk):
    r = harness(HacLifecycleNode, wait=False, **MIN_SAMPLES)
    assert state(r) == 'unconfigured'
    r.play(walk.events[:5])  # nobody listens yet
    assert lifecycle(r, 'configure') and state(r) == 'inactive'
    assert lifecycle(r, 'activate') and state(r) == 'active'
    assert wait_for(r.connected, PATIENCE_S)
    half = frames_after(walk, 0.5)
    r.play(walk.events[:half])
    r.settle_to(walk.events[half - 1].stamp_ns)
    converged = len(r.messages('/hac/scale'))
    assert converged > 0
    assert lifecycle(r, 'deactivate') and state(r) == 'inactive'
    count = len(r.messages('/hac/odometry'))
    for event in walk.events[half:half + 60]:
        r.publishers[event.kind].publish(event.msg)
    time.sleep(0.5)
    assert len(r.messages('/hac/odometry')) == count  # inactive: nothing in, nothing out
    assert lifecycle(r, 'activate')
    assert wait_for(r.connected, PATIENCE_S)
    before = len(r.messages('/hac/scale'))
    r.play(walk.events[half + 60:])
    r.settle_to(walk.events[-1].stamp_ns)
    assert len(r.messages('/hac/scale')) > before  # continued at once: the estimate was kept
    assert lifecycle(r, 'deactivate') and lifecycle(r, 'cleanup')
    assert state(r) == 'unconfigured' and r.node.calibrator is None


def test_tf_through_a_stand_in_broadcaster(tmp_path, walk):
    """publish_tf and publish_odom_tf in a node process whose tf2_ros is test/standins' (it
    publishes each TransformStamped on /tf_standin): odom -> camera is the odometry, and
    metric -> odom composes the odometry of a stamp into its /hac/pose."""
    params = {**TEST_PARAMS, 'min_samples': 10, 'publish_tf': True, 'publish_odom_tf': True}
    standins = os.pathsep.join([str(REPO / 'test' / 'standins'), os.environ.get('PYTHONPATH', '')])
    node = start_node(tmp_path, params, env={'PYTHONPATH': standins})
    client = Client()
    tfs: list[Any] = []
    client.io.create_subscription(TYPES.get('geometry_msgs/msg/TransformStamped'), '/tf_standin',
                                  tfs.append, RELIABLE)
    got = client.received
    try:
        assert wait_for(lambda: client.node_is_up() and client.io.count_publishers('/tf_standin'),
                        STARTUP_S), 'no node, no TF'
        for event in walk.events[:frames_after(walk, 0.6)]:
            client.publishers[event.kind].publish(event.msg)
            time.sleep(0.5 if event.kind == 'cloud' else 0.004 if event.kind == 'joints' else 0)
        assert wait_for(lambda: len(got['/hac/pose']) > 50 and len(tfs) > 100, PATIENCE_S)
    finally:
        client.close()
        _, log = stop(node, signal.SIGINT)
    assert 'tf2_ros is not available' not in log, log
    odom = {stamp_to_ns(m.header.stamp): pose_msg_to_rt(m) for m in got['/hac/odometry']}
    pose = {stamp_to_ns(m.header.stamp): pose_msg_to_rt(m) for m in got['/hac/pose']}
    checked = 0
    for tf in tfs:
        stamp, t, q = stamp_to_ns(tf.header.stamp), tf.transform.translation, tf.transform.rotation
        if stamp not in odom or stamp not in pose:
            continue  # the last few: received before the outputs of their stamp
        R_tf, p_tf = pose_msg_to_rt_parts(t, q)
        if (tf.header.frame_id, tf.child_frame_id) == ('hac_odom', walk.camera_frame):
            np.testing.assert_allclose(R_tf, odom[stamp][0], atol=1e-9)
            np.testing.assert_allclose(p_tf, odom[stamp][1], atol=1e-9)
            checked += 1
        else:
            assert (tf.header.frame_id, tf.child_frame_id) == ('map_metric', 'hac_odom')
            R_o, p_o = odom[stamp]
            np.testing.assert_allclose(R_tf @ R_o, pose[stamp][0], atol=1e-9)
            np.testing.assert_allclose(R_tf @ p_o + p_tf, pose[stamp][1], atol=1e-9)
            checked += 1
    assert checked > 100


def pose_msg_to_rt_parts(t: Any, q: Any) -> tuple[np.ndarray, np.ndarray]:
    from scipy.spatial.transform import Rotation

    return (Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), np.array([t.x, t.y, t.z]))


@pytest.mark.slow
def test_pose_source_tf_through_a_stand_in_listener(tmp_path, walk):
    """pose_source tf in a node process whose tf2_ros is test/standins': the SLAM's dynamic
    transform map -> base_link on /tf_standin and the static base_link -> camera_optical on
    /tf_static_standin (transient local, published before the node starts). The node takes a pose
    at every SLAM transform's stamp, composed with the static one, and converges as with the
    PoseStamped topic."""
    from test_node import SCALE_TOL

    from hac_ros.core.bodies.conventions import optical_transform
    from hac_ros.simulate.writer import BASE_FRAME, BASE_TO_OPTICAL
    from msg_adapters import rt_to_transform_stamped

    R_bo, t_bo = optical_transform(BASE_TO_OPTICAL)
    params = {**TEST_PARAMS, 'min_samples': 10, 'pose_source': 'tf',
              'slam_pose_frame': walk.camera_frame}
    standins = os.pathsep.join([str(REPO / 'test' / 'standins'), os.environ.get('PYTHONPATH', '')])
    client = Client()
    transform = TYPES.get('geometry_msgs/msg/TransformStamped')
    dynamic = client.io.create_publisher(transform, '/tf_standin', RELIABLE)
    static = client.io.create_publisher(transform, '/tf_static_standin', CLOUD_LATE)
    first = walk.events[0].stamp_ns
    static.publish(rt_to_transform_stamped(R_bo, t_bo, first, BASE_FRAME, walk.camera_frame,
                                           TYPES))
    node = start_node(tmp_path, params, env={'PYTHONPATH': standins})
    got = client.received
    try:
        assert wait_for(lambda: dynamic.get_subscription_count() > 0
                        and static.get_subscription_count() > 0
                        and client.publishers['joints'].get_subscription_count() > 0
                        and client.io.count_publishers('/hac/pose') > 0, STARTUP_S), 'no node'
        time.sleep(1.0)  # the latched static transform reaches the node
        for event in walk.events:
            if event.kind == 'pose':  # the SLAM's pose of the base: pose_camera · T⁻¹
                R, c = pose_msg_to_rt(event.msg)
                R_b = R @ R_bo.T
                dynamic.publish(rt_to_transform_stamped(
                    R_b, c - R_b @ t_bo, event.stamp_ns, event.msg.header.frame_id, BASE_FRAME,
                    TYPES))
            else:
                client.publishers[event.kind].publish(event.msg)
            time.sleep(0.5 if event.kind == 'cloud' else 0.004 if event.kind == 'joints' else 0)
        last = int(walk.pose_stamps[-1])
        assert wait_for(lambda: got['/hac/pose'] and stamp_to_ns(
            got['/hac/pose'][-1].header.stamp) == last, PATIENCE_S), 'the last pose was not taken'
    finally:
        client.close()
        code, log = stop(node, signal.SIGINT)
    assert code == 0 and 'Traceback' not in log, log
    assert 'TF map -> camera_optical' in log
    scale = got['/hac/scale'][-1].data
    assert abs(scale / walk.scale_at(last) - 1.0) < SCALE_TOL
    stamps = [stamp_to_ns(m.header.stamp) for m in got['/hac/pose']]
    poses = [int(s) for s in walk.pose_stamps]
    assert stamps == poses[poses.index(stamps[0]):]  # every SLAM transform once converged
    diagnostics = {kv.key: kv.value for kv in got['/diagnostics'][-1].status[0].values}
    assert int(diagnostics['pose_match.exact']) > 100
    # should the latched static still come after the first SLAM transforms (a loaded machine),
    # those are counted, never turned into poses
    assert int(diagnostics.get('rejected.tf_unconnected', '0')) <= 10


def test_pose_source_tf_refuses_a_chain_through_a_second_dynamic_transform(harness, monkeypatch,
                                                                           capfd):
    """The node's own TF path (hac_ros.ros.tf_input fed by test/standins' listener, in this
    process): a SLAM's map -> odom over wheel odometry's odom -> camera_optical would mix metric
    motion into SLAM units. Every such transform is counted as rejected.tf_chain_dynamic, no pose
    is made of it, the error naming both transforms is logged once, and the node keeps running."""
    from msg_adapters import rt_to_transform_stamped

    spec = importlib.util.spec_from_file_location(
        'tf2_ros', REPO / 'test' / 'standins' / 'tf2_ros' / '__init__.py')
    assert spec is not None and spec.loader is not None
    standin = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(standin)
    monkeypatch.setitem(sys.modules, 'tf2_ros', standin)  # for this test only
    r = harness(wait=False, pose_source='tf', slam_pose_frame='camera_optical')
    tf = r.io.create_publisher(TYPES.get('geometry_msgs/msg/TransformStamped'), '/tf_standin',
                               RELIABLE)
    assert wait_for(lambda: tf.get_subscription_count() > 0, PATIENCE_S), 'the listener did not connect'
    pairs = 20
    for i in range(pairs):
        stamp = 1_000_000_000 + i * 33_000_000
        along = np.array([0.01 * i, 0.0, 0.0])
        tf.publish(rt_to_transform_stamped(np.eye(3), along, stamp, 'map', 'odom', TYPES))
        tf.publish(rt_to_transform_stamped(np.eye(3), along, stamp, 'odom', 'camera_optical',
                                           TYPES))

    def rejected() -> dict[str, int]:
        with r.node.lock:
            return dict(r.node.core.status().rejected)
    # the first map -> odom cannot reach camera_optical yet; every transform after it closes a
    # chain through both
    assert wait_for(lambda: rejected().get('tf_chain_dynamic', 0) == 2 * pairs - 1, PATIENCE_S), \
        rejected()
    assert rejected().get('tf_unconnected') == 1
    with r.node.lock:
        assert r.node.core.status().frames == 0
    assert r.messages('/hac/pose') == [] and r.messages('/hac/odometry') == []
    error = ("passes through 2 dynamic transforms (map -> odom, odom -> camera_optical)")
    logged = capfd.readouterr().err
    assert logged.count(error) == 1, logged
    assert 'further ones are counted as rejected.tf_chain_dynamic' in logged
    assert r.node.tf_input is not None and r.node.context.ok()  # still listening


def test_pose_source_tf_without_tf2_ros_names_what_to_install(tmp_path):
    node = start_node(tmp_path, {'pose_source': 'tf', 'slam_pose_frame': 'camera_optical'})
    out, err = node.communicate(timeout=STARTUP_S)
    assert node.returncode == 2, out + err
    assert 'pose_source tf needs tf2_ros' in err and 'ros-jazzy-tf2-ros' in err, err
    assert 'Traceback' not in err


def test_a_publisher_of_another_type_on_the_pose_topic_is_counted_and_named(harness):
    """Odometry on slam/pose while pose_type is PoseStamped: DDS delivers nothing and says nothing
    (this rmw reports no incompatible-type event); the node's graph check names it."""
    r = harness(**MIN_SAMPLES)
    assert wait_for(r.connected, PATIENCE_S)
    context = Context()  # another participant: one participant refuses two types on one topic
    rclpy.init(context=context)
    other = rclpy.create_node('hac_wrong_type', context=context)
    try:
        other.create_publisher(TYPES.get('nav_msgs/msg/Odometry'), 'slam/pose', RELIABLE)
        assert wait_for(lambda: r.node.calibrator.rejected['pose_wrong_type'] > 0, PATIENCE_S), \
            'a publisher of nav_msgs/Odometry on slam/pose went unnoticed'
        time.sleep(2.5)  # another graph check: the same publisher is not counted twice
        assert r.node.calibrator.rejected['pose_wrong_type'] == 1
        assert r.node.notices['pose_wrong_type'] == 1
    finally:
        other.destroy_node()
        rclpy.shutdown(context=context)
