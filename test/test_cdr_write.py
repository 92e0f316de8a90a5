"""msg_adapters.cdr_write and the node/replay output messages, byte for byte against rosbags and
rclpy.

Every encoded message is deserialized by rosbags (and rclpy where importable) into a real message
object whose fields must equal the inputs, and that object serialized again must give exactly our
bytes: a wrong alignment, a missing field or a wrong default cannot pass.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from hac_ros.bridge.messages import DIAGNOSTICS, MARKERS, SAMPLES, OutputMessages, samples_message
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.outputs import SampleOut
from hac_ros.core.params import HacParams
from hac_ros.simulate import make_scenario
from hac_ros.simulate.feed import scenario_events
from msg_adapters import MessageError, cdr_write

try:
    from rclpy.serialization import deserialize_message

    from msg_adapters import rclpy_types
    RCLPY_TYPES = rclpy_types()
    HAVE_RCLPY = True
except ImportError:  # a plain `pip install .` has no ROS: rosbags only
    HAVE_RCLPY = False

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
finite = st.floats(-1e6, 1e6, allow_nan=False)
names = st.text(st.characters(codec='utf-8', exclude_characters='\x00'), max_size=12)
stamps = st.integers(0, 2**31 * 10**9 - 1)


def roundtrip(data: bytes, msgtype: str):
    """rosbags: our bytes → message → bytes must be our bytes. rclpy (when importable) must read
    our bytes into a message whose every field equals rosbags' reading. (rclpy's own bytes differ
    in padding: Fast CDR leaves padding uninitialised and pads before an empty float64 sequence.)"""
    msg = TYPESTORE.deserialize_cdr(data, msgtype)
    assert bytes(TYPESTORE.serialize_cdr(msg, msgtype)) == data
    if HAVE_RCLPY:
        assert_same(deserialize_message(data, RCLPY_TYPES.get(msgtype)), msg, msgtype)
    return msg


def assert_same(ours, theirs, where: str) -> None:
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


def stamp_ns(header) -> int:
    return header.stamp.sec * 10**9 + header.stamp.nanosec


@FUZZ
@given(stamp=stamps, frame=names, positions=st.lists(st.tuples(finite, finite, finite), max_size=30))
def test_pose_array(stamp, frame, positions):
    xyz = np.array(positions, dtype=float).reshape(-1, 3)
    msg = roundtrip(cdr_write.pose_array(stamp, frame, xyz), 'geometry_msgs/msg/PoseArray')
    assert stamp_ns(msg.header) == stamp and msg.header.frame_id == frame
    assert [(p.position.x, p.position.y, p.position.z) for p in msg.poses] == [tuple(p) for p in xyz]
    assert all((p.orientation.x, p.orientation.w) == (0.0, 1.0) for p in msg.poses)


@FUZZ
@given(stamp=stamps, frame=names, child=names, values=st.lists(finite, min_size=85, max_size=85),
       twist=st.booleans())
def test_odometry(stamp, frame, child, values, twist):
    v = np.array(values)
    q = Rotation.from_rotvec(v[3:6] * 1e-6).as_quat()
    twist_cov = v[49:85].reshape(6, 6) if twist else None
    data = cdr_write.odometry(stamp, frame, child, v[:3], q, v[7:43].reshape(6, 6), v[43:46],
                              v[46:49], twist_cov)
    msg = roundtrip(data, 'nav_msgs/msg/Odometry')
    assert (stamp_ns(msg.header), msg.header.frame_id, msg.child_frame_id) == (stamp, frame, child)
    pose = msg.pose.pose
    assert [pose.position.x, pose.position.y, pose.position.z] == v[:3].tolist()
    assert [pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w] == q.tolist()
    assert msg.pose.covariance.tolist() == v[7:43].tolist()
    assert [msg.twist.twist.linear.x, msg.twist.twist.angular.z] == [v[43], v[48]]
    assert msg.twist.covariance.tolist() == (v[49:85].tolist() if twist else [0.0] * 36)


@FUZZ
@given(stamp=stamps, frame=names, values=st.lists(finite, min_size=43, max_size=43))
def test_pose_with_covariance_stamped(stamp, frame, values):
    v = np.array(values)
    q = Rotation.from_rotvec(v[3:6] * 1e-6).as_quat()
    data = cdr_write.pose_with_covariance_stamped(stamp, frame, v[:3], q, v[7:43].reshape(6, 6))
    msg = roundtrip(data, 'geometry_msgs/msg/PoseWithCovarianceStamped')
    assert (stamp_ns(msg.header), msg.header.frame_id) == (stamp, frame)
    pose = msg.pose.pose
    assert [pose.position.x, pose.position.y, pose.position.z] == v[:3].tolist()
    assert [pose.orientation.x, pose.orientation.w] == [q[0], q[3]]
    assert msg.pose.covariance.tolist() == v[7:43].tolist()


@FUZZ
@given(stamp=stamps, frame=names,
       points=st.lists(st.tuples(finite, finite, finite), max_size=40), nan=st.booleans())
def test_point_cloud_xyz32(stamp, frame, points, nan):
    """Our cloud reads back through msg_adapters.pointcloud (the node's own input decoder)."""
    from msg_adapters.cdr import cloud_points, parse_cloud_cdr

    xyz = np.array(points, dtype=np.float32).reshape(-1, 3)
    if nan and len(xyz):
        xyz[0, 1] = np.nan
    msg = roundtrip(cdr_write.point_cloud_xyz32(stamp, frame, xyz), 'sensor_msgs/msg/PointCloud2')
    assert (stamp_ns(msg.header), msg.header.frame_id) == (stamp, frame)
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (1, len(xyz), 12, 12 * len(xyz))
    assert [(f.name, f.offset, f.datatype, f.count) for f in msg.fields] == [
        ('x', 0, 7, 1), ('y', 4, 7, 1), ('z', 8, 7, 1)]
    assert msg.is_dense == (not (nan and len(xyz)))
    back = np.frombuffer(bytes(msg.data), dtype='<f4').reshape(-1, 3)
    assert np.array_equal(back, xyz, equal_nan=True)
    parsed = cloud_points(parse_cloud_cdr(cdr_write.point_cloud_xyz32(stamp, frame, xyz)))
    keep = np.isfinite(xyz).all(axis=1) & xyz.any(axis=1)
    assert np.array_equal(parsed, xyz[keep].astype(float))


def test_odometry_refuses_wrong_sizes_and_stamps():
    with pytest.raises(MessageError):
        cdr_write.odometry(0, 'a', 'b', np.zeros(3), (0, 0, 0, 1), np.zeros((5, 5)), np.zeros(3),
                           np.zeros(3))
    with pytest.raises(MessageError):
        cdr_write.pose_array(2**31 * 10**9, 'a', np.zeros((1, 3)))


@FUZZ
@given(value=st.floats(allow_nan=True, allow_infinity=True))
def test_float64(value):
    msg = TYPESTORE.deserialize_cdr(cdr_write.float64(value), 'std_msgs/msg/Float64')
    assert msg.data == value or (math.isnan(value) and math.isnan(msg.data))


@FUZZ
@given(dims=st.lists(st.tuples(names, st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1)),
                     max_size=3),
       data=st.lists(finite, max_size=20), offset=st.integers(0, 2**32 - 1))
