"""``sensor_msgs/PointCloud2`` ↔ (N, 3) float64 points.

Like sensor_msgs_py's ``point_cloud2.py``: a numpy structured dtype built from the PointFields and
one strided view of the bytes, no per-point Python loop. Only x, y, z are read (FLOAT32 or FLOAT64,
any order and offset, padding inside ``point_step`` and at the end of each row, either endianness);
other fields are ignored; non-finite and exactly (0, 0, 0) points are dropped (as hac_ros' map
input: (0, 0, 0) is how many SLAM wrappers mark an unset point).
"""
from __future__ import annotations

import array
import operator
from collections.abc import Sequence
from typing import Any

import numpy as np

from msg_adapters.errors import MessageError
from msg_adapters.stamps import make_header
from msg_adapters.types import MessageTypes

# sensor_msgs/msg/PointField datatype constants and their sizes in bytes
INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = 1, 2, 3, 4, 5, 6, 7, 8
DATATYPE_SIZES = {INT8: 1, UINT8: 1, INT16: 2, UINT16: 2, INT32: 4, UINT32: 4, FLOAT32: 4,
                  FLOAT64: 8}
XYZ_FORMATS = {FLOAT32: 'f4', FLOAT64: 'f8'}  # the datatypes accepted for x, y and z
AXES = ('x', 'y', 'z')


def _count(value: Any, what: str) -> int:
    """A non-negative integer header value, or MessageError naming it."""
    try:
        number = operator.index(value)
    except TypeError as exc:
        raise MessageError(f'PointCloud2: {what} must be an integer, got {value!r}') from exc
    if number < 0:
        raise MessageError(f'PointCloud2: {what} must be >= 0, got {number}')
    return number


def _xyz_fields(fields: Sequence[Any], point_step: int) -> list[tuple[str, int, int]]:
    """(axis, offset, datatype) of x, y and z, checked against the point layout."""
    found: dict[str, tuple[int, int, int]] = {}
    try:
        for field in fields:
            name = field.name
            if name not in AXES:
                continue
            if name in found:
                raise MessageError(f'PointCloud2: field "{name}" appears more than once')
            found[name] = (_count(field.offset, f'field "{name}" offset'),
                           _count(field.datatype, f'field "{name}" datatype'),
                           _count(field.count, f'field "{name}" count'))
    except (AttributeError, TypeError) as exc:
        raise MessageError(f'PointCloud2: fields must be PointFields with name, offset, datatype '
                           f'and count ({exc})') from exc
    out = []
    for axis in AXES:
        if axis not in found:
            names = ', '.join(str(getattr(f, 'name', '?')) for f in fields) or 'none'
            raise MessageError(f'PointCloud2: no "{axis}" field (fields: {names})')
        offset, datatype, count = found[axis]
        if datatype not in XYZ_FORMATS:
            raise MessageError(f'PointCloud2: field "{axis}" has datatype {datatype}; expected '
                               f'FLOAT32 ({FLOAT32}) or FLOAT64 ({FLOAT64})')
        if count != 1:
            raise MessageError(f'PointCloud2: field "{axis}" has count {count}; expected 1')
        size = DATATYPE_SIZES[datatype]
        if offset + size > point_step:
            raise MessageError(f'PointCloud2: field "{axis}" (offset {offset}, {size} bytes) does '
                               f'not fit in point_step {point_step}')
        out.append((axis, offset, datatype))
    return out


def xyz_from_buffer(data: Any, fields: Sequence[Any], point_step: int, width: int, height: int,
                    row_step: int, is_bigendian: bool) -> np.ndarray:
    """Points (N, 3) float64 from a PointCloud2's raw fields, in the cloud's frame and unit.

    ``data``: the point bytes (bytes, bytearray, memoryview, ``array.array('B')``, a uint8/int8
    numpy array or a sequence of ints 0..255); ``fields``: objects with name, offset, datatype,
    count (PointField or the CDR parser's specs). Point (r, i) starts at byte
    ``r * row_step + i * point_step``; N <= width * height after dropping non-finite and (0, 0, 0)
    points. Raises MessageError for: missing, repeated, non-float or count != 1 x/y/z; a field not
    inside the point; point_step 0; row_step < width * point_step; len(data) != row_step * height.
    """
    point_step = _count(point_step, 'point_step')
    width, height = _count(width, 'width'), _count(height, 'height')
    row_step = _count(row_step, 'row_step')
    if point_step == 0:
        raise MessageError('PointCloud2: point_step must be > 0, got 0')
    xyz = _xyz_fields(fields, point_step)
    if row_step < width * point_step:
        raise MessageError(f'PointCloud2: row_step {row_step} < width {width} x point_step '
                           f'{point_step}')
    buf = _as_uint8(data)
    if buf.size != row_step * height:
        raise MessageError(f'PointCloud2: data has {buf.size} bytes; expected row_step {row_step} '
                           f'x height {height} = {row_step * height}')
    if width * height == 0:
        return np.empty((0, 3))
    endian = '>' if is_bigendian else '<'
    dtype = np.dtype({'names': [axis for axis, _, _ in xyz],
                      'formats': [endian + XYZ_FORMATS[datatype] for _, _, datatype in xyz],
                      'offsets': [offset for _, offset, _ in xyz], 'itemsize': point_step})
    # one strided view over the rows (row padding skipped, nothing copied); its last byte,
    # (height - 1) * row_step + width * point_step, is within the checked length
    records = np.ndarray((height, width), dtype=dtype, buffer=buf, strides=(row_step, point_step))
    columns = [records[axis].reshape(-1) for axis in AXES]  # in the field's own precision
    # the mask column by column: numpy reduces (N, 3) along axis 1 several times slower
    x, y, z = columns
    keep = np.isfinite(x)
    keep &= np.isfinite(y)
    keep &= np.isfinite(z)
    keep &= (x != 0) | (y != 0) | (z != 0)
    if keep.all():
        points = np.empty((x.size, 3))
        for k, column in enumerate(columns):
            points[:, k] = column
    else:
        points = np.empty((int(np.count_nonzero(keep)), 3))
        for k, column in enumerate(columns):
            points[:, k] = column[keep]
    return points


