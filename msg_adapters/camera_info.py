"""``sensor_msgs/CameraInfo`` ↔ intrinsics K (3, 3) and image size (pinhole, optical frame).

A CameraInfo describes the full-resolution sensor; REP-104's ``roi`` and ``binning_x/y`` say which
part of it, at which sampling, the images on the topic hold. :func:`camera_info_to_intrinsics`
gives the K of those images as ``image_geometry`` does: the ROI's offset taken from the principal
point, then focal lengths and principal point divided by the binning; the size is the ROI's (the
full size when its width or height is 0) divided by the binning. With ``rectified`` it gives the
projection P's left 3 x 3 instead (the camera of ``image_rect``, whose D is then void).
"""
from __future__ import annotations

import operator
from typing import Any

import numpy as np

from msg_adapters.errors import MessageError
from msg_adapters.stamps import make_header
from msg_adapters.types import MessageTypes

PLUMB_BOB = 'plumb_bob'
PLUMB_BOB_COEFFICIENTS = 5  # k1, k2, t1, t2, k3
PRINCIPAL_POINT_MARGIN = 0.1  # of the image's size: the principal point lies at least this far
# inside every edge (a lens's is within a few per cent of the centre; a K meant for an image twice
# the size, or cx = cy = 0, puts it on an edge)


def _intrinsics(K: Any, where: str) -> np.ndarray:
    """A finite (3, 3) camera matrix with fx, fy > 0, float64 pixels."""
    try:
        K = np.array(K, dtype=float)
    except (TypeError, ValueError) as exc:
        raise MessageError(f'{where}: K must be 9 numbers ({exc})') from exc
    if K.size != 9:
        raise MessageError(f'{where}: K must have 9 values (3 x 3), got shape {K.shape}')
    K = K.reshape(3, 3)
    if not np.isfinite(K).all():
        raise MessageError(f'{where}: K is not finite: {K.ravel().tolist()}')
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise MessageError(f'{where}: focal lengths fx = {K[0, 0]}, fy = {K[1, 1]} must be > 0')
    return K


def _size(value: Any, what: str, where: str) -> int:
    try:
        size = operator.index(value)
    except TypeError as exc:
        raise MessageError(f'{where}: {what} must be an integer, got {value!r}') from exc
    if size <= 0:
        raise MessageError(f'{where}: {what} must be > 0 pixels, got {size}')
    return size


def camera_info_to_intrinsics(msg: Any, rectified: bool = False) -> tuple[np.ndarray, int, int]:
    """CameraInfo → (K (3, 3) float64 pixels, width, height in pixels) of the images it describes:
    ROI and binning applied (REP-104, as ``image_geometry``); with ``rectified``, P's left 3 x 3
    (the camera of the rectified image) instead of K.

    MessageError when K (or P) is not finite with fx, fy > 0, the image is empty, the ROI does not
    fit the sensor, or the principal point is not inside the image by
    :data:`PRINCIPAL_POINT_MARGIN` of its size (K made for another image size).
    """
    where = 'CameraInfo'
    try:
        k, width, height = (msg.p if rectified else msg.k), msg.width, msg.height
        binning = [max(int(b), 1) for b in (msg.binning_x, msg.binning_y)]
        roi = msg.roi
        offset = [int(roi.x_offset), int(roi.y_offset)]
        roi_size = [int(roi.width), int(roi.height)]
    except (AttributeError, TypeError, ValueError) as exc:
        raise MessageError(f'{where}: expected k, p, width, height, binning and roi ({exc})'
                           ) from exc
    if rectified:
        try:
            k = np.array(k, dtype=float).reshape(3, 4)[:, :3]
        except (TypeError, ValueError) as exc:
            raise MessageError(f'{where}: P must be 12 numbers (3 x 4) ({exc})') from exc
    K = _intrinsics(k, where + (' P' if rectified else ''))
    full = [_size(width, 'width', where), _size(height, 'height', where)]
    if any(roi_size) and (not all(roi_size) or any(
            o + n > f for o, n, f in zip(offset, roi_size, full))):
        raise MessageError(f'{where}: roi {roi_size[0]} x {roi_size[1]} at ({offset[0]}, '
                           f'{offset[1]}) does not fit the {full[0]} x {full[1]} sensor')
    size = [n if any(roi_size) else f for n, f in zip(roi_size, full)]
    K = K.copy()
    for axis in (0, 1):
        if any(roi_size):
            K[axis, 2] -= offset[axis]
        K[axis, axis] /= binning[axis]
        K[axis, 2] /= binning[axis]
        size[axis] //= binning[axis]
    if min(size) <= 0:
        raise MessageError(f'{where}: binning {binning[0]} x {binning[1]} leaves no pixel of '
                           f'{full[0]} x {full[1]}')
    problem = principal_point_problem(K, size[0], size[1])
    if problem:
        raise MessageError(f'{where}: {problem}')
    return K, size[0], size[1]


def principal_point_problem(K: np.ndarray, width: int, height: int) -> str:
    """'' when K's principal point lies inside a ``width`` x ``height`` image by
    :data:`PRINCIPAL_POINT_MARGIN` of its size; else what is wrong (K (3, 3) pixels)."""
    for axis, name, size in ((0, 'cx', width), (1, 'cy', height)):
        low, high = PRINCIPAL_POINT_MARGIN * size, (1 - PRINCIPAL_POINT_MARGIN) * size
        if not low <= K[axis, 2] <= high:
            return (f'principal point {name} = {K[axis, 2]:g} px is not inside the {width} x '
                    f'{height} image (within {PRINCIPAL_POINT_MARGIN:.0%} of its edges or '
                    'beyond): a K made for another image size?')
    return ''


def intrinsics_to_camera_info(K: np.ndarray, width: int, height: int, stamp_ns: int, frame_id: str,
                              types: MessageTypes) -> Any:
    """K (3, 3) pixels and image size → CameraInfo of the optical frame ``frame_id``.

    plumb_bob with 5 zero coefficients, R = I, P = [K | 0], no binning, empty ROI.
    """
    where = 'intrinsics_to_camera_info'
    K = _intrinsics(K, where)
    width, height = _size(width, 'width', where), _size(height, 'height', where)
    P = np.hstack([K, np.zeros((3, 1))])
    roi = types.get('sensor_msgs/msg/RegionOfInterest')(x_offset=0, y_offset=0, height=0, width=0,
                                                       do_rectify=False)
    d = np.zeros(PLUMB_BOB_COEFFICIENTS) if types.is_rosbags else [0.0] * PLUMB_BOB_COEFFICIENTS
    return types.get('sensor_msgs/msg/CameraInfo')(
        header=make_header(stamp_ns, frame_id, types), height=height, width=width,
        distortion_model=PLUMB_BOB, d=d, k=K.reshape(9), r=np.eye(3).reshape(9), p=P.reshape(12),
        binning_x=0, binning_y=0, roi=roi)
