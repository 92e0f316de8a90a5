"""PointCloud2 straight from its serialized CDR bytes; no ROS import.

The header fields and a zero-copy view of the points: the node subscribes to the map with
``raw=True`` and the replay reads CDR bytes from the recording, so parsing the few header fields by
hand and handing the point bytes to :func:`~msg_adapters.pointcloud.xyz_from_buffer` avoids
building (and copying) a 1M-element ``data`` array in a message object.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

from msg_adapters.errors import MessageError
from msg_adapters.pointcloud import xyz_from_buffer
from msg_adapters.stamps import time_to_ns


@dataclass(frozen=True)
class PointFieldSpec:
    """One sensor_msgs/PointField as read from the CDR bytes."""

    name: str
    offset: int
    datatype: int
    count: int


@dataclass
class RawCloud:
    """The fields of a serialized sensor_msgs/PointCloud2, with ``data`` a view into the CDR
    bytes."""

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


def parse_cloud_cdr(data: bytes | memoryview) -> RawCloud:
    """The header fields of a serialized PointCloud2 and a zero-copy view of its point data.

    Field order: sensor_msgs/msg/PointCloud2 (header, height, width, fields, is_bigendian,
    point_step, row_step, data, is_dense). Raises :class:`MessageError` on truncated bytes or an
    invalid stamp.
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
    return RawCloud(time_to_ns(sec, nanosec), frame_id, height, width, fields, is_bigendian,
                    point_step, row_step, points)


def cloud_points(cloud: RawCloud) -> Any:
    """Points of a raw cloud: (N, 3) float64, SLAM units, ``cloud.frame_id`` (the adapter's
    rules)."""
    return xyz_from_buffer(cloud.data, cloud.fields, cloud.point_step, cloud.width, cloud.height,
                           cloud.row_step, cloud.is_bigendian)
