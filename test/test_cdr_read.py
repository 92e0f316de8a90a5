"""msg_adapters.cdr's pose and joints parsers against rosbags' deserializer and the message adapters.

The replay feeds the calibrator from these parsers; the node (and every other reader) goes through
message objects. Both must give the same arrays for every message, in either byte order, and the
same refusals for malformed ones.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from msg_adapters import (MessageError, parse_joints_cdr, parse_pose_cdr, pose_array_to_joints,
                          pose_msg_to_rt, rosbags_types, stamp_to_ns)
from msg_adapters.joints import joints_to_pose_array
from msg_adapters.poses import rt_to_odometry, rt_to_pose_stamped

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
TYPES = rosbags_types(TYPESTORE)
FUZZ = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
finite = st.floats(-1e6, 1e6, allow_nan=False)
frames = st.text(st.characters(codec='utf-8', exclude_characters='\x00'), max_size=10)
stamps = st.integers(0, 2**31 * 10**9 - 1)


def pose_message(msgtype: str, R: np.ndarray, c: np.ndarray, stamp: int, frame: str):
    if msgtype == 'nav_msgs/msg/Odometry':
        return rt_to_odometry(R, c, stamp, frame, 'camera', TYPES)
    stamped = rt_to_pose_stamped(R, c, stamp, frame, TYPES)
    if msgtype == 'geometry_msgs/msg/PoseStamped':
        return stamped
    cov = TYPES.get('geometry_msgs/msg/PoseWithCovariance')(pose=stamped.pose, covariance=np.zeros(36))
    return TYPES.get(msgtype)(header=stamped.header, pose=cov)


@FUZZ
@given(msgtype=st.sampled_from(['geometry_msgs/msg/PoseStamped', 'nav_msgs/msg/Odometry',
                                'geometry_msgs/msg/PoseWithCovarianceStamped']),
       rotvec=st.tuples(finite, finite, finite), c=st.tuples(finite, finite, finite),
       stamp=stamps, frame=frames, little=st.booleans())
def test_pose_parser_equals_the_adapter(msgtype, rotvec, c, stamp, frame, little):
    R = Rotation.from_rotvec(np.array(rotvec) * 1e-6).as_matrix()
    msg = pose_message(msgtype, R, np.array(c), stamp, frame)
    data = bytes(TYPESTORE.serialize_cdr(msg, msgtype, little_endian=little))
    raw = parse_pose_cdr(data, msgtype)
    back = TYPESTORE.deserialize_cdr(data, msgtype)
    R_ref, c_ref = pose_msg_to_rt(back)
    assert raw.stamp_ns == stamp_to_ns(back.header.stamp) == stamp
    assert raw.frame_id == frame
    assert raw.child_frame_id == ('camera' if msgtype.endswith('Odometry') else '')
    np.testing.assert_array_equal(raw.c_map, c_ref)
    np.testing.assert_array_equal(raw.R_wc, R_ref)


@FUZZ
@given(people=st.integers(0, 3), seed=st.integers(0, 2**32 - 1), stamp=stamps, frame=frames,
       little=st.booleans(), nan=st.booleans())
def test_joints_parser_equals_the_adapter(people, seed, stamp, frame, little, nan):
    joints = np.random.default_rng(seed).normal(0.0, 3.0, (people, 24, 3))
    if nan and people:
        joints[0, 5, 1] = np.nan  # passes through: the core counts it
    msg = joints_to_pose_array(joints, stamp, frame, TYPES)
    data = bytes(TYPESTORE.serialize_cdr(msg, 'geometry_msgs/msg/PoseArray', little_endian=little))
    got_stamp, got_frame, got = parse_joints_cdr(data)
    ref = pose_array_to_joints(TYPESTORE.deserialize_cdr(data, 'geometry_msgs/msg/PoseArray'))
    assert (got_stamp, got_frame) == (stamp, frame)
    assert got.shape == ref.shape == (people, 24, 3)
    np.testing.assert_array_equal(got, ref)


def test_malformed_bytes_are_message_errors():
    R, c = np.eye(3), np.ones(3)
    data = bytes(TYPESTORE.serialize_cdr(pose_message('geometry_msgs/msg/PoseStamped', R, c, 5, 'map'),
                                         'geometry_msgs/msg/PoseStamped'))
    for cut in (0, 3, 10, len(data) - 1):
        with pytest.raises(MessageError, match='PoseStamped'):
            parse_pose_cdr(data[:cut], 'geometry_msgs/msg/PoseStamped')
    with pytest.raises(MessageError, match='not a pose message'):
        parse_pose_cdr(data, 'sensor_msgs/msg/Imu')
    bad = bytearray(data)
    bad[-8:] = np.float64(0.5).tobytes()  # w = 0.5: not a unit quaternion
    with pytest.raises(MessageError, match='orientation'):
        parse_pose_cdr(bytes(bad), 'geometry_msgs/msg/PoseStamped')
    nan = bytearray(data)
    nan[-56:-48] = np.float64(np.nan).tobytes()  # position x
    with pytest.raises(MessageError, match='not finite'):
        parse_pose_cdr(bytes(nan), 'geometry_msgs/msg/PoseStamped')

    joints = joints_to_pose_array(np.zeros((1, 24, 3)), 5, 'camera', TYPES)
    data = bytes(TYPESTORE.serialize_cdr(joints, 'geometry_msgs/msg/PoseArray'))
    with pytest.raises(MessageError, match='truncated|do not fit'):
        parse_joints_cdr(data[:-8])
    msg23 = TYPES.get('geometry_msgs/msg/PoseArray')(header=joints.header, poses=joints.poses[:23])
    with pytest.raises(MessageError, match='multiple of 24'):
        parse_joints_cdr(bytes(TYPESTORE.serialize_cdr(msg23, 'geometry_msgs/msg/PoseArray')))
    huge = bytearray(data)
    huge[24:28] = (10**9).to_bytes(4, 'little')  # the poses count (after the header): far too big
    with pytest.raises(MessageError):
        parse_joints_cdr(bytes(huge))
    with pytest.raises(MessageError, match='representation'):
        parse_joints_cdr(b'\x07\x07\x00\x00' + data[4:])
