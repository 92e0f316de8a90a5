"""Map point files a SLAM pipeline writes, as (N, 3) float64 points (``hac import --map``).

Units and frame are the file's own: for ``hac import``, SLAM units in the SLAM map frame. Formats,
chosen by the file name's ending:

- ``.ply``: ASCII, ``binary_little_endian`` or ``binary_big_endian`` PLY with a ``vertex`` element
  holding ``x``, ``y`` and ``z`` (any numeric type); other vertex properties (colours, normals, even
  list properties in ASCII files) are skipped, and other elements before or after ``vertex`` are
  skipped (in binary files an element before ``vertex`` may have list properties: it is walked
  item by item).
- ``.npy``: one (N, 3) numeric array (no pickles).
- anything else: text, ``x y z`` per line (commas allowed; ``#`` comments and blank lines skipped).

Read with numpy alone (no plyfile). Every problem raises
:class:`~hac_ros.core.basics.errors.InputError` naming the file: a missing file, a garbage or
truncated header, fewer vertex bytes or lines than the
header announces, missing x/y/z, a wrong shape.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from hac_ros.core.basics.errors import InputError
from hac_ros.files.readers import existing_file

PLY_TYPES = {  # PLY scalar type names (both spellings) -> numpy type without byte order
    'char': 'i1', 'int8': 'i1', 'uchar': 'u1', 'uint8': 'u1', 'short': 'i2', 'int16': 'i2',
    'ushort': 'u2', 'uint16': 'u2', 'int': 'i4', 'int32': 'i4', 'uint': 'u4', 'uint32': 'u4',
    'float': 'f4', 'float32': 'f4', 'double': 'f8', 'float64': 'f8'}
PLY_FORMATS = {'ascii': None, 'binary_little_endian': '<', 'binary_big_endian': '>'}
MAX_HEADER_BYTES = 1 << 20


class _Element:
    """One PLY element: name, count, properties [(name, type, list count type or None)]."""

    def __init__(self, name: str, count: int) -> None:
        self.name, self.count = name, count
        self.properties: list[tuple[str, str, str | None]] = []

    @property
    def has_lists(self) -> bool:
        return any(p[2] is not None for p in self.properties)


def read_map(path: str | Path) -> np.ndarray:
    """The points of a map file (PLY, .npy or text, by ending) as (N, 3) float64, the file's unit
    and frame. InputError when the file is missing, unreadable, malformed or holds no point."""
    path = existing_file(path, 'map file')
    suffix = path.suffix.lower()
    if suffix == '.ply':
        points = read_ply(path)
    elif suffix == '.npy':
        try:
            points = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InputError(f'map file {path}: not a readable .npy array ({exc})') from exc
    else:
        points = _read_text(path)
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] != 3 or points.dtype.kind not in 'iuf':
        raise InputError(f'map file {path}: expected (N, 3) numbers, got shape {points.shape} '
                         f'of {points.dtype}')
    points = points.astype(float)
    if not np.isfinite(points).all(axis=1).any():
        raise InputError(f'map file {path}: no finite point')
    return points


def _read_text(path: Path) -> np.ndarray:
    rows = []
    try:
        lines = path.read_text(encoding='utf-8').splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f'map file {path}: cannot read it as text ({exc})') from exc
    for number, line in enumerate(lines, 1):
        text = line.split('#', 1)[0].replace(',', ' ').split()
        if not text:
            continue
        if len(text) != 3:
            raise InputError(f'map file {path}:{number}: expected 3 values (x y z), got '
                             f'{len(text)}')
        try:
            rows.append([float(v) for v in text])
        except ValueError as exc:
            raise InputError(f'map file {path}:{number}: not a number ({exc})') from exc
    return np.asarray(rows, dtype=float).reshape(-1, 3)


def _parse_header(path: Path, data: bytes) -> tuple[str, list[_Element], int]:
    """(format, elements, offset of the body) of a PLY file's bytes."""
    if not data.startswith(b'ply'):
        raise InputError(f'map file {path}: not a PLY file (it does not start with "ply")')
    end = data.find(b'end_header', 0, MAX_HEADER_BYTES)
    if end < 0:
        raise InputError(f'map file {path}: PLY header without "end_header"')
    body = data.find(b'\n', end)
    body = len(data) if body < 0 else body + 1
    try:
        lines = data[:end].decode('ascii').splitlines()[1:]
    except UnicodeDecodeError as exc:
        raise InputError(f'map file {path}: PLY header is not ASCII text') from exc
    fmt, elements = None, []
    for line in lines:
        words = line.split()
        if not words or words[0] in ('comment', 'obj_info'):
            continue
        bad = InputError(f'map file {path}: bad PLY header line "{line.strip()}"')
        if words[0] == 'format':
            if len(words) < 2 or words[1] not in PLY_FORMATS:
                raise InputError(f'map file {path}: unknown PLY format "{line.strip()}" (ascii, '
                                 'binary_little_endian or binary_big_endian)')
            fmt = words[1]
        elif words[0] == 'element':
            if len(words) != 3 or not words[2].isdigit():
                raise bad
            elements.append(_Element(words[1], int(words[2])))
        elif words[0] == 'property':
            if not elements:
                raise bad
            if len(words) == 5 and words[1] == 'list' and words[2] in PLY_TYPES \
                    and words[3] in PLY_TYPES:
                elements[-1].properties.append((words[4], PLY_TYPES[words[3]], PLY_TYPES[words[2]]))
            elif len(words) == 3 and words[1] in PLY_TYPES:
                elements[-1].properties.append((words[2], PLY_TYPES[words[1]], None))
            else:
                raise bad
        else:
            raise bad
    if fmt is None:
        raise InputError(f'map file {path}: PLY header without a "format" line')
    return fmt, elements, body


