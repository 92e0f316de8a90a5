"""``sensor_msgs/CameraInfo`` ↔ intrinsics K (3, 3) and image size (pinhole, optical frame)."""
from __future__ import annotations

import operator
from typing import Any

import numpy as np

from msg_adapters.errors import MessageError
from msg_adapters.stamps import make_header
from msg_adapters.types import MessageTypes

PLUMB_BOB = 'plumb_bob'
PLUMB_BOB_COEFFICIENTS = 5  # k1, k2, t1, t2, k3


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


def camera_info_to_intrinsics(msg: Any) -> tuple[np.ndarray, int, int]:
    """CameraInfo → (K (3, 3) float64 pixels, width, height in pixels).

    MessageError when K is not 9 finite values with fx, fy > 0, or the image is empty.
    """
    try:
        k, width, height = msg.k, msg.width, msg.height
    except AttributeError as exc:
        raise MessageError(f'CameraInfo: expected k, width and height ({exc})') from exc
    where = 'CameraInfo'
    return _intrinsics(k, where), _size(width, 'width', where), _size(height, 'height', where)


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