def test_float64_multi_array(dims, data, offset):
    msg = roundtrip(cdr_write.float64_multi_array(dims, np.array(data), offset),
                    'std_msgs/msg/Float64MultiArray')
    assert [(d.label, d.size, d.stride) for d in msg.layout.dim] == dims
    assert msg.layout.data_offset == offset and msg.data.tolist() == data


@FUZZ
@given(stamp=stamps, frame=names,
       statuses=st.lists(st.tuples(st.integers(0, 3), names, names, names,
                                   st.lists(st.tuples(names, names), max_size=4)), max_size=3))
def test_diagnostic_array(stamp, frame, statuses):
    msg = roundtrip(cdr_write.diagnostic_array(stamp, frame, statuses),
                    'diagnostic_msgs/msg/DiagnosticArray')
    assert [(s.level, s.name, s.message, s.hardware_id, [(kv.key, kv.value) for kv in s.values])
            for s in msg.status] == [(lv, n, m, h, list(kv)) for lv, n, m, h, kv in statuses]


@FUZZ
@given(stamp=stamps, frame=names, ns=names, marker_id=st.integers(-2**31, 2**31 - 1),
       points=st.one_of(st.none(), st.lists(st.tuples(finite, finite, finite), max_size=10)),
       count=st.integers(0, 3))
