"""Pose messages ↔ (R, c).

A SLAM pose message is the camera's pose in the SLAM map frame (SPEC, conventions): the readers
return **camera-to-map** ``(R_wc (3, 3), c (3,))`` — the rotation from the camera frame to the map
frame and the camera centre in map coordinates, SLAM units.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from msg_adapters.errors import MessageError
from msg_adapters.stamps import make_header
from msg_adapters.types import MessageTypes

QUATERNION_NORM_TOL = 1e-2  # |‖q‖ − 1| up to this is rounding and is normalised; beyond it, an error


def quat_to_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Unit quaternion (x, y, z, w) → rotation matrix (3, 3)."""
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quat(R: np.ndarray) -> tuple[float, float, float, float]:
    """Rotation matrix (3, 3) → unit quaternion (x, y, z, w), w >= 0."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat()
    if q[3] < 0:
        q = -q
    return float(q[0]), float(q[1]), float(q[2]), float(q[3])


def pose_to_rt(pose: Any) -> tuple[np.ndarray, np.ndarray]:
    """``geometry_msgs/Pose`` → (R (3, 3), t (3,)); for a SLAM pose: camera-to-map, camera centre."""
    try:
        p, q = pose.position, pose.orientation
        t = np.array([float(p.x), float(p.y), float(p.z)])
        x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    except (AttributeError, TypeError, ValueError) as exc:
        raise MessageError(f'Pose: expected position and orientation ({exc})') from exc
    if not np.all(np.isfinite(t)):
        raise MessageError(f'Pose: position is not finite: {t.tolist()}')
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(norm) or abs(norm - 1.0) > QUATERNION_NORM_TOL:
        raise MessageError(f'Pose: orientation is not a unit quaternion (norm {norm:.6g})')
    return quat_to_matrix(x / norm, y / norm, z / norm, w / norm), t


def pose_msg_to_rt(msg: Any) -> tuple[np.ndarray, np.ndarray]:
    """PoseStamped, Odometry, PoseWithCovariance(Stamped) or Pose → camera-to-map (R_wc, c).

    R_wc: (3, 3) camera to map frame; c: (3,) camera centre, SLAM units, map frame.
    """
    inner = msg
    for _ in range(2):  # Odometry.pose.pose, PoseWithCovarianceStamped.pose.pose, PoseStamped.pose
        if hasattr(inner, 'position'):
            break
        inner = getattr(inner, 'pose', None)
        if inner is None:
            raise MessageError(f'{type(msg).__name__}: no pose in this message')
    return pose_to_rt(inner)


def rt_to_pose(R: np.ndarray, t: np.ndarray, types: MessageTypes) -> Any:
    x, y, z, w = matrix_to_quat(R)
    return types.get('geometry_msgs/msg/Pose')(
        position=types.get('geometry_msgs/msg/Point')(x=float(t[0]), y=float(t[1]), z=float(t[2])),
        orientation=types.get('geometry_msgs/msg/Quaternion')(x=x, y=y, z=z, w=w))


def rt_to_pose_stamped(R: np.ndarray, c: np.ndarray, stamp_ns: int, frame_id: str,
                       types: MessageTypes) -> Any:
    return types.get('geometry_msgs/msg/PoseStamped')(
        header=make_header(stamp_ns, frame_id, types), pose=rt_to_pose(R, c, types))


def _vector3(v: Any, types: MessageTypes) -> Any:
    v = np.zeros(3) if v is None else np.asarray(v, dtype=float)
    return types.get('geometry_msgs/msg/Vector3')(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _covariance(cov: Any) -> np.ndarray:
    return np.zeros(36) if cov is None else np.ascontiguousarray(cov, dtype=np.float64).reshape(36)


def rt_to_odometry(R: np.ndarray, c: np.ndarray, stamp_ns: int, frame_id: str, child_frame_id: str,
                   types: MessageTypes, covariance: Any = None, linear: Any = None,
                   angular: Any = None, twist_covariance: Any = None) -> Any:
    """``nav_msgs/Odometry``: pose of ``child_frame_id`` in ``frame_id``; twist in the child frame."""
    t = types
    return t.get('nav_msgs/msg/Odometry')(
        header=make_header(stamp_ns, frame_id, t), child_frame_id=child_frame_id,
        pose=t.get('geometry_msgs/msg/PoseWithCovariance')(pose=rt_to_pose(R, c, t),
                                                           covariance=_covariance(covariance)),
        twist=t.get('geometry_msgs/msg/TwistWithCovariance')(
            twist=t.get('geometry_msgs/msg/Twist')(linear=_vector3(linear, t),
                                                   angular=_vector3(angular, t)),
            covariance=_covariance(twist_covariance)))


def rt_to_transform_stamped(R: np.ndarray, t: np.ndarray, stamp_ns: int, frame_id: str,
                            child_frame_id: str, types: MessageTypes) -> Any:
    x, y, z, w = matrix_to_quat(R)
    return types.get('geometry_msgs/msg/TransformStamped')(
        header=make_header(stamp_ns, frame_id, types), child_frame_id=child_frame_id,
        transform=types.get('geometry_msgs/msg/Transform')(
            translation=_vector3(t, types),
            rotation=types.get('geometry_msgs/msg/Quaternion')(x=x, y=y, z=z, w=w)))
