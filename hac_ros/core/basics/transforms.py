"""Rotation and pose helpers: interpolation, rotation vectors, checks, the base's offset."""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation, Slerp


def interpolate_pose(stamp_ns: int, t0_ns: int, R0: np.ndarray, c0: np.ndarray,
                     t1_ns: int, R1: np.ndarray, c1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """SE(3) interpolation at ``stamp_ns`` between two camera-to-map poses: slerp and lerp."""
    if t1_ns == t0_ns:
        return np.asarray(R0), np.asarray(c0)
    alpha = (stamp_ns - t0_ns) / (t1_ns - t0_ns)
    slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([R0, R1])))
    R = slerp([alpha]).as_matrix()[0]
    c = (1.0 - alpha) * np.asarray(c0) + alpha * np.asarray(c1)
    return R, c


NEAR_HALF_TURN_RAD = math.pi - 1e-2  # beyond this the skew part no longer gives the axis well


def rotation_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) rad of the rotation matrix R (3, 3): the angle from atan2 of the skew
    part's norm and the trace (exact at small angles), about the skew part's axis; near a half
    turn, scipy's. In closed form because the odometry takes one per SLAM pose, where scipy's
    cost about 0.5 ms (docs/benchmarks.md, replay throughput)."""
    R = np.asarray(R, dtype=float)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    sin2 = math.sqrt(float(w @ w))  # 2 sin(angle)
    angle = math.atan2(0.5 * sin2, 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0))
    if angle > NEAR_HALF_TURN_RAD:
        return Rotation.from_matrix(R).as_rotvec()
    if sin2 < 1e-12:
        return 0.5 * w
    return (angle / sin2) * w


def is_rotation(R: np.ndarray, tol: float = 1e-6) -> bool:
    """Is R a finite proper rotation (3, 3): max |RᵀR − I| <= tol and det R > 0?"""
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3) or not np.isfinite(R).all():
        return False
    return bool(np.abs(R.T @ R - np.eye(3)).max() <= tol and np.linalg.det(R) > 0.0)


def base_from_camera(base_to_camera: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """The base's pose in the camera frame (R (3, 3), t (3,) metres) from the camera's pose in the
    base frame (``base_to_camera``: x y z metres, qx qy qz qw)."""
    t_bc = np.asarray(base_to_camera[:3], dtype=float)
    R_bc = Rotation.from_quat(base_to_camera[3:]).as_matrix()
    return R_bc.T, -R_bc.T @ t_bc
