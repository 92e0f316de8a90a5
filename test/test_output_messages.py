"""hac_ros.bridge.messages: the node's and the replay's output messages.

Each message is read back from its bytes by rosbags and, where importable, by rclpy (what a
subscriber of the node sees); rclpy's reading must equal rosbags' field by field, and the fields
must hold the calibrator's outputs: values, frames, stamps, units.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore
from scenes import QUICK_CONVERGENCE
from scipy.spatial.transform import Rotation

from hac_ros.bridge.messages import (
    DIAGNOSTIC_NAME,
    DIAGNOSTICS,
    MARKERS,
    SAMPLES,
    Message,
    OutputMessages,
    samples_message,
)
from hac_ros.bridge.topics import BY_NAME, NODE_TOPICS
from hac_ros.core.basics.outputs import (
    CloudOut,
    HumanJointsOut,
    OdometryOut,
    PoseOut,
    SampleOut,
    ScaleOut,
)
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.rules.params import HacParams
from hac_ros.simulate import make_scenario
from hac_ros.simulate.feed import scenario_events
from msg_adapters import MessageError, quat_to_matrix, stamp_to_ns

try:
    from rclpy.serialization import deserialize_message

    from msg_adapters import rclpy_types
    RCLPY_TYPES = rclpy_types()
    HAVE_RCLPY = True
except ImportError:  # a plain `pip install .` has no ROS: rosbags only
    HAVE_RCLPY = False

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
STAMP = 1_700_000_000_123_456_789


def read(message: Message) -> Any:
    """The message as rosbags reads its bytes; rclpy (when importable) must read the same."""
    msg = TYPESTORE.deserialize_cdr(message.msg, message.msgtype)
    if HAVE_RCLPY:
        assert_same(deserialize_message(message.msg, RCLPY_TYPES.get(message.msgtype)), msg,
                    message.msgtype)
    return msg


def assert_same(ours: Any, theirs: Any, where: str) -> None:
    """An rclpy message equals a rosbags message, field by field (NaN equals NaN)."""
    if hasattr(ours, 'get_fields_and_field_types'):
        for name in ours.get_fields_and_field_types():
            assert_same(getattr(ours, name), getattr(theirs, name), f'{where}.{name}')
    elif isinstance(ours, (list, tuple)) and ours and hasattr(ours[0], 'get_fields_and_field_types'):
        assert len(ours) == len(theirs), where
        for k, (a, b) in enumerate(zip(ours, theirs)):
            assert_same(a, b, f'{where}[{k}]')
    elif isinstance(ours, bytes):  # rclpy's byte fields; rosbags gives ints
        assert list(ours) == [int(theirs)] if np.ndim(theirs) == 0 else list(theirs), where
    else:
        a, b = np.asarray(ours), np.asarray(theirs)
        assert a.shape == b.shape, where
        if a.dtype.kind == 'f':
            assert np.array_equal(a, b, equal_nan=True), where
        else:
            assert (a == b).all(), where


def only(messages: list[Message], topic: str) -> Any:
    """The one message of ``topic`` among ``messages``, read."""
    found = [m for m in messages if m.topic == topic]
    assert len(found) == 1, [m.topic for m in messages]
    assert found[0].stamp_ns == STAMP
    return read(found[0])


def rotation_of(q: Any) -> np.ndarray:
    return quat_to_matrix(q.x, q.y, q.z, q.w)


def test_pose_and_odometry_hold_the_outputs():
    rng = np.random.default_rng(4)
    R = Rotation.random(random_state=5).as_matrix()
    p = rng.normal(size=3) * 10.0
    cov, twist_cov = np.diag(rng.uniform(0.1, 1.0, 6)), np.diag(rng.uniform(0.1, 1.0, 6))
    v, w = rng.normal(size=3), rng.normal(size=3)
    params = HacParams()
    out = OutputMessages(params)

    pose = only(out.convert(PoseOut(STAMP, 'camera', R, p, cov)), 'hac/pose')
    assert (stamp_to_ns(pose.header.stamp), pose.header.frame_id) == (STAMP, params.metric_frame)
    position = pose.pose.pose.position
    assert [position.x, position.y, position.z] == p.tolist()
    np.testing.assert_allclose(rotation_of(pose.pose.pose.orientation), R, atol=1e-12)
    assert pose.pose.covariance.tolist() == cov.ravel().tolist()

    odom = only(out.convert(OdometryOut(STAMP, 'base_link', R, p, cov, v, w, twist_cov)),
                'hac/odometry')
    assert (odom.header.frame_id, odom.child_frame_id) == (params.odom_frame, 'base_link')
    np.testing.assert_allclose(rotation_of(odom.pose.pose.orientation), R, atol=1e-12)
    twist = odom.twist.twist
    assert [twist.linear.x, twist.linear.y, twist.linear.z] == v.tolist()
    assert [twist.angular.x, twist.angular.y, twist.angular.z] == w.tolist()
    assert odom.twist.covariance.tolist() == twist_cov.ravel().tolist()
    assert odom.pose.covariance.tolist() == cov.ravel().tolist()


def test_pose_stamp_outside_ros_time_is_a_message_error():
    with pytest.raises(MessageError):
        OutputMessages(HacParams()).convert(
            PoseOut(2**31 * 10**9, 'camera', np.eye(3), np.zeros(3), np.eye(6)))


def test_cloud_and_obstacles():
    """The map as float32 points in metric_frame, dense unless a point is not finite; obstacles:
    its points between the two heights."""
    points = np.array([[1.0, 2.0, 0.05], [3.0, 4.0, 1.0], [5.0, 6.0, 2.5], [7.0, 8.0, np.nan]],
                      dtype=np.float32)
    params = dataclasses.replace(HacParams(), publish_obstacles=True)
    messages = OutputMessages(params).convert(CloudOut(STAMP, points, levelled=True))
    cloud = only(messages, 'hac/cloud')
    assert (cloud.header.frame_id, cloud.height, cloud.width) == (params.metric_frame, 1, 4)
    assert [(f.name, f.offset, f.datatype, f.count) for f in cloud.fields] == [
        ('x', 0, 7, 1), ('y', 4, 7, 1), ('z', 8, 7, 1)]
    assert (cloud.point_step, cloud.row_step, cloud.is_dense) == (12, 48, False)
    back = np.frombuffer(bytes(cloud.data), dtype='<f4').reshape(-1, 3)
    assert np.array_equal(back, points, equal_nan=True)
    obstacles = only(messages, 'hac/obstacles')
    assert np.frombuffer(bytes(obstacles.data), dtype='<f4').reshape(-1, 3).tolist() == [
        [3.0, 4.0, 1.0]]
    assert obstacles.is_dense
    not_levelled = OutputMessages(params).convert(CloudOut(STAMP, points, levelled=False))
    assert [m.topic for m in not_levelled] == ['hac/cloud']


def test_joints_scale_and_skeleton_markers():
    """Joints (P, K, 3) in order with identity orientations, a joint not seen (NaN) kept NaN; a
    skeleton LINE_LIST per person, its points the layout's bones (parent, child) whose joints are
    both seen; a person with no joint seen has none."""
    params = HacParams()
    edges = np.array(params.layout().edges, dtype=int)
    k = int(edges.max()) + 1
    joints = np.random.default_rng(1).normal(size=(3, k, 3))
    joints[1, 2, 0] = np.nan  # one joint of person 1 not seen
    joints[2] = np.nan  # person 2 not seen at all
    out = OutputMessages(params)
    messages = out.convert(HumanJointsOut(STAMP, joints))
    array = only(messages, 'hac/human_joints')
    assert array.header.frame_id == params.metric_frame
    got = np.array([[p.position.x, p.position.y, p.position.z] for p in array.poses])
    assert np.array_equal(got, joints.reshape(-1, 3), equal_nan=True)
    assert all((p.orientation.x, p.orientation.w) == (0.0, 1.0) for p in array.poses)
    markers = only(messages, 'hac/markers').markers
    assert [(m.ns, m.id, m.type, m.action) for m in markers] == [('skeleton', 0, 5, 0),
                                                                 ('skeleton', 1, 5, 0)]
    touching = int((edges == 2).any(axis=1).sum())  # person 1's bones with joint 2
    assert [len(m.points) for m in markers] == [2 * len(edges), 2 * (len(edges) - touching)]
    for m, person in zip(markers, (0, 1)):
        assert (m.header.frame_id, stamp_to_ns(m.header.stamp)) == (params.metric_frame, STAMP)
        seen = edges[~(edges == 2).any(axis=1)] if person == 1 else edges
        assert [[q.x, q.y, q.z] for q in m.points] == joints[person][seen.ravel()].tolist()
        assert (m.scale.x, m.color.g, m.pose.orientation.w) == (0.03, pytest.approx(0.9), 1.0)
        assert (m.lifetime.sec, m.lifetime.nanosec, m.frame_locked, m.text) == (0, 0, False, '')
    scale = only(out.convert(ScaleOut(STAMP, 0.125, 0.01)), 'hac/scale')
    assert scale.data == 0.125


def test_samples_message():
    samples = [SampleOut(5, 0, 0.5, 'map', True), SampleOut(5, 1, math.nan, 'gated', False)]
    msg = read(Message(*SAMPLES, samples_message(samples), 5))
    assert [(d.label, d.size, d.stride) for d in msg.layout.dim] == [
        ('sample', 2, 8), ('person,scale,source(0 map 1 ground 2 rejected),accepted', 4, 4)]
    data = msg.data.reshape(-1, 4)
    assert data[0].tolist() == [0.0, 0.5, 0.0, 1.0]
    assert data[1, 0] == 1.0 and math.isnan(data[1, 1]) and data[1, 2:].tolist() == [2.0, 0.0]


@pytest.mark.parametrize('name', ['walk', 'reset', 'crowd'])
def test_every_output_message_of_a_scenario(name):
    """The node's and the replay's messages for a whole simulated run (markers with the path and
    the ground plane, diagnostics with rejections, odometry across a SLAM reset): each on a topic
    of the table (hac_ros.bridge.topics), in the frame its parameter names."""
    sc = make_scenario(name, seed=1, duration=12.0)
    params = HacParams(converged_max_rel_sigma=QUICK_CONVERGENCE,  # publishing from early on
                       metric_frame='world_metric', odom_frame='odom_metric')
    cal = Calibrator(params)
    messages = OutputMessages(params)
    seen: dict[str, int] = {}
    slow: dict[str, list[int]] = {'camera_path': [], 'ground_plane': []}
    cal.add_camera_info(sc.K, sc.width, sc.height)
    for stamp, kind, payload in scenario_events(sc):
        add = {'map': cal.add_map, 'pose': cal.add_pose, 'joints': cal.add_joints}[kind]
        for output in add(stamp, *payload):
            for m in messages.convert(output):
                msg = read(m)
                seen[m.topic] = seen.get(m.topic, 0) + 1
                entry = BY_NAME[m.topic]
                assert m.msgtype == entry.msgtype
                if entry.frame:
                    headers = ([mk.header for mk in msg.markers] if m.topic == MARKERS[0]
                               else [msg.header])
                    assert {h.frame_id for h in headers} == {getattr(params, entry.frame)}
                if m.topic == MARKERS[0]:
                    kinds = {mk.ns for mk in msg.markers}
                    assert 'skeleton' in kinds
                    for ns in kinds & set(slow):
                        slow[ns].append(m.stamp_ns)
                if m.topic == DIAGNOSTICS[0]:
                    status = msg.status[0]
                    assert (status.name, status.hardware_id) == (DIAGNOSTIC_NAME,
                                                                 params.metric_frame)
                    assert status.values[0].key == 'converged'
                    assert status.values[-1].key == 'reasons'
                    assert stamp_to_ns(msg.header.stamp) == m.stamp_ns
    assert set(seen) == {t.name for t in NODE_TOPICS if t.enabled(params)}
    # the path and the plane are refreshed about once a second of stamp time, not every frame
    for ns, stamps in slow.items():
        assert len(stamps) >= 5, ns
        assert min(np.diff(stamps)) >= 1_000_000_000, ns
        assert len(stamps) < seen['hac/markers'] / 10, ns
    # the metric map is latched and sent again only on a scale change or a new segment
    assert 1 <= seen['hac/cloud'] < seen['hac/markers'] / 10
