"""msg_adapters against real message classes: rosbags dataclasses and rclpy's generated classes.

Round trips numpy → message → (CDR bytes →) message → numpy for both flavours; PointCloud2 layouts
built by hand; every malformed input is a MessageError. The hypothesis fuzzing against independent
slow reference decoders is in test_msg_adapters_fuzz.py.
"""
from __future__ import annotations

import array
import math
import subprocess
import sys
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import msg_adapters as ma
from msg_adapters import MessageError

try:
    import rclpy.serialization  # noqa: F401
    HAVE_RCLPY = True
except ImportError:
    HAVE_RCLPY = False
NEEDS_RCLPY = pytest.mark.skipif(not HAVE_RCLPY, reason='rclpy (ROS 2 Jazzy) is not importable')
JAZZY = 'ROS2_JAZZY'


def flavours() -> list[Any]:
    """rosbags always; rclpy when importable (a plain ``pip install .`` has no ROS)."""
    return [pytest.param('rosbags', id='rosbags'),
            pytest.param('rclpy', id='rclpy', marks=[NEEDS_RCLPY, pytest.mark.ros])]


@pytest.fixture(params=flavours())
def types(request: pytest.FixtureRequest) -> ma.MessageTypes:
    return ma.rosbags_types() if request.param == 'rosbags' else ma.rclpy_types()


def typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(getattr(Stores, JAZZY))


def cdr_round_trip(msg: Any, msgtype: str, types: ma.MessageTypes) -> Any:
    """Serialise and deserialise with the flavour's own CDR implementation."""
    if types.is_rosbags:
        store = typestore()
        return store.deserialize_cdr(store.serialize_cdr(msg, msgtype), msgtype)
    from rclpy.serialization import deserialize_message, serialize_message
    return deserialize_message(serialize_message(msg), type(msg))


def u8(data: bytes, types: ma.MessageTypes) -> Any:
    """A uint8[] field value as each flavour holds it."""
    return np.frombuffer(data, np.uint8).copy() if types.is_rosbags else array.array('B', data)


