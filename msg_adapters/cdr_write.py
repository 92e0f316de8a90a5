"""Serialized CDR straight from numpy for the messages hac_ros publishes; no ROS import.

Building a message object field by field and then serializing it costs far more than the
calibrator's own work for a frame (a MarkerArray with a 600-point camera path is 600 Point objects).
These encoders write the same bytes ``rosbags``' ``serialize_cdr`` (and rclpy's
``serialize_message``) give for the same values, in one pass: XCDR1 little endian, the 4-byte
encapsulation header, every primitive aligned to its size relative to the payload's start. The
node publishes them with ``Publisher.publish(bytes)`` and the replay writes them as they are.
test/test_cdr_write.py checks every encoder byte for byte against rosbags and rclpy.

Arrays are documented with their frame and unit by the callers; here a position is 3 float64, a
quaternion (x, y, z, w) 4 float64, a colour (r, g, b, a) 4 float32.
"""
from __future__ import annotations

import struct
from collections.abc import Iterable, Sequence
from functools import lru_cache

import numpy as np

from msg_adapters.errors import MessageError
from msg_adapters.pointcloud import FLOAT32
from msg_adapters.stamps import NS_PER_S

ENCAPSULATION_LE = b'\x00\x01\x00\x00'  # CDR_LE, no options
_I32_U32 = struct.Struct('<iI')
_U32 = struct.Struct('<I')
_I32X3 = struct.Struct('<iii')
_F64 = struct.Struct('<d')
_ZEROS = bytes(8)
IDENTITY_POSE = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])  # position, quaternion (x, y, z, w)


class CdrWriter:
    """Appends XCDR1 little-endian primitives to a buffer that starts with the encapsulation."""

    __slots__ = ('buf',)

    def __init__(self) -> None:
        self.buf = bytearray(ENCAPSULATION_LE)

    def bytes(self) -> bytes:
        return bytes(self.buf)

    def align(self, size: int) -> None:
        pad = -(len(self.buf) - 4) % size
        if pad:
            self.buf += _ZEROS[:pad]

    def u32(self, value: int) -> None:
        self.align(4)
        self.buf += _U32.pack(value)

    def i32x3(self, a: int, b: int, c: int) -> None:
        self.align(4)
        self.buf += _I32X3.pack(a, b, c)

    def octet(self, value: int) -> None:
        self.buf.append(value)

    def string(self, text: str) -> None:
        data = text.encode()
        self.align(4)
        self.buf += _U32.pack(len(data) + 1)
        self.buf += data
        self.buf.append(0)

    def f64_array(self, values: np.ndarray) -> None:
        """Fixed-size float64 array (or the elements of a sequence whose count is written)."""
        if values.size:
            self.align(8)
            self.buf += np.ascontiguousarray(values, dtype='<f8').tobytes()

    def f64_sequence(self, values: np.ndarray) -> None:
        self.u32(values.size)
        self.f64_array(values)

    def empty_sequence(self) -> None:
        self.u32(0)

    def header(self, stamp_ns: int, frame_id: str) -> None:
        """std_msgs/Header: builtin_interfaces/Time (int32 sec, uint32 nanosec) and frame_id."""
        sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
        if not -2**31 <= sec < 2**31:
            raise MessageError(f'stamp {stamp_ns} ns is outside builtin_interfaces/Time')
        self.align(4)
        self.buf += _I32_U32.pack(sec, nanosec)
        self.string(frame_id)


def float64(value: float) -> bytes:
    """std_msgs/Float64."""
    return ENCAPSULATION_LE + _F64.pack(float(value))


def pose_array(stamp_ns: int, frame_id: str, positions: np.ndarray) -> bytes:
    """geometry_msgs/PoseArray of positions (N, 3) with identity orientations."""
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.u32(len(positions))
    poses = np.zeros((len(positions), 7))
    poses[:, :3] = positions
    poses[:, 6] = 1.0
    w.f64_array(poses)
    return w.bytes()


def odometry(stamp_ns: int, frame_id: str, child_frame_id: str, position: np.ndarray,
             quat_xyzw: Sequence[float], covariance: np.ndarray, linear: np.ndarray,
             angular: np.ndarray, twist_covariance: np.ndarray | None = None) -> bytes:
    """nav_msgs/Odometry: pose (position (3,), quaternion (4,)) with covariance (6, 6); twist
    (linear (3,), angular (3,), child frame) with covariance (6, 6) or zeros."""
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.string(child_frame_id)
    twist_cov = np.zeros(36) if twist_covariance is None else np.ravel(twist_covariance)
    body = np.concatenate([np.ravel(position), np.ravel(quat_xyzw), np.ravel(covariance),
                           np.ravel(linear), np.ravel(angular), twist_cov])
    if body.size != 3 + 4 + 36 + 3 + 3 + 36:
        raise MessageError(f'odometry: expected 85 numbers, got {body.size}')
    w.f64_array(body)
    return w.bytes()