def cloud_to_xyz(msg: Any) -> np.ndarray:
    """``sensor_msgs/PointCloud2`` (rclpy or rosbags) → (N, 3) float64, the cloud's frame and unit.

    See :func:`xyz_from_buffer` for the accepted layouts and the errors.
    """
    try:
        fields, data = msg.fields, msg.data
        layout = (msg.point_step, msg.width, msg.height, msg.row_step, bool(msg.is_bigendian))
    except AttributeError as exc:
        raise MessageError(f'PointCloud2: missing field ({exc})') from exc
    return xyz_from_buffer(data, fields, *layout)


def xyz_to_cloud(points: np.ndarray, stamp_ns: int, frame_id: str, types: MessageTypes,
                 dtype: Any = np.float32) -> Any:
    """(N, 3) points (any unit and frame: ``frame_id``'s) → ``PointCloud2``.

    Height 1, little-endian, fields x, y, z of ``dtype`` (float32 or float64) at offsets 0, s, 2s,
    no padding; ``is_dense`` when every point is finite.
    """
    points = np.asarray(points, dtype=float)
    if points.size == 0:
        points = points.reshape(0, 3)
    if points.ndim != 2 or points.shape[1] != 3:
        raise MessageError(f'xyz_to_cloud: points must be (N, 3), got shape {points.shape}')
    try:
        dtype = np.dtype(dtype)
    except TypeError as exc:
        raise MessageError(f'xyz_to_cloud: dtype must be float32 or float64, '
                           f'got {dtype!r}') from exc
    if dtype.kind != 'f' or dtype.itemsize not in (4, 8):
        raise MessageError(f'xyz_to_cloud: dtype must be float32 or float64, got {dtype}')
    size = dtype.itemsize
    datatype = FLOAT32 if size == 4 else FLOAT64
    PointField = types.get('sensor_msgs/msg/PointField')
    fields = [PointField(name=axis, offset=k * size, datatype=datatype, count=1)
              for k, axis in enumerate(AXES)]
    raw = np.array(points, dtype=dtype.newbyteorder('<'), order='C')  # a copy: no aliasing
    if types.is_rosbags:
        data: Any = raw.reshape(-1).view(np.uint8)
    else:  # rclpy takes an array.array('B') as is (anything else is checked element by element)
        data = array.array('B')
        data.frombytes(raw.tobytes())
    n = len(points)
    return types.get('sensor_msgs/msg/PointCloud2')(
        header=make_header(stamp_ns, frame_id, types), height=1, width=n, fields=fields,
        is_bigendian=False, point_step=3 * size, row_step=3 * size * n, data=data,
        is_dense=bool(np.isfinite(points).all()))


def _as_uint8(data: Any) -> np.ndarray:
    """The point bytes as a 1-D uint8 array (a view when ``data`` is a buffer)."""
    if isinstance(data, np.ndarray):
        if data.dtype not in (np.uint8, np.int8):
            raise MessageError(f'PointCloud2: data must be uint8 bytes, got a {data.dtype} array')
        return np.ascontiguousarray(data).reshape(-1).view(np.uint8)
    if isinstance(data, array.array) and data.typecode not in 'Bb':
        raise MessageError(f"PointCloud2: data must be uint8 bytes, got array('{data.typecode}')")
    if isinstance(data, (bytes, bytearray, memoryview, array.array)):
        try:
            return np.frombuffer(data, dtype=np.uint8)
        except (TypeError, ValueError) as exc:  # e.g. a non-contiguous memoryview
            raise MessageError(f'PointCloud2: data is not a contiguous byte buffer '
                               f'({exc})') from exc
    try:
        values = np.asarray(data)
    except (TypeError, ValueError) as exc:
        raise MessageError(f'PointCloud2: data is not bytes ({type(data).__name__})') from exc
    if values.size == 0:
        return np.empty(0, np.uint8)
    if values.dtype.kind not in 'iu' or values.min() < 0 or values.max() > 255:
        raise MessageError(f'PointCloud2: data must be bytes (ints 0..255), got '
                           f'{type(data).__name__} of {values.dtype}')
    return values.reshape(-1).astype(np.uint8)
