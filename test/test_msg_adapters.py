"""msg_adapters against real message classes: rosbags dataclasses and rclpy's generated classes."""
from __future__ import annotations

import array
import struct
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import msg_adapters as ma
from msg_adapters import MessageError

rclpy = pytest.importorskip  # alias for readability below


def all_types():
    """rosbags always; rclpy when importable (a plain `pip install .` has no ROS)."""
    out = [pytest.param(ma.rosbags_types(), id='rosbags')]
    try:
        import geometry_msgs.msg  # noqa: F401
        out.append(pytest.param(ma.rclpy_types(), id='rclpy'))
    except ImportError:
        out.append(pytest.param(None, id='rclpy', marks=pytest.mark.skip('rclpy not installed')))
    return out


def cdr_round_trip(msg, msgtype, types):
    """Serialise and deserialise with the flavour's own CDR implementation."""
    if types.is_rosbags:
        from rosbags.typesys import Stores, get_typestore
        store = get_typestore(Stores.ROS2_JAZZY)
        return store.deserialize_cdr(store.serialize_cdr(msg, msgtype), msgtype)
    from rclpy.serialization import deserialize_message, serialize_message
    return deserialize_message(serialize_message(msg), type(msg))


@pytest.mark.parametrize('types', all_types())
def test_round_trips_through_cdr(types):
    rng = np.random.default_rng(0)
    points = rng.normal(size=(500, 3))
    cloud = cdr_round_trip(ma.xyz_to_cloud(points, 123, 'map', types, np.float64),
                           'sensor_msgs/msg/PointCloud2', types)
    np.testing.assert_array_equal(ma.cloud_to_xyz(cloud), points)
    assert ma.stamp_to_ns(cloud.header.stamp) == 123 and cloud.header.frame_id == 'map'

    R = Rotation.random(random_state=3).as_matrix()
    c = np.array([1.5, -2.0, 0.25])
    for msg, name in [(ma.rt_to_pose_stamped(R, c, 5, 'map', types), 'geometry_msgs/msg/PoseStamped'),
                      (ma.rt_to_odometry(R, c, 5, 'map', 'cam', types, covariance=np.eye(6),
                                         linear=[1, 2, 3]), 'nav_msgs/msg/Odometry')]:
        back = cdr_round_trip(msg, name, types)
        R2, c2 = ma.pose_msg_to_rt(back)
        np.testing.assert_allclose(R2, R, atol=1e-12)
        np.testing.assert_allclose(c2, c, atol=1e-12)

    joints = rng.normal(size=(3, 24, 3))
    back = cdr_round_trip(ma.joints_to_pose_array(joints, 7, 'camera', types),
                          'geometry_msgs/msg/PoseArray', types)
    np.testing.assert_array_equal(ma.pose_array_to_joints(back), joints)

    K = np.array([[520.0, 0, 320.5], [0, 521.0, 240.5], [0, 0, 1]])
    back = cdr_round_trip(ma.intrinsics_to_camera_info(K, 640, 480, 1, 'camera', types),
                          'sensor_msgs/msg/CameraInfo', types)
    K2, w, h = ma.camera_info_to_intrinsics(back)
    np.testing.assert_array_equal(K2, K)
    assert (w, h) == (640, 480)


def structured_cloud(types, records: np.ndarray, fields, height: int, row_pad: int, big: bool):
    """A PointCloud2 built by hand from a structured array (not by xyz_to_cloud)."""
    PointField = types.get('sensor_msgs/msg/PointField')
    itemsize = records.dtype.itemsize
    width = len(records) // height
    rows = records.tobytes()
    row_bytes = width * itemsize
    data = b''.join(rows[r * row_bytes:(r + 1) * row_bytes] + b'\xab' * row_pad for r in range(height))
    payload = np.frombuffer(data, np.uint8) if types.is_rosbags else array.array('B', data)
    return types.get('sensor_msgs/msg/PointCloud2')(
        header=ma.make_header(0, 'map', types), height=height, width=width,
        fields=[PointField(name=n, offset=o, datatype=d, count=1) for n, o, d in fields],
        is_bigendian=big, point_step=itemsize, row_step=row_bytes + row_pad, data=payload,
        is_dense=False)


@pytest.mark.parametrize('types', all_types())
@pytest.mark.parametrize('big', [False, True])
def test_cloud_with_reordered_fields_padding_and_rows(types, big):
    e = '>' if big else '<'
    dtype = np.dtype({'names': ['intensity', 'z', 'rgb', 'x', 'y'],
                      'formats': [e + 'f4', e + 'f8', e + 'u4', e + 'f4', e + 'f8'],
                      'offsets': [0, 4, 12, 16, 24], 'itemsize': 40})
    rng = np.random.default_rng(1)
    records = np.zeros(12, dtype=dtype)
    xyz = rng.normal(size=(12, 3)).astype(np.float32).astype(float)
    records['x'], records['y'], records['z'] = xyz.T
    records['x'][3] = np.nan  # dropped
    records['x'][5] = records['y'][5] = records['z'][5] = 0.0  # (0,0,0): dropped
    records['z'][7] = np.inf  # dropped
    fields = [('intensity', 0, 7), ('z', 4, 8), ('rgb', 12, 6), ('x', 16, 7), ('y', 24, 8)]
    msg = structured_cloud(types, records, fields, height=3, row_pad=6, big=big)
    got = ma.cloud_to_xyz(msg)
    keep = np.ones(12, bool)
    keep[[3, 5, 7]] = False
    np.testing.assert_array_equal(got, xyz[keep])