def pose_with_covariance_stamped(stamp_ns: int, frame_id: str, position: np.ndarray,
                                 quat_xyzw: Sequence[float], covariance: np.ndarray) -> bytes:
    """geometry_msgs/PoseWithCovarianceStamped: position (3,), quaternion (4,), covariance (6,
    6)."""
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    body = np.concatenate([np.ravel(position), np.ravel(quat_xyzw), np.ravel(covariance)])
    if body.size != 3 + 4 + 36:
        raise MessageError(f'pose with covariance: expected 43 numbers, got {body.size}')
    w.f64_array(body)
    return w.bytes()


def point_cloud_xyz32(stamp_ns: int, frame_id: str, points: np.ndarray) -> bytes:
    """sensor_msgs/PointCloud2 of points (N, 3): fields x, y, z float32, one row, dense when every
    point is finite."""
    xyz = np.ascontiguousarray(points, dtype='<f4').reshape(-1, 3)
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.u32(1)  # height
    w.u32(len(xyz))  # width
    w.u32(3)
    for k, name in enumerate('xyz'):
        w.string(name)
        w.u32(4 * k)  # offset
        w.octet(FLOAT32)
        w.u32(1)  # count
    w.octet(0)  # is_bigendian
    w.u32(12)  # point_step
    w.u32(12 * len(xyz))  # row_step
    data = xyz.tobytes()
    w.u32(len(data))
    w.buf += data
    w.octet(int(bool(np.isfinite(xyz).all())))  # is_dense
    return w.bytes()


def float64_multi_array(dims: Iterable[tuple[str, int, int]], data: np.ndarray,
                        data_offset: int = 0) -> bytes:
    """std_msgs/Float64MultiArray: layout dimensions (label, size, stride) and the data."""
    w = CdrWriter()
    dims = list(dims)
    w.u32(len(dims))
    for label, size, stride in dims:
        w.string(label)
        w.u32(size)
        w.u32(stride)
    w.u32(data_offset)
    w.f64_sequence(np.ravel(np.asarray(data, dtype=float)))
    return w.bytes()


def marker(w: CdrWriter, stamp_ns: int, frame_id: str, ns: str, marker_id: int, kind: int,
           action: int, pose: np.ndarray, scale: Sequence[float], rgba: Sequence[float],
           points: np.ndarray | None = None) -> None:
    """Append one visualization_msgs/Marker: pose (7,) position and quaternion (x, y, z, w),
    scale (3,), colour rgba (4,), points (N, 3) or None; every other field empty (lifetime 0:
    forever, not frame-locked, no colours, texture, mesh or text)."""
    w.header(stamp_ns, frame_id)
    w.string(ns)
    w.i32x3(marker_id, kind, action)
    w.f64_array(np.concatenate([np.ravel(pose), np.ravel(scale)]))  # 8-aligned, 80 bytes
    count = 0 if points is None else len(points)
    # colour, lifetime (0 s, 0 ns), frame_locked, padding, the points' count: fixed offsets here
    w.buf += _MARKER_MIDDLE.pack(*rgba, 0, 0, 0, count)
    if count:
        w.f64_array(np.asarray(points, dtype=float))
    w.buf += _marker_tail()


_MARKER_MIDDLE = struct.Struct('<4fiIB3xI')


@lru_cache(maxsize=1)
def _marker_tail() -> bytes:
    """A Marker's fields after ``points``, all empty. They align to at most 4 bytes and start
    4-aligned (after the points' count or float64 points), so their bytes never change."""
    w = CdrWriter()
    w.empty_sequence()  # colors
    w.string('')  # texture_resource
    w.header(0, '')  # texture: sensor_msgs/CompressedImage
    w.string('')  # texture.format
    w.empty_sequence()  # texture.data
    w.empty_sequence()  # uv_coordinates
    w.string('')  # text
    w.string('')  # mesh_resource
    w.string('')  # mesh_file.filename
    w.empty_sequence()  # mesh_file.data
    w.octet(0)  # mesh_use_embedded_materials
    return bytes(w.buf[len(ENCAPSULATION_LE):])


def diagnostic_array(stamp_ns: int, frame_id: str,
                     statuses: Iterable[tuple[int, str, str, str, Sequence[tuple[str, str]]]]
                     ) -> bytes:
    """diagnostic_msgs/DiagnosticArray of (level, name, message, hardware_id, [(key, value)])."""
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    statuses = list(statuses)
    w.u32(len(statuses))
    for level, name, message, hardware_id, values in statuses:
        w.octet(level)
        w.string(name)
        w.string(message)
        w.string(hardware_id)
        w.u32(len(values))
        for key, value in values:
            w.string(key)
            w.string(value)
    return w.bytes()
