"""msg_adapters fuzzed with hypothesis on rosbags messages: whatever a PointCloud2's header and
bytes, a PoseArray or a pose say, the adapters give what an independent slow reference decoder
(written with ``struct`` and textbook formulas) gives, or raise a MessageError."""
from __future__ import annotations

import array
import math
import struct
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st
from test_msg_adapters import rosbags_pose, textbook_matrix

import msg_adapters as ma
from msg_adapters import MessageError

FUZZ = settings(max_examples=200, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


# ------------------------------------------------------------------------------------ fuzzing
XYZ_SIZES = {7: ('f', 4), 8: ('d', 8)}


def reference_cloud(data: bytes, fields: list[tuple[str, int, int, int]], point_step: int,
                    width: int, height: int, row_step: int, big: bool) -> np.ndarray | None:
    """The PointCloud2 rules, decoded one value at a time with struct; None = must be refused."""
    xyz: dict[str, tuple[int, int, int]] = {}
    for name, offset, datatype, count in fields:
        if name in ('x', 'y', 'z'):
            if name in xyz:
                return None  # ambiguous
            xyz[name] = (offset, datatype, count)
    if point_step == 0 or len(xyz) < 3:
        return None
    for offset, datatype, count in xyz.values():
        if datatype not in XYZ_SIZES or count != 1 or offset + XYZ_SIZES[datatype][1] > point_step:
            return None
    if row_step < width * point_step or len(data) != row_step * height:
        return None
    out = []
    for row in range(height):
        for col in range(width):
            start = row * row_step + col * point_step
            point = []
            for axis in 'xyz':
                offset, datatype, _ = xyz[axis]
                fmt = ('>' if big else '<') + XYZ_SIZES[datatype][0]
                point.append(struct.unpack_from(fmt, data, start + offset)[0])
            if all(math.isfinite(v) for v in point) and any(v != 0.0 for v in point):
                out.append(point)
    return np.array(out, dtype=float).reshape(-1, 3)


@st.composite
def cloud_cases(draw: st.DrawFn) -> dict[str, Any]:
    """Mostly plausible layouts, each header value sometimes replaced by an arbitrary one."""
    def sometimes(plausible: Any, wild: st.SearchStrategy) -> Any:
        return draw(wild) if draw(st.integers(0, 9)) == 9 else plausible

    extras = draw(st.lists(st.sampled_from(['rgb', 'intensity', 'X', '']), unique=True))
    names = list(draw(st.permutations(['x', 'y', 'z', *extras])))
    if draw(st.integers(0, 14)) == 14:
        names.remove(draw(st.sampled_from(['x', 'y', 'z'])))
    if draw(st.integers(0, 14)) == 14:
        names.append(draw(st.sampled_from(['x', 'y', 'z'])))
    fields, cursor = [], 0
    for name in names:
        cursor += draw(st.integers(0, 3))
        datatype = sometimes(draw(st.sampled_from([7, 8])), st.integers(0, 9))
        size = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 8: 8}.get(datatype, 4)
        offset = sometimes(cursor, st.integers(0, 48))
        fields.append((name, offset, datatype, sometimes(1, st.integers(0, 3))))
        cursor += size
    point_step = sometimes(cursor + draw(st.integers(0, 5)), st.integers(0, 48))
    width, height = draw(st.integers(0, 6)), draw(st.integers(0, 3))
    row_step = sometimes(width * point_step + draw(st.integers(0, 7)), st.integers(0, 200))
    length = sometimes(row_step * height, st.integers(0, 600))
    raw = bytearray(draw(st.binary(min_size=length, max_size=length)))
    big = draw(st.booleans())
    # plant zeros, NaN and inf (random bytes are almost never those) where x, y, z are
    for row in range(height):
        for col in range(width):
            special = draw(st.sampled_from([None, None, 0.0, math.nan, math.inf]))
            for name, offset, datatype, _ in fields:
                start = row * row_step + col * point_step + offset
                if special is not None and name in ('x', 'y', 'z') and datatype in XYZ_SIZES:
                    fmt = ('>' if big else '<') + XYZ_SIZES[datatype][0]
                    if start + XYZ_SIZES[datatype][1] <= len(raw):
                        struct.pack_into(fmt, raw, start, special)
    container = draw(st.sampled_from(['bytes', 'numpy', 'array', 'memoryview']))
    return dict(raw=bytes(raw), fields=fields, point_step=point_step, width=width,
                height=height, row_step=row_step, big=big, container=container)


@pytest.fixture(scope='module')
def decoded_sizes():
    """Sizes of the clouds the fuzz test decoded: it must reach the decoder, not only refuse."""
    sizes: list[int] = []
    yield sizes
    assert len(sizes) >= 10 and sum(sizes) > 0, f'fuzzer decoded only {sizes}'


