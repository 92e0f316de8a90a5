"""``sensor_msgs/CameraInfo`` ↔ intrinsics K (3, 3) and image size."""
from __future__ import annotations

from typing import Any

import numpy as np

from msg_adapters.errors import MessageError
from msg_adapters.stamps import make_header
from msg_adapters.types import MessageTypes


def camera_info_to_intrinsics(msg: Any) -> tuple[np.ndarray, int, int]:
    """CameraInfo → (K (3, 3) float64 pixels, width, height)."""
    try:
        K = np.asarray(msg.k, dtype=float).reshape(3, 3)
        width, height = int(msg.width), int(msg.height)
    except (AttributeError, TypeError, ValueError) as exc:
        raise MessageError(f'CameraInfo: expected k (9 values), width and height ({exc})') from exc
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise MessageError(f'CameraInfo: K is not a valid camera matrix: {K.ravel().tolist()}')
    if width <= 0 or height <= 0:
        raise MessageError(f'CameraInfo: image size {width}x{height} is empty')
    return K, width, height


def intrinsics_to_camera_info(K: np.ndarray, width: int, height: int, stamp_ns: int, frame_id: str,
                              types: MessageTypes) -> Any:
    """A pinhole CameraInfo (plumb_bob, zero distortion, R = I, P = [K | 0])."""
    K = np.asarray(K, dtype=float).reshape(3, 3)
    P = np.hstack([K, np.zeros((3, 1))])
    roi = types.get('sensor_msgs/msg/RegionOfInterest')(x_offset=0, y_offset=0, height=0, width=0,
                                                       do_rectify=False)
    d = np.zeros(5) if types.is_rosbags else [0.0] * 5
    return types.get('sensor_msgs/msg/CameraInfo')(
        header=make_header(stamp_ns, frame_id, types), height=int(height), width=int(width),
        distortion_model='plumb_bob', d=d, k=K.ravel().copy(), r=np.eye(3).ravel(), p=P.ravel(),
        binning_x=0, binning_y=0, roi=roi)