def test_cloud_errors_are_message_errors():
    types = ma.rosbags_types()
    good = ma.xyz_to_cloud(np.ones((4, 3)), 0, 'map', types)
    PointField = types.get('sensor_msgs/msg/PointField')

    def variant(**changes):
        fields = {k: getattr(good, k) for k in ('header', 'height', 'width', 'fields', 'is_bigendian',
                                                'point_step', 'row_step', 'data', 'is_dense')}
        fields.update(changes)
        return types.get('sensor_msgs/msg/PointCloud2')(**fields)

    cases = {
        'no "z" field': variant(fields=good.fields[:2]),
        'point_step must be > 0': variant(point_step=0),
        'does not fit': variant(point_step=8, row_step=32, data=good.data[:32]),
        'data has': variant(data=good.data[:-1]),
        'datatype 5': variant(fields=[*good.fields[:2], PointField(name='z', offset=8, datatype=5,
                                                                   count=1)]),
        'row_step': variant(row_step=11),
    }
    for text, msg in cases.items():
        with pytest.raises(MessageError, match=text):
            ma.cloud_to_xyz(msg)


def reference_decode(data: bytes, fields, point_step, width, height, row_step, big):
    """An independent, slow decoder (struct) for the fuzz test."""
    by = {f[0]: f for f in fields}
    out = []
    for r in range(height):
        for i in range(width):
            base = r * row_step + i * point_step
            p = []
            for axis in 'xyz':
                _, off, dt = by[axis]
                fmt = ('>' if big else '<') + ('f' if dt == 7 else 'd')
                p.append(struct.unpack_from(fmt, data, base + off)[0])
            if all(np.isfinite(p)) and any(v != 0.0 for v in p):
                out.append(p)
    return np.array(out, dtype=float).reshape(-1, 3)


DECODED: list[int] = []


@settings(max_examples=300, deadline=None)
@given(data=st.data())
def test_fuzzed_clouds_decode_correctly_or_raise_message_error(data):
    """A valid layout (random field order, offsets, types, padding, rows, endianness), then
    sometimes one corruption: the result is the reference decoding or a MessageError."""
    types = ma.rosbags_types()
    names = data.draw(st.permutations(['x', 'y', 'z', 'rgb']))
    dts = {n: data.draw(st.sampled_from([7, 8])) for n in names}
    offsets, cursor = {}, 0
    for n in names:
        cursor += data.draw(st.integers(0, 3))
        offsets[n] = cursor
        cursor += 4 if dts[n] == 7 else 8
    point_step = cursor + data.draw(st.integers(0, 5))
    width, height = data.draw(st.integers(0, 6)), data.draw(st.integers(0, 3))
    row_step = width * point_step + data.draw(st.integers(0, 7))
    length = row_step * height
    corrupt = data.draw(st.sampled_from([None, None, 'offset', 'step', 'row', 'length', 'type',
                                         'missing']))
    if corrupt == 'offset':
        offsets['x'] = point_step - 1
    elif corrupt == 'step':
        point_step = data.draw(st.integers(0, 4))
    elif corrupt == 'row':
        row_step = max(0, width * point_step - data.draw(st.integers(1, 5)))
    elif corrupt == 'length':
        length = max(0, length + data.draw(st.sampled_from([-1, 1, 7])))
    elif corrupt == 'type':
        dts['y'] = data.draw(st.sampled_from([1, 2, 5, 6]))
    elif corrupt == 'missing':
        names.remove(data.draw(st.sampled_from(['x', 'y', 'z'])))
    raw = data.draw(st.binary(min_size=length, max_size=length))
    big = data.draw(st.booleans())
    PointField = types.get('sensor_msgs/msg/PointField')
    pf = [PointField(name=n, offset=offsets[n], datatype=dts[n], count=1) for n in names]
    try:
        got = ma.xyz_from_buffer(raw, pf, point_step, width, height, row_step, big)
    except MessageError:
        assert corrupt is not None, 'a valid cloud was refused'
        return
    DECODED.append(len(got))
    ref_fields = [(n, offsets[n], dts[n]) for n in names]
    expected = reference_decode(raw, ref_fields, point_step, width, height, row_step, big)
    np.testing.assert_array_equal(got, expected)


def test_the_fuzzer_reached_the_decoder():
    """Guards the fuzz test above against only ever exercising the error paths."""
    assert len(DECODED) >= 10 and sum(DECODED) > 0


@settings(max_examples=200, deadline=None)
@given(n=st.integers(0, 100), q=st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64),
                                          min_size=4, max_size=4))
def test_fuzzed_pose_arrays_and_quaternions(n, q):
    types = ma.rosbags_types()
    Pose, Point, Quat = (types.get('geometry_msgs/msg/Pose'), types.get('geometry_msgs/msg/Point'),
                         types.get('geometry_msgs/msg/Quaternion'))
    poses = [Pose(position=Point(x=float(i), y=0.0, z=1.0), orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0))
             for i in range(n)]
    msg = types.get('geometry_msgs/msg/PoseArray')(header=ma.make_header(0, 'c', types), poses=poses)
    if n % 24:
        with pytest.raises(MessageError, match='multiple of 24'):
            ma.pose_array_to_joints(msg)
    else:
        assert ma.pose_array_to_joints(msg).shape == (n // 24, 24, 3)
    pose = Pose(position=Point(x=0.0, y=0.0, z=0.0), orientation=Quat(x=q[0], y=q[1], z=q[2], w=q[3]))
    norm = float(np.linalg.norm(q)) if np.all(np.isfinite(q)) else np.nan
    if np.isfinite(norm) and abs(norm - 1) <= 1e-2:
        R, _ = ma.pose_to_rt(pose)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)
    else:
        with pytest.raises(MessageError):
            ma.pose_to_rt(pose)


def test_importing_the_adapters_does_not_import_rclpy():
    code = 'import sys, msg_adapters; assert "rclpy" not in sys.modules'
    subprocess.run([sys.executable, '-c', code], check=True)
