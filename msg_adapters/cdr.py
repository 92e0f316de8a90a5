"""Input messages straight from their serialized CDR bytes; no ROS import.

- PointCloud2: the header fields and a zero-copy view of the points. The node subscribes to the
  map with ``raw=True`` and the replay reads CDR bytes from the recording: parsing the few header
  fields by hand and handing the point bytes to :func:`xyz_from_buffer` avoids building a
  1M-element ``data`` array in a message object.
- SLAM poses (PoseStamped, PoseWithCovarianceStamped, Odometry) and HMR joints (PoseArray): the
  header and one ``np.frombuffer`` of the float64 block, instead of a message object per pose.

The values then go through the same checks as the message adapters (:mod:`msg_adapters.poses`,
:mod:`msg_adapters.joints`).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from msg_adapters.errors import MessageError
from msg_adapters.joints import JOINTS_PER_PERSON, positions_to_joints
from msg_adapters.pointcloud import xyz_from_buffer
from msg_adapters.poses import pose_values_to_rt

# Messages whose header is followed (after child_frame_id for Odometry) by a geometry_msgs/Pose
POSE_TYPES = ('geometry_msgs/msg/PoseStamped', 'geometry_msgs/msg/PoseWithCovarianceStamped',
              'nav_msgs/msg/Odometry')


class PointFieldSpec(NamedTuple):
    """One sensor_msgs/PointField as read from the CDR bytes."""

    name: str
    offset: int
    datatype: int
    count: int


@dataclass
class RawCloud:
    """The fields of a serialized sensor_msgs/PointCloud2, with ``data`` a view into the CDR bytes."""

    stamp_ns: int
    frame_id: str
    height: int
    width: int
    fields: list[PointFieldSpec]
    is_bigendian: bool
    point_step: int
    row_step: int
    data: memoryview  # point bytes, not copied


class _CdrReader:
    """Reads XCDR1 (ROS 2's plain CDR) primitives; alignment is relative to the payload start."""

    ENCAPSULATION = 4  # representation id + options before the payload

    def __init__(self, data: bytes | memoryview, what: str = 'PointCloud2') -> None:
        self.what = what
        self.view = memoryview(data)
        if len(self.view) < self.ENCAPSULATION:
            raise MessageError(f'{what}: serialized message shorter than its CDR header')
        representation = bytes(self.view[:2])
        if representation in (b'\x00\x01', b'\x00\x03'):  # CDR_LE, PL_CDR_LE
            self.order = '<'
        elif representation in (b'\x00\x00', b'\x00\x02'):  # CDR_BE, PL_CDR_BE
            self.order = '>'
        else:
            raise MessageError(f'{what}: unknown CDR representation {representation.hex()}')
        self.pos = self.ENCAPSULATION

    def _align(self, size: int) -> None:
        offset = self.pos - self.ENCAPSULATION
        self.pos += (-offset) % size

    def _take(self, size: int) -> memoryview:
        if self.pos + size > len(self.view):
            raise MessageError(f'{self.what}: serialized message is truncated')
        chunk = self.view[self.pos:self.pos + size]
        self.pos += size
        return chunk

    def u8(self) -> int:
        return self._take(1)[0]

    def u32(self) -> int:
        self._align(4)
        return struct.unpack(self.order + 'I', self._take(4))[0]

    def i32(self) -> int:
        self._align(4)
        return struct.unpack(self.order + 'i', self._take(4))[0]

    def string(self) -> str:
        length = self.u32()  # includes the terminating NUL
        raw = bytes(self._take(length))
        return raw[:-1].decode('utf-8', errors='replace') if length else ''

    def u8_sequence(self) -> memoryview:
        return self._take(self.u32())

    def f64_block(self, count: int) -> np.ndarray:
        """``count`` float64 (aligned to 8 when count > 0) as a float64 array in native order."""
        return self.f64_view(count).astype(np.float64)

    def f64_view(self, count: int) -> np.ndarray:
        """``count`` float64 (aligned to 8 when count > 0): a read-only view of the bytes, in the
        message's byte order (copy what is kept: the view holds the whole message)."""
        if count == 0:
            return np.empty(0)
        self._align(8)
        return np.frombuffer(self._take(8 * count), dtype=self.order + 'f8')

    def header(self) -> tuple[int, str]:
        """std_msgs/Header → (stamp ns, frame_id); nanosec must be < 1e9."""
        sec, nanosec = self.i32(), self.u32()
        if nanosec >= 1_000_000_000:
            raise MessageError(f'{self.what}: stamp nanosec must be in [0, 1e9), got {nanosec}')
        return sec * 1_000_000_000 + nanosec, self.string()


def parse_cloud_cdr(data: bytes | memoryview) -> RawCloud:
    """The header fields of a serialized PointCloud2 and a zero-copy view of its point data.

    Field order: sensor_msgs/msg/PointCloud2 (header, height, width, fields, is_bigendian,
    point_step, row_step, data, is_dense). Raises :class:`MessageError` on truncated bytes.
    """
    reader = _CdrReader(data)
    sec, nanosec = reader.i32(), reader.u32()
    frame_id = reader.string()
    height, width = reader.u32(), reader.u32()
    fields = []
    for _ in range(reader.u32()):
        name = reader.string()
        offset = reader.u32()
        datatype = reader.u8()
        count = reader.u32()
        fields.append(PointFieldSpec(name, offset, datatype, count))
    is_bigendian = bool(reader.u8())
    point_step, row_step = reader.u32(), reader.u32()
    points = reader.u8_sequence()
    return RawCloud(sec * 1_000_000_000 + nanosec, frame_id, height, width, fields, is_bigendian,
                    point_step, row_step, points)


def cloud_points(cloud: RawCloud) -> Any:
    """Points of a raw cloud: (N, 3) float64, SLAM units, ``cloud.frame_id`` (the adapter's rules)."""
    return xyz_from_buffer(cloud.data, cloud.fields, cloud.point_step, cloud.width, cloud.height,
                           cloud.row_step, cloud.is_bigendian)


@dataclass
class RawPose:
    """A SLAM pose read from CDR: R_wc (3, 3) camera to map, c (3,) camera centre, SLAM units."""

    stamp_ns: int
    frame_id: str
    child_frame_id: str
    R_wc: np.ndarray
    c_map: np.ndarray


def parse_pose_cdr(data: bytes | memoryview, msgtype: str) -> RawPose:
    """A serialized PoseStamped, PoseWithCovarianceStamped or Odometry → :class:`RawPose`.

    MessageError for another type, truncated bytes, a non-finite position or a quaternion that is
    not a rotation (:func:`msg_adapters.poses.pose_values_to_rt`).
    """
    if msgtype not in POSE_TYPES:
        raise MessageError(f'{msgtype}: not a pose message (expected one of {", ".join(POSE_TYPES)})')
    name = msgtype.rsplit('/', 1)[-1]
    reader = _CdrReader(data, name)
    stamp_ns, frame_id = reader.header()
    child = reader.string() if msgtype == 'nav_msgs/msg/Odometry' else ''
    values = reader.f64_block(7)  # position x, y, z; orientation x, y, z, w
    R_wc, c_map = pose_values_to_rt(values[:3], values[3:], name)
    return RawPose(stamp_ns, frame_id, child, R_wc, c_map)


def parse_joints_cdr(data: bytes | memoryview) -> tuple[int, str, np.ndarray]:
    """A serialized PoseArray of SMPL-24 joints → (stamp ns, frame_id, joints (P, 24, 3) float64,
    metres, that frame). Non-finite values pass through; MessageError when truncated or when the
    number of poses is not a multiple of 24."""
    reader = _CdrReader(data, 'PoseArray')
    stamp_ns, frame_id = reader.header()
    count = reader.u32()
    if 56 * count > len(reader.view) - reader.pos:
        raise MessageError(f'PoseArray: {count} poses do not fit in the serialized message')
    poses = reader.f64_view(7 * count).reshape(count, 7)
    # a contiguous copy of the positions alone (native order): the frame keeps 24 x 3, not 24 x 7
    positions = np.ascontiguousarray(poses[:, :3], dtype=np.float64)
    return stamp_ns, frame_id, positions_to_joints(positions, 'PoseArray', JOINTS_PER_PERSON)