def read_ply(path: str | Path) -> np.ndarray:
    """The x, y, z of a PLY file's ``vertex`` element, (N, 3) float64, the file's unit and frame."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f'map file {path}: cannot read it ({exc})') from exc
    fmt, elements, offset = _parse_header(path, data)
    names = [e.name for e in elements]
    if 'vertex' not in names:
        raise InputError(f'map file {path}: PLY has no "vertex" element (elements: '
                         f'{", ".join(names) or "none"})')
    vertex = elements[names.index('vertex')]
    props = [p[0] for p in vertex.properties]
    missing = [axis for axis in 'xyz' if axis not in props]
    if missing:
        raise InputError(f'map file {path}: PLY vertex has no {", ".join(missing)} property '
                         f'(properties: {", ".join(props) or "none"})')
    before = elements[:names.index('vertex')]
    if fmt == 'ascii':
        return _ply_ascii(path, data[offset:], before, vertex)
    order = PLY_FORMATS[fmt]
    assert order is not None
    for element in before:
        offset = _skip_binary(path, data, offset, element, order)
    if vertex.has_lists:
        raise InputError(f'map file {path}: binary PLY vertex with list properties is not '
                         'supported')
    dtype = np.dtype([(name, order + kind) for name, kind, _ in vertex.properties])
    need = vertex.count * dtype.itemsize
    if len(data) - offset < need:
        raise InputError(f'map file {path}: truncated PLY: the header announces {vertex.count} '
                         f'vertices ({need} bytes) but only {len(data) - offset} bytes follow')
    table = np.frombuffer(data, dtype=dtype, count=vertex.count, offset=offset)
    return np.stack([table[axis].astype(float) for axis in 'xyz'], axis=1)


def _skip_binary(path: Path, data: bytes, offset: int, element: _Element, order: str) -> int:
    """The offset after a binary element (item by item when it has list properties)."""
    if not element.has_lists:
        size = element.count * sum(np.dtype(kind).itemsize for _, kind, _ in element.properties)
        if offset + size > len(data):
            raise InputError(f'map file {path}: truncated PLY in element "{element.name}"')
        return offset + size
    for _ in range(element.count):  # each item moves on by one byte at least: bounded by the data
        for _, kind, count_kind in element.properties:
            if count_kind is not None:
                count_type = np.dtype(order + count_kind)
                if offset + count_type.itemsize > len(data):
                    raise InputError(f'map file {path}: truncated PLY in element "{element.name}"')
                n = int(np.frombuffer(data, count_type, 1, offset)[0])
                if n < 0:
                    raise InputError(f'map file {path}: PLY element "{element.name}": a list '
                                     f'of {n} items')
                offset += count_type.itemsize + n * np.dtype(kind).itemsize
            else:
                offset += np.dtype(kind).itemsize
        if offset > len(data):
            raise InputError(f'map file {path}: truncated PLY in element "{element.name}"')
    return offset


def _ply_ascii(path: Path, body: bytes, before: list[_Element], vertex: _Element) -> np.ndarray:
    lines = [line for line in body.decode('ascii', errors='replace').splitlines() if line.strip()]
    start = sum(e.count for e in before)
    rows = lines[start:start + vertex.count]
    if len(rows) < vertex.count:
        raise InputError(f'map file {path}: truncated PLY: the header announces {vertex.count} '
                         f'vertices but only {max(len(rows), 0)} lines follow')
    columns = {}
    if not vertex.has_lists:
        columns = {name: k for k, (name, _, _) in enumerate(vertex.properties)}
    out = np.empty((vertex.count, 3))
    for i, row in enumerate(rows):
        words = row.split()
        try:
            if vertex.has_lists:  # walk the properties of this line
                values, k = {}, 0
                for name, _, count_kind in vertex.properties:
                    if count_kind is None:
                        values[name] = words[k]
                        k += 1
                    else:
                        n = int(words[k])
                        if n < 0:
                            raise ValueError(f'a list of {n} items')
                        k += 1 + n
                out[i] = [float(values[axis]) for axis in 'xyz']
            else:
                if len(words) != len(vertex.properties):
                    raise ValueError(f'{len(words)} values for {len(vertex.properties)} properties')
                out[i] = [float(words[columns[axis]]) for axis in 'xyz']
        except (ValueError, IndexError, KeyError) as exc:
            raise InputError(f'map file {path}: PLY vertex {i}: malformed line "{row.strip()}" '
                             f'({exc})') from exc
    return out


def write_ply(path: str | Path, points: np.ndarray, comment: str = '') -> None:
    """``points`` (N, 3), any unit and frame (the caller's ``comment`` says which), as a binary
    little-endian PLY of float32 x, y, z vertices (what :func:`read_ply`, CloudCompare, MeshLab and
    Open3D read)."""
    xyz = np.ascontiguousarray(np.asarray(points, dtype='<f4').reshape(-1, 3))
    lines = ['ply', 'format binary_little_endian 1.0']
    lines += [f'comment {line}' for line in comment.splitlines() if line.strip()]
    lines += [f'element vertex {len(xyz)}', 'property float x', 'property float y',
              'property float z', 'end_header']
    with open(path, 'wb') as out:
        out.write(('\n'.join(lines) + '\n').encode('ascii'))
        out.write(xyz.tobytes())