def textbook_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Unit quaternion (x, y, z, w) → rotation matrix, written out (independent of scipy)."""
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


# ---------------------------------------------------------------------------- round trips
@pytest.mark.parametrize('dtype', [np.float32, np.float64])
def test_point_cloud_round_trip_through_cdr(types, dtype):
    points = np.random.default_rng(0).normal(size=(500, 3)) * 40.0
    msg = ma.xyz_to_cloud(points, 1_700_000_000_123_456_789, 'map', types, dtype)
    assert (msg.height, msg.width, msg.is_bigendian, msg.is_dense) == (1, 500, False, True)
    back = cdr_round_trip(msg, 'sensor_msgs/msg/PointCloud2', types)
    np.testing.assert_array_equal(ma.cloud_to_xyz(back), points.astype(dtype).astype(np.float64))
    assert ma.stamp_to_ns(back.header.stamp) == 1_700_000_000_123_456_789
    assert back.header.frame_id == 'map'
    assert ma.cloud_to_xyz(ma.xyz_to_cloud(np.zeros((0, 3)), 0, 'map', types)).shape == (0, 3)


def test_point_cloud_does_not_alias_the_callers_array(types):
    points = np.ones((4, 3))
    msg = ma.xyz_to_cloud(points, 0, 'map', types, np.float64)
    points[:] = 7.0
    np.testing.assert_array_equal(ma.cloud_to_xyz(msg), np.ones((4, 3)))


def test_poses_round_trip_through_cdr(types):
    R = Rotation.random(random_state=3).as_matrix()
    c = np.array([1.5, -2.0, 0.25])
    cov = np.diag([1.0, 2, 3, 4, 5, 6])
    msgs = {
        'geometry_msgs/msg/PoseStamped': ma.rt_to_pose_stamped(R, c, 5, 'map', types),
        'nav_msgs/msg/Odometry': ma.rt_to_odometry(R, c, 5, 'map', 'cam', types, covariance=cov,
                                                   linear=[1, 2, 3], angular=np.array([4., 5, 6])),
        'geometry_msgs/msg/PoseWithCovarianceStamped': ma.rt_to_pose_with_covariance_stamped(
            R, c, 5, 'map', types, covariance=cov),
        'geometry_msgs/msg/Pose': ma.rt_to_pose(R, c, types),
    }
    for name, msg in msgs.items():
        back = cdr_round_trip(msg, name, types)
        R2, c2 = ma.pose_msg_to_rt(back)
        np.testing.assert_allclose(R2, R, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(c2, c, atol=1e-12, err_msg=name)
    odom = cdr_round_trip(msgs['nav_msgs/msg/Odometry'], 'nav_msgs/msg/Odometry', types)
    assert odom.child_frame_id == 'cam' and odom.header.frame_id == 'map'
    np.testing.assert_array_equal(np.reshape(odom.pose.covariance, (6, 6)), cov)
    twist = odom.twist.twist
    assert (twist.linear.x, twist.linear.y, twist.linear.z) == (1, 2, 3)
    assert (twist.angular.x, twist.angular.y, twist.angular.z) == (4, 5, 6)
    np.testing.assert_array_equal(odom.twist.covariance, np.zeros(36))
    stamped = cdr_round_trip(msgs['geometry_msgs/msg/PoseWithCovarianceStamped'],
                             'geometry_msgs/msg/PoseWithCovarianceStamped', types)
    assert (ma.stamp_to_ns(stamped.header.stamp), stamped.header.frame_id) == (5, 'map')
    np.testing.assert_array_equal(np.reshape(stamped.pose.covariance, (6, 6)), cov)

    tf = cdr_round_trip(ma.rt_to_transform_stamped(R, c, 9, 'world', 'camera', types),
                        'geometry_msgs/msg/TransformStamped', types)
    q, t = tf.transform.rotation, tf.transform.translation
    np.testing.assert_allclose(textbook_matrix(q.x, q.y, q.z, q.w), R, atol=1e-12)
    np.testing.assert_allclose([t.x, t.y, t.z], c)
    assert (tf.header.frame_id, tf.child_frame_id, ma.stamp_to_ns(tf.header.stamp)) == (
        'world', 'camera', 9)
    assert q.w >= 0  # canonical hemisphere


def test_joints_round_trip_through_cdr(types):
    joints = np.random.default_rng(2).normal(size=(3, 24, 3))
    joints[1, 4, 2] = np.nan  # non-finite values pass through both ways
    joints[2, 0, 0] = -np.inf
    msg = ma.joints_to_pose_array(joints, 7, 'camera', types)
    assert len(msg.poses) == 72
    assert all(p.orientation.w == 1.0 and p.orientation.x == 0.0 for p in msg.poses)
    back = cdr_round_trip(msg, 'geometry_msgs/msg/PoseArray', types)
    np.testing.assert_array_equal(ma.pose_array_to_joints(back), joints)
    one = ma.joints_to_pose_array(joints[0], 8, 'camera', types)  # (24, 3): one person
    np.testing.assert_array_equal(ma.pose_array_to_joints(one), joints[:1])
    empty = cdr_round_trip(ma.joints_to_pose_array(np.zeros((0, 24, 3)), 9, 'camera', types),
                           'geometry_msgs/msg/PoseArray', types)
    assert ma.pose_array_to_joints(empty).shape == (0, 24, 3)


def test_camera_info_round_trip_through_cdr(types):
    K = np.array([[520.0, 0, 320.5], [0, 521.0, 240.5], [0, 0, 1]])
    back = cdr_round_trip(ma.intrinsics_to_camera_info(K, 640, 480, 1, 'camera', types),
                          'sensor_msgs/msg/CameraInfo', types)
    K2, width, height = ma.camera_info_to_intrinsics(back)
    np.testing.assert_array_equal(K2, K)
    assert (width, height) == (640, 480) and back.distortion_model == 'plumb_bob'
    np.testing.assert_array_equal(back.d, np.zeros(5))
    np.testing.assert_array_equal(np.reshape(back.r, (3, 3)), np.eye(3))
    np.testing.assert_array_equal(np.reshape(back.p, (3, 4)), np.hstack([K, np.zeros((3, 1))]))


@pytest.mark.parametrize('ns', [0, 1, 999_999_999, 1_000_000_000, 1_700_000_000_999_999_999])
def test_stamps_round_trip(types, ns):
    back = cdr_round_trip(ma.make_header(ns, 'f', types), 'std_msgs/msg/Header', types)
    assert ma.stamp_to_ns(back.stamp) == ns and 0 <= back.stamp.nanosec < 1_000_000_000


@NEEDS_RCLPY
@pytest.mark.ros
def test_rclpy_and_rosbags_bytes_are_interchangeable():
    """What one flavour serialises, the other reads to the same numbers."""
    from rclpy.serialization import deserialize_message, serialize_message
    store, rb, rc = typestore(), ma.rosbags_types(), ma.rclpy_types()
    points = np.random.default_rng(5).normal(size=(50, 3))
    R, c = Rotation.random(random_state=1).as_matrix(), np.array([3.0, 2.0, 1.0])
    for build, name, read in [
            (lambda t: ma.xyz_to_cloud(points, 11, 'map', t, np.float64),
             'sensor_msgs/msg/PointCloud2', ma.cloud_to_xyz),
            (lambda t: ma.rt_to_odometry(R, c, 12, 'map', 'cam', t), 'nav_msgs/msg/Odometry',
             lambda m: np.vstack(ma.pose_msg_to_rt(m)))]:
        from_rclpy = store.deserialize_cdr(serialize_message(build(rc)), name)
        to_rclpy = deserialize_message(bytes(store.serialize_cdr(build(rb), name)), type(build(rc)))
        np.testing.assert_array_equal(read(from_rclpy), read(build(rb)))
        np.testing.assert_array_equal(read(to_rclpy), read(build(rc)))


# ------------------------------------------------------------------ PointCloud2 layouts by hand
def hand_cloud(types: ma.MessageTypes, records: np.ndarray, fields: list[tuple[str, int, int]],
               height: int, row_pad: int, big: bool) -> Any:
    """A PointCloud2 from a structured array (not from xyz_to_cloud), rows padded by row_pad."""
    PointField = types.get('sensor_msgs/msg/PointField')
    point_step = records.dtype.itemsize
    width = len(records) // height
    rows = records.tobytes()
    row_bytes = width * point_step
    data = b''.join(rows[r * row_bytes:(r + 1) * row_bytes] + b'\xab' * row_pad
                    for r in range(height))
    return types.get('sensor_msgs/msg/PointCloud2')(
        header=ma.make_header(0, 'map', types), height=height, width=width,
        fields=[PointField(name=n, offset=o, datatype=d, count=1) for n, o, d in fields],
        is_bigendian=big, point_step=point_step, row_step=row_bytes + row_pad,
        data=u8(data, types), is_dense=False)


@pytest.mark.parametrize('big', [False, True], ids=['little', 'big'])
def test_cloud_with_reordered_mixed_fields_padding_and_padded_rows(types, big):
    e = '>' if big else '<'
    dtype = np.dtype({'names': ['intensity', 'z', 'rgb', 'x', 'y'],
                      'formats': [e + 'f4', e + 'f8', e + 'u4', e + 'f4', e + 'f8'],
                      'offsets': [0, 4, 12, 16, 24], 'itemsize': 40})  # 8 bytes of padding
    records = np.zeros(12, dtype=dtype)
    xyz = np.random.default_rng(1).normal(size=(12, 3)).astype(np.float32).astype(float)
    xyz[3, 0] = np.nan
    xyz[5] = 0.0
    xyz[7, 2] = np.inf
    xyz[9, 1] = -np.inf
    xyz[10, [0, 2]] = 0.0  # (0, y, 0) is a real point: kept
    records['x'], records['y'], records['z'] = xyz.T
    records['intensity'], records['rgb'] = 7.0, 0xFF00FF
    fields = [('intensity', 0, 7), ('z', 4, 8), ('rgb', 12, 6), ('x', 16, 7), ('y', 24, 8)]
    msg = cdr_round_trip(hand_cloud(types, records, fields, height=3, row_pad=6, big=big),
                         'sensor_msgs/msg/PointCloud2', types)
    keep = np.ones(12, bool)
    keep[[3, 5, 7, 9]] = False
    np.testing.assert_array_equal(ma.cloud_to_xyz(msg), xyz[keep])


def test_cloud_float64_xyz_rgb_like_a_slam_wrapper(types):
    dtype = np.dtype([('x', '<f8'), ('y', '<f8'), ('z', '<f8'), ('rgb', '<f4'), ('pad', 'V4')])
    records = np.zeros(6, dtype=dtype)
    xyz = np.random.default_rng(4).normal(size=(6, 3)) * 1e-3  # millimetre-sized SLAM units
    records['x'], records['y'], records['z'] = xyz.T
    msg = hand_cloud(types, records, [('x', 0, 8), ('y', 8, 8), ('z', 16, 8), ('rgb', 24, 7)],
                     height=2, row_pad=0, big=False)
    np.testing.assert_array_equal(ma.cloud_to_xyz(msg), xyz)


def test_raw_cdr_path_decodes_like_the_message_path():
    """parse_cloud_cdr + cloud_points (the node's raw subscription) == cloud_to_xyz."""
    types, store = ma.rosbags_types(), typestore()
    dtype = np.dtype({'names': ['y', 'x', 'z'], 'formats': ['>f4', '>f8', '>f4'],
                      'offsets': [0, 8, 16], 'itemsize': 24})
    records = np.zeros(10, dtype=dtype)
    records['x'], records['y'], records['z'] = np.random.default_rng(8).normal(size=(3, 10))
    msg = hand_cloud(types, records, [('y', 0, 7), ('x', 8, 8), ('z', 16, 7)], height=2,
                     row_pad=3, big=True)
    raw = ma.parse_cloud_cdr(store.serialize_cdr(msg, 'sensor_msgs/msg/PointCloud2'))
    assert (raw.width, raw.height, raw.row_step, raw.is_bigendian) == (5, 2, 123, True)
    np.testing.assert_array_equal(ma.cloud_points(raw), ma.cloud_to_xyz(msg))


@pytest.mark.parametrize('container', [bytes, bytearray, memoryview, list,
                                       lambda b: array.array('B', b),
                                       lambda b: np.frombuffer(b, np.int8)])
def test_cloud_data_containers(container):
    points = np.arange(1.0, 13.0).reshape(4, 3)
    raw = points.astype('<f4').tobytes()
    fields = ma.xyz_to_cloud(points, 0, 'map', ma.rosbags_types()).fields
    got = ma.xyz_from_buffer(container(raw), fields, 12, 4, 1, 48, False)
    np.testing.assert_array_equal(got, points)


def cloud_variant(**changes: Any) -> Any:
    """A valid 4-point float32 rosbags cloud with some fields replaced."""
    types = ma.rosbags_types()
    good = ma.xyz_to_cloud(np.ones((4, 3)), 0, 'map', types)
    fields = {k: getattr(good, k) for k in ('header', 'height', 'width', 'fields', 'is_bigendian',
                                            'point_step', 'row_step', 'data', 'is_dense')}
    fields.update(changes)
    return types.get('sensor_msgs/msg/PointCloud2')(**fields)


def point_field(name: str, offset: int, datatype: int = 7, count: int = 1) -> Any:
    return ma.rosbags_types().get('sensor_msgs/msg/PointField')(name=name, offset=offset,
                                                                datatype=datatype, count=count)


@pytest.mark.parametrize('text, changes', [
    ('no "z" field', dict(fields=[point_field('x', 0), point_field('y', 4)])),
    ('field "z" has datatype 5', dict(fields=[point_field('x', 0), point_field('y', 4),
                                              point_field('z', 8, datatype=5)])),
    ('field "y" has count 2', dict(fields=[point_field('x', 0), point_field('y', 4, count=2),
                                           point_field('z', 8)])),
    ('field "x" appears more than once', dict(fields=[point_field('x', 0), point_field('y', 4),
                                                      point_field('z', 8), point_field('x', 4)])),
    ('field "z" .offset 8, 8 bytes. does not fit in point_step 12',
     dict(fields=[point_field('x', 0), point_field('y', 4), point_field('z', 8, datatype=8)])),
    ('point_step must be > 0', dict(point_step=0)),
    ('data has 47 bytes; expected row_step 48', dict(data=np.ones(47, np.uint8))),
    ('data has 49 bytes', dict(data=np.ones(49, np.uint8))),
    ('row_step 40 < width 4 x point_step 12', dict(row_step=40, data=np.ones(40, np.uint8))),
    ('data must be uint8 bytes, got a float64 array', dict(data=np.ones(6))),
    ('data must be bytes .ints 0..255.', dict(data=[300] * 48)),
    ('width must be an integer', dict(width=4.0)),
])
def test_malformed_clouds_are_message_errors_that_say_why(text, changes):
    with pytest.raises(MessageError, match=text):
        ma.cloud_to_xyz(cloud_variant(**changes))


def test_not_a_cloud_is_a_message_error():
    with pytest.raises(MessageError, match='PointCloud2: missing field'):
        ma.cloud_to_xyz(ma.make_header(0, 'map', ma.rosbags_types()))
    with pytest.raises(MessageError, match='fields must be PointFields'):
        ma.xyz_from_buffer(b'', [object()], 12, 0, 0, 0, False)
    with pytest.raises(MessageError, match=r'points must be \(N, 3\)'):
        ma.xyz_to_cloud(np.ones((4, 2)), 0, 'map', ma.rosbags_types())
    with pytest.raises(MessageError, match='float32 or float64'):
        ma.xyz_to_cloud(np.ones((4, 3)), 0, 'map', ma.rosbags_types(), np.int32)


# ------------------------------------------------------------- other readers' and builders' errors
def rosbags_pose(position: tuple[float, float, float],
                 quat: tuple[float, float, float, float]) -> Any:
    t = ma.rosbags_types()
    x, y, z = position
    qx, qy, qz, qw = quat
    return t.get('geometry_msgs/msg/Pose')(
        position=t.get('geometry_msgs/msg/Point')(x=x, y=y, z=z),
        orientation=t.get('geometry_msgs/msg/Quaternion')(x=qx, y=qy, z=qz, w=qw))


@pytest.mark.parametrize('position, quat, text', [
    ((0.0, math.nan, 0.0), (0, 0, 0, 1.0), 'position is not finite'),
    ((0.0, 0.0, 0.0), (0, 0, 0, 0.0), 'has norm 0'),
    ((0.0, 0.0, 0.0), (0, 0, 0, 1.01), 'has norm 1.01'),
    ((0.0, 0.0, 0.0), (0, 0, 0, 0.998), 'has norm 0.998'),
    ((0.0, 0.0, 0.0), (0, math.inf, 0, 1.0), 'not finite'),
])
def test_bad_poses_are_message_errors(position, quat, text):
    with pytest.raises(MessageError, match=text):
        ma.pose_to_rt(rosbags_pose(position, quat))


def test_a_rounded_quaternion_is_normalised():
    q = np.array([0.1, -0.2, 0.3, 0.9])
    q = q / np.linalg.norm(q) * (1 + 8e-4)
    R, c = ma.pose_to_rt(rosbags_pose((1.0, 2.0, 3.0), tuple(q)))
    np.testing.assert_allclose(R, textbook_matrix(*(q / np.linalg.norm(q))), atol=1e-12)
    np.testing.assert_array_equal(c, [1, 2, 3])


def test_rotations_become_canonical_unit_quaternions():
    """w >= 0 (one of the two quaternions of a rotation), unit norm, the same rotation back."""
    for R in Rotation.random(200, random_state=7).as_matrix():
        q = ma.matrix_to_quat(R)
        assert q[3] >= 0 and math.isclose(math.hypot(*q), 1.0, abs_tol=1e-12)
        np.testing.assert_allclose(textbook_matrix(*q), R, atol=1e-12)
        assert all(type(v) is float for v in q)  # rclpy float fields refuse numpy scalars


def test_pose_dispatch_refuses_messages_without_a_pose():
    t = ma.rosbags_types()
    for msg in (ma.make_header(0, 'map', t), t.get('std_msgs/msg/Float64')(data=1.0), None):
        with pytest.raises(MessageError, match='expected a Pose, PoseStamped'):
            ma.pose_msg_to_rt(msg)


def test_builders_refuse_what_is_not_a_pose():
    t = ma.rosbags_types()
    with pytest.raises(MessageError, match='not a rotation matrix'):
        ma.rt_to_pose(np.diag([1.0, 1.0, -1.0]), np.zeros(3), t)  # a reflection
    with pytest.raises(MessageError, match='not a rotation matrix'):
        ma.rt_to_pose_stamped(2 * np.eye(3), np.zeros(3), 0, 'map', t)
    with pytest.raises(MessageError, match=r'\(3, 3\)'):
        ma.rt_to_transform_stamped(np.eye(4), np.zeros(3), 0, 'map', 'cam', t)
    with pytest.raises(MessageError, match='position is not finite'):
        ma.rt_to_pose(np.eye(3), [0.0, np.nan, 0.0], t)
    with pytest.raises(MessageError, match='covariance: expected shape'):
        ma.rt_to_odometry(np.eye(3), np.zeros(3), 0, 'map', 'cam', t, covariance=np.eye(3))
    with pytest.raises(MessageError, match='linear velocity: expected shape'):
        ma.rt_to_odometry(np.eye(3), np.zeros(3), 0, 'map', 'cam', t, linear=[1.0, 2.0])
    with pytest.raises(MessageError, match='PoseWithCovarianceStamped: covariance'):
        ma.rt_to_pose_with_covariance_stamped(np.eye(3), np.zeros(3), 0, 'map', t,
                                              covariance=np.eye(5))


def test_bad_joints_are_message_errors():
    t = ma.rosbags_types()
    msg = ma.joints_to_pose_array(np.zeros((2, 24, 3)), 0, 'camera', t)
    msg.poses = msg.poses[:47]
    with pytest.raises(MessageError, match='47 poses is not a multiple of 24'):
        ma.pose_array_to_joints(msg)
    with pytest.raises(MessageError, match=r'expected \(P, K, 3\)'):
        ma.joints_to_pose_array(np.zeros((23, 2)), 0, 'camera', t)
    coco = ma.joints_to_pose_array(np.zeros((3, 17, 3)), 0, 'camera', t)  # any layout's K
    assert ma.pose_array_to_joints(coco, 17).shape == (3, 17, 3)
    with pytest.raises(MessageError, match='expected a poses sequence'):
        ma.pose_array_to_joints(ma.make_header(0, 'camera', t))


@pytest.mark.parametrize('k, width, height, text', [
    ([0.0, 0, 320, 0, 500, 240, 0, 0, 1], 640, 480, 'fx = 0.0'),
    ([500, 0, 320, 0, -1, 240, 0, 0, 1], 640, 480, 'fy = -1.0'),
    ([500, 0, math.nan, 0, 500, 240, 0, 0, 1], 640, 480, 'K is not finite'),
    ([500, 0, 320, 0, 500, 240, 0, 0, 1], 0, 480, 'width must be > 0'),
    ([500, 0, 320, 0, 500, 240, 0, 0, 1], 640, 0, 'height must be > 0'),
    ([500, 0, 320, 0, 500, 240], 640, 480, 'K must have 9 values'),
])
def test_bad_camera_info_is_a_message_error(k, width, height, text):
    t = ma.rosbags_types()
    good = ma.intrinsics_to_camera_info(np.diag([500.0, 500.0, 1.0]), 640, 480, 0, 'cam', t)
    fields = {f: getattr(good, f) for f in good.__dataclass_fields__}
    fields.update(k=np.array(k, dtype=float), width=width, height=height)
    with pytest.raises(MessageError, match=text):
        ma.camera_info_to_intrinsics(t.get('sensor_msgs/msg/CameraInfo')(**fields))


def test_bad_stamps_and_type_names_are_message_errors():
    t = ma.rosbags_types()
    with pytest.raises(MessageError, match=r'nanosec must be in \[0, 1e9\)'):
        ma.stamp_to_ns(t.get('builtin_interfaces/msg/Time')(sec=1, nanosec=1_000_000_000))
    with pytest.raises(MessageError, match='negative time'):  # an unset clock: not a ROS time
        ma.stamp_to_ns(t.get('builtin_interfaces/msg/Time')(sec=-5, nanosec=0))
    cloud = ma.xyz_to_cloud(np.ones((2, 3)), 0, 'map', t)
    cloud.header.stamp.sec = -5
    with pytest.raises(MessageError, match='negative time'):  # the node's raw map path
        ma.parse_cloud_cdr(typestore().serialize_cdr(cloud, 'sensor_msgs/msg/PointCloud2'))
    with pytest.raises(MessageError, match='int32 seconds'):
        ma.ns_to_stamp(2**31 * 1_000_000_000, t)
    for ns in (-1, -1_500_000_000):
        with pytest.raises(MessageError, match='negative time'):
            ma.ns_to_stamp(ns, t)
    with pytest.raises(MessageError, match='integer nanoseconds'):
        ma.ns_to_stamp(1.5e9, t)
    with pytest.raises(MessageError, match='unknown to the rosbags'):
        t.get('geometry_msgs/msg/NoSuchMessage')
    assert t.get('geometry_msgs/PoseStamped') is t.get('geometry_msgs/msg/PoseStamped')


# ------------------------------------------------------------------------------------ imports
def test_importing_the_adapters_imports_no_ros():
    code = ('import sys, msg_adapters; '
            'assert "rclpy" not in sys.modules, "rclpy imported"; '
            'assert not any(m.endswith("_msgs") or m.endswith("_msgs.msg") for m in sys.modules)')
    subprocess.run([sys.executable, '-c', code], check=True)


# ================================================================================ images
@pytest.mark.parametrize('flavour', flavours())
def test_images_of_every_encoding_read_as_rgb_rows_padding_ignored(flavour):
    """sensor_msgs/Image → (H, W, 3) RGB for rgb8, bgr8, mono8, rgba8, bgra8, rows padded to a
    longer step; a wrong encoding, no pixels or too few bytes raise ImageError with its reason."""
    from msg_adapters.image import ImageError, image_to_rgb, rgb_to_image

    types = ma.rosbags_types() if flavour == 'rosbags' else ma.rclpy_types()
    rgb = np.random.default_rng(3).integers(0, 256, (5, 7, 3), dtype=np.uint8)
    for encoding in ('rgb8', 'bgr8'):
        np.testing.assert_array_equal(image_to_rgb(rgb_to_image(rgb, 1, 'c', types, encoding)),
                                      rgb)
    mono = image_to_rgb(rgb_to_image(rgb, 1, 'c', types, 'mono8'))
    np.testing.assert_array_equal(mono[..., 0], rgb.mean(axis=2).round())
    for encoding, pixel in (('rgba8', [0, 1, 2, 3]), ('bgra8', [2, 1, 0, 3])):
        msg = rgb_to_image(rgb, 1, 'c', types)
        step = 7 * 4 + 6  # padded rows
        data = np.zeros((5, step), dtype=np.uint8)
        data[:, :28] = np.concatenate([rgb, np.full((5, 7, 1), 255, np.uint8)], axis=2)[
            :, :, pixel].reshape(5, 28)
        msg.encoding, msg.step = encoding, step
        msg.data = data.reshape(-1) if types.is_rosbags else data.tobytes()
        np.testing.assert_array_equal(image_to_rgb(msg), rgb)
    for change, reason in ((dict(encoding='16UC1'), 'wrong_encoding'),
                           (dict(height=0), 'empty_image'),
                           (dict(step=3), 'corrupt_image')):
        msg = rgb_to_image(rgb, 1, 'c', types)
        for key, value in change.items():
            setattr(msg, key, value)
        with pytest.raises(ImageError) as error:
            image_to_rgb(msg)
        assert error.value.reason == reason
