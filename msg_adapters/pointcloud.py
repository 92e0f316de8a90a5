"""PointCloud2 ↔ (N, 3) float64 points.

Like sensor_msgs_py's ``point_cloud2.py``: a numpy dtype built from the PointFields and one
``np.frombuffer``, no per-point Python loop. Only x, y, z are read (FLOAT32 or FLOAT64, any order
and offset, padding in ``point_step`` and ``row_step``, either endianness); other fields are
ignored; non-finite and exactly (0, 0, 0) points are dropped (SPEC: map input).
"""
from __future__ import annotations

import array
from typing import Any, Sequence

import numpy as np

from msg_adapters.errors import MessageError
from msg_adapters.stamps import make_header
from msg_adapters.types import MessageTypes

FLOAT32, FLOAT64 = 7, 8
_SIZES = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 8: 8}  # PointField datatype -> bytes
_FLOATS = {FLOAT32: 'f4', FLOAT64: 'f8'}


def xyz_from_buffer(data: Any, fields: Sequence[Any], point_step: int, width: int, height: int,
                    row_step: int, is_bigendian: bool) -> np.ndarray:
    """Points (N, 3) float64 from a PointCloud2's raw fields (the CDR fast path uses this too).

    data: bytes-like (bytes, memoryview, array.array('B'), uint8 ndarray or a list of ints).
    Raises MessageError for missing x/y/z, a non-float or multi-count x/y/z, a field outside the
    point, a zero point_step, a row_step shorter than a row, or a data length != row_step * height.
    """
    point_step, width, height, row_step = int(point_step), int(width), int(height), int(row_step)
    if point_step <= 0:
        raise MessageError(f'PointCloud2: point_step must be > 0, got {point_step}')
    if width < 0 or height < 0:
        raise MessageError(f'PointCloud2: negative width/height {width}x{height}')
    by_name = {}
    for f in fields:
        by_name.setdefault(str(f.name), f)
    names, formats, offsets = [], [], []
    endian = '>' if is_bigendian else '<'
    for axis in ('x', 'y', 'z'):
        f = by_name.get(axis)
        if f is None:
            raise MessageError(f'PointCloud2: no "{axis}" field (fields: '
                               f'{", ".join(by_name) or "none"})')
        datatype, offset, count = int(f.datatype), int(f.offset), int(f.count)
        if datatype not in _FLOATS:
            raise MessageError(f'PointCloud2: field "{axis}" has datatype {datatype}; expected '
                               f'FLOAT32 (7) or FLOAT64 (8)')
        if count != 1:
            raise MessageError(f'PointCloud2: field "{axis}" has count {count}; expected 1')
        if offset < 0 or offset + _SIZES[datatype] > point_step:
            raise MessageError(f'PointCloud2: field "{axis}" (offset {offset}, '
                               f'{_SIZES[datatype]} bytes) does not fit in point_step {point_step}')
        names.append(axis)
        formats.append(endian + _FLOATS[datatype])
        offsets.append(offset)
    if height and width and row_step < width * point_step:
        raise MessageError(f'PointCloud2: row_step {row_step} < width {width} x point_step '
                           f'{point_step}')
    buf = _as_uint8(data)
    expected = row_step * height if width else len(buf)
    if len(buf) != expected:
        raise MessageError(f'PointCloud2: data has {len(buf)} bytes; row_step {row_step} x height '
                           f'{height} = {row_step * height}')
    n = width * height
    if n == 0:
        return np.empty((0, 3))
    if row_step != width * point_step:
        buf = buf.reshape(height, row_step)[:, :width * point_step].reshape(-1)
    dtype = np.dtype({'names': names, 'formats': formats, 'offsets': offsets, 'itemsize': point_step})
    records = np.frombuffer(buf, dtype=dtype, count=n)
    points = np.empty((n, 3))
    points[:, 0] = records['x']
    points[:, 1] = records['y']
    points[:, 2] = records['z']
    keep = np.isfinite(points).all(axis=1) & np.any(points != 0.0, axis=1)
    return points if keep.all() else points[keep]


def cloud_to_xyz(msg: Any) -> np.ndarray:
    """``sensor_msgs/PointCloud2`` (rclpy or rosbags) → (N, 3) float64, the cloud's frame and unit."""
    try:
        fields, data = msg.fields, msg.data
        args = (msg.point_step, msg.width, msg.height, msg.row_step, bool(msg.is_bigendian))
    except AttributeError as exc:
        raise MessageError(f'PointCloud2: missing field ({exc})') from exc
    return xyz_from_buffer(data, fields, *args)


def xyz_to_cloud(points: np.ndarray, stamp_ns: int, frame_id: str, types: MessageTypes,
                 dtype: Any = np.float32) -> Any:
    """(N, 3) points → a dense, little-endian, height-1 ``PointCloud2`` with x, y, z fields."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    dtype = np.dtype(dtype).newbyteorder('<')
    if dtype.kind != 'f' or dtype.itemsize not in (4, 8):
        raise MessageError(f'xyz_to_cloud: dtype must be float32 or float64, got {dtype}')
    size = dtype.itemsize
    datatype = FLOAT32 if size == 4 else FLOAT64
    PointField = types.get('sensor_msgs/msg/PointField')
    fields = [PointField(name=n, offset=i * size, datatype=datatype, count=1)
              for i, n in enumerate('xyz')]
    raw = np.ascontiguousarray(points, dtype=dtype).tobytes()
    if types.is_rosbags:
        data: Any = np.frombuffer(raw, dtype=np.uint8)
    else:
        data = array.array('B')
        data.frombytes(raw)
    return types.get('sensor_msgs/msg/PointCloud2')(
        header=make_header(stamp_ns, frame_id, types), height=1, width=len(points),
        fields=fields, is_bigendian=False, point_step=3 * size, row_step=3 * size * len(points),
        data=data, is_dense=True)


def _as_uint8(data: Any) -> np.ndarray:
    if isinstance(data, np.ndarray):
        return data.reshape(-1).view(np.uint8) if data.dtype.itemsize == 1 else data.astype(np.uint8)
    if isinstance(data, (bytes, bytearray, memoryview, array.array)):
        return np.frombuffer(data, dtype=np.uint8)
    try:
        return np.asarray(data, dtype=np.uint8).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise MessageError(f'PointCloud2: data is not bytes ({type(data).__name__})') from exc