@FUZZ
@given(case=cloud_cases())
def test_fuzzed_clouds_decode_like_the_reference_or_raise_message_error(case, decoded_sizes):
    """Anything a PointCloud2 header can say: the reference decoding, or a MessageError."""
    PointField = ma.rosbags_types().get('sensor_msgs/msg/PointField')
    fields = [PointField(name=n, offset=o, datatype=d, count=c) for n, o, d, c in case['fields']]
    raw = case['raw']
    data = {'bytes': raw, 'numpy': np.frombuffer(raw, np.uint8), 'array': array.array('B', raw),
            'memoryview': memoryview(raw)}[case['container']]
    expected = reference_cloud(raw, case['fields'], case['point_step'], case['width'],
                               case['height'], case['row_step'], case['big'])
    try:
        got = ma.xyz_from_buffer(data, fields, case['point_step'], case['width'], case['height'],
                                 case['row_step'], case['big'])
    except MessageError:
        assert expected is None, 'a valid cloud was refused'
        return
    assert expected is not None, 'a malformed cloud was decoded'
    assert got.dtype == np.float64 and got.shape[1:] == (3,)
    np.testing.assert_array_equal(got, expected)
    decoded_sizes.append(len(got))


finite_or_not = st.floats(allow_nan=True, allow_infinity=True, width=64)


@FUZZ
@given(n=st.integers(0, 100), per_person=st.sampled_from([24, 24, 24, 1, 5]), data=st.data())
def test_fuzzed_pose_arrays(n, per_person, data):
    t = ma.rosbags_types()
    values = data.draw(st.lists(st.tuples(finite_or_not, finite_or_not, finite_or_not),
                                min_size=n, max_size=n))
    Pose, Point, Quat = (t.get('geometry_msgs/msg/Pose'), t.get('geometry_msgs/msg/Point'),
                         t.get('geometry_msgs/msg/Quaternion'))
    msg = t.get('geometry_msgs/msg/PoseArray')(header=ma.make_header(0, 'c', t), poses=[
        Pose(position=Point(x=x, y=y, z=z), orientation=Quat(x=0.0, y=0.0, z=0.0, w=0.0))
        for x, y, z in values])  # orientations are ignored, even invalid ones
    if n % per_person:
        with pytest.raises(MessageError, match=f'multiple of {per_person}'):
            ma.pose_array_to_joints(msg, per_person)
        return
    got = ma.pose_array_to_joints(msg, per_person)
    assert got.shape == (n // per_person, per_person, 3) and got.dtype == np.float64
    np.testing.assert_array_equal(got.reshape(-1, 3), np.array(values, dtype=float).reshape(-1, 3))


@st.composite
def quaternions(draw: st.DrawFn) -> tuple[float, float, float, float]:
    """Arbitrary floats, or a unit quaternion off by a little (rounding) or a lot."""
    if draw(st.booleans()):
        return tuple(draw(st.lists(finite_or_not, min_size=4, max_size=4)))
    direction = np.array(draw(st.lists(st.floats(-1, 1), min_size=4, max_size=4)))
    assume(np.linalg.norm(direction) > 1e-3)
    stretch = draw(st.one_of(st.floats(-2e-3, 2e-3), st.floats(-1, 1)))
    return tuple((direction / np.linalg.norm(direction) * (1 + stretch)).tolist())


@FUZZ
@given(q=quaternions(), position=st.tuples(finite_or_not, finite_or_not, finite_or_not))
@example(q=(0.0, 7.741001517595157e+153, 7.741001517595157e+153, 7.741001517595157e+153),
         position=(0.0, 0.0, 0.0))  # its squares' sum overflows: found by this test in CI
def test_fuzzed_poses(q, position):
    # hypot, not the root of a sum of squares: three components of 7.7e153 overflow that sum
    norm = math.hypot(*q) if all(math.isfinite(v) for v in q) else math.inf
    assume(not math.isfinite(norm) or abs(abs(norm - 1) - ma.poses.QUATERNION_NORM_TOL) > 1e-9)
    valid = (math.isfinite(norm) and abs(norm - 1) <= ma.poses.QUATERNION_NORM_TOL
             and all(math.isfinite(v) for v in position))
    msg = ma.rosbags_types().get('geometry_msgs/msg/PoseStamped')(
        header=ma.make_header(0, 'map', ma.rosbags_types()), pose=rosbags_pose(position, q))
    if not valid:
        with pytest.raises(MessageError):
            ma.pose_msg_to_rt(msg)
        return
    R, c = ma.pose_msg_to_rt(msg)
    np.testing.assert_allclose(R, textbook_matrix(*(v / norm for v in q)), atol=1e-12)
    np.testing.assert_array_equal(c, position)
    R2, c2 = ma.pose_msg_to_rt(ma.rt_to_pose(R, c, ma.rosbags_types()))  # and back
    np.testing.assert_allclose(R2, R, atol=1e-12)
    np.testing.assert_array_equal(c2, c)