def test_marker_array(stamp, frame, ns, marker_id, points, count):
    xyz = None if points is None else np.array(points, dtype=float).reshape(-1, 3)
    w = cdr_write.CdrWriter()
    w.u32(count)
    pose = np.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0])
    for _ in range(count):
        cdr_write.marker(w, stamp, frame, ns, marker_id, 5, 0, pose, (0.1, 0.2, 0.3),
                         (0.25, 0.5, 0.75, 1.0), xyz)
    msg = roundtrip(w.bytes(), 'visualization_msgs/msg/MarkerArray')
    assert len(msg.markers) == count
    for m in msg.markers:
        assert (stamp_ns(m.header), m.header.frame_id, m.ns, m.id, m.type) == (stamp, frame, ns,
                                                                              marker_id, 5)
        assert (m.scale.y, m.color.b, m.pose.position.z) == (0.2, 0.75, 3.0)
        got = [(p.x, p.y, p.z) for p in m.points]
        assert got == ([] if xyz is None else [tuple(p) for p in xyz])


def test_samples_message():
    samples = [SampleOut(5, 0, 0.5, 'map', True), SampleOut(5, 1, math.nan, 'gated', False)]
    msg = roundtrip(samples_message(samples), SAMPLES[1])
    data = msg.data.reshape(-1, 4)
    assert data[0].tolist() == [0.0, 0.5, 0.0, 1.0]
    assert data[1, 0] == 1.0 and math.isnan(data[1, 1]) and data[1, 2:].tolist() == [2.0, 0.0]


@pytest.mark.parametrize('name', ['walk', 'reset', 'crowd'])
def test_every_output_message_of_a_scenario_round_trips(name):
    """The node's and the replay's messages for a whole simulated run (markers with the path and
    the ground plane, diagnostics with rejections, odometry across a SLAM reset)."""
    sc = make_scenario(name, seed=1, duration=12.0)
    params = HacParams()
    cal = Calibrator(params)
    messages = OutputMessages(params)
    seen: dict[str, int] = {}
    slow: dict[str, list[int]] = {'camera_path': [], 'ground_plane': []}
    cal.add_camera_info(sc.K, sc.width, sc.height)
    for stamp, kind, payload in scenario_events(sc):
        add = {'map': cal.add_map, 'pose': cal.add_pose, 'joints': cal.add_joints}[kind]
        for output in add(stamp, *payload):
            for m in messages.convert(output):
                msg = TYPESTORE.deserialize_cdr(m.msg, m.msgtype)
                assert bytes(TYPESTORE.serialize_cdr(msg, m.msgtype)) == m.msg
                seen[m.topic] = seen.get(m.topic, 0) + 1
                if m.topic == MARKERS[0]:
                    kinds = {mk.ns for mk in msg.markers}
                    assert 'skeleton' in kinds
                    for ns in kinds & set(slow):
                        slow[ns].append(m.stamp_ns)
                if m.topic == DIAGNOSTICS[0]:
                    assert msg.status[0].values[0].key == 'converged'
    assert set(seen) == {'hac/odometry', 'hac/pose', 'hac/cloud', 'hac/human_joints',
                         'hac/scale', 'hac/markers', '/diagnostics'}
    # the path and the plane are refreshed about once a second of stamp time, not every frame
    for ns, stamps in slow.items():
        assert len(stamps) >= 5, ns
        assert min(np.diff(stamps)) >= 1_000_000_000, ns
        assert len(stamps) < seen['hac/markers'] / 10, ns
    # the metric map is latched and sent again only on a scale change or a new segment
    assert 1 <= seen['hac/cloud'] < seen['hac/markers'] / 10
