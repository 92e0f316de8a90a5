"""Pose messages ↔ (R, c); quaternions are scalar-last (x, y, z, w), as in ROS and scipy.

A SLAM pose message is the camera's pose in the SLAM map frame (hac_ros' docs/interface.md,
"Conventions"): the readers return **camera-to-map** ``(R_wc (3, 3), c (3,))`` — the rotation from
the camera frame to the map frame and the camera centre in map coordinates, in SLAM units. The
builders take the same pair for any parent/child frames (e.g. the metric world and the camera,
metres).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from msg_adapters.errors import MessageError
from msg_adapters.stamps import make_header
from msg_adapters.types import MessageTypes

# |‖q‖ − 1| up to this is float rounding of a unit quaternion (float32 publishers, text
# round-trips) and is normalised away; beyond it the message is not a rotation and is refused.
QUATERNION_NORM_TOL = 1e-3
# max |RᵀR − I| and |det R − 1| accepted by the builders: a rotation that went through float64
# arithmetic is within 1e-12; anything further is not a rotation (scipy would silently project it).
ROTATION_TOL = 1e-6
POSE_NESTING = 3  # Pose, PoseStamped.pose, Odometry/PoseWithCovarianceStamped .pose.pose


def quat_to_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Quaternion (x, y, z, w) → rotation matrix (3, 3) float64.

    Normalised when |‖q‖ − 1| <= QUATERNION_NORM_TOL; MessageError when not finite or further off.
    """
    try:
        q = [float(x), float(y), float(z), float(w)]
    except (TypeError, ValueError) as exc:
        raise MessageError(f'quaternion (x, y, z, w) is not 4 numbers ({exc})') from exc
    if not all(math.isfinite(v) for v in q):
        raise MessageError(f'quaternion (x, y, z, w) is not finite: {q}')
    norm = math.hypot(*q)  # no overflow for huge components
    if not abs(norm - 1.0) <= QUATERNION_NORM_TOL:
        raise MessageError(f'quaternion (x, y, z, w) = {q} has norm {norm:.9g}; expected '
                           f'1 within {QUATERNION_NORM_TOL}')
    x, y, z, w = (v / norm for v in q)
    # the textbook formula in plain floats (runs for every input pose)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz, wx, wy, wz = x * y, x * z, y * z, w * x, w * y, w * z
    return np.array([[1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)],
                     [2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)],
                     [2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)]])


def matrix_to_quat(R: np.ndarray) -> tuple[float, float, float, float]:
    """Rotation matrix (3, 3) → unit quaternion (x, y, z, w) as Python floats, w >= 0.

    MessageError when R is not a finite proper rotation (within ROTATION_TOL).
    """
    try:
        R = np.asarray(R, dtype=float)
    except (TypeError, ValueError) as exc:
        raise MessageError(f'rotation: expected a (3, 3) matrix ({exc})') from exc
    if R.shape != (3, 3):
        raise MessageError(f'rotation: expected a (3, 3) matrix, got shape {R.shape}')
    if not np.isfinite(R).all():
        raise MessageError(f'rotation is not finite: {R.tolist()}')
    orthogonality = float(np.abs(R.T @ R - np.eye(3)).max())
    determinant = float(np.linalg.det(R))
    if orthogonality > ROTATION_TOL or abs(determinant - 1.0) > ROTATION_TOL:
        raise MessageError(f'rotation: not a rotation matrix (max |RᵀR − I| = {orthogonality:.3g}, '
                           f'det = {determinant:.6g})')
    # Shepperd's method in plain floats (every published pose): the largest of 4w², 4x², 4y², 4z²
    # gives a well-conditioned division
    a, b, c, d, e, f, g, h, i = R.ravel().tolist()
    trace = a + e + i
    best = max(trace, a, e, i)
    if best == trace:
        w = math.sqrt(1.0 + trace) * 2.0
        q = ((h - f) / w, (c - g) / w, (d - b) / w, 0.25 * w)
    elif best == a:
        x = math.sqrt(1.0 + a - e - i) * 2.0
        q = (0.25 * x, (b + d) / x, (c + g) / x, (h - f) / x)
    elif best == e:
        y = math.sqrt(1.0 + e - a - i) * 2.0
        q = ((b + d) / y, 0.25 * y, (f + h) / y, (c - g) / y)
    else:
        z = math.sqrt(1.0 + i - a - e) * 2.0
        q = ((c + g) / z, (f + h) / z, 0.25 * z, (d - b) / z)
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    sign = -1.0 if q[3] < 0 else 1.0
    x, y, z, w = (sign * v / norm for v in q)
    return x, y, z, w


def pose_to_rt(pose: Any) -> tuple[np.ndarray, np.ndarray]:
    """``geometry_msgs/Pose`` → (R (3, 3) float64, c (3,) float64).

    For a SLAM pose: R_wc (camera to map) and c the camera centre, map frame, SLAM units.
    MessageError for a non-finite position or orientation, or a quaternion whose norm is not 1
    within QUATERNION_NORM_TOL (a zero quaternion included).
    """
    return _rigid(pose, 'position', 'orientation', 'Pose')


def pose_msg_to_rt(msg: Any) -> tuple[np.ndarray, np.ndarray]:
    """A SLAM pose message → camera-to-map ``(R_wc, c)``.

    Accepts ``geometry_msgs/PoseStamped`` (``msg.pose``), ``nav_msgs/Odometry`` and
    ``geometry_msgs/PoseWithCovarianceStamped`` (``msg.pose.pose``), ``PoseWithCovariance`` or a
    bare ``Pose``, dispatching on attributes. Returns R_wc: (3, 3) float64, rotation from the
    camera frame to the map frame; c: (3,) float64, camera centre in the map frame, SLAM units.
    """
    node = msg
    for _ in range(POSE_NESTING):
        if hasattr(node, 'position') and hasattr(node, 'orientation'):
            return pose_to_rt(node)
        node = getattr(node, 'pose', None)
        if node is None:
            break
    raise MessageError(f'{type(msg).__name__}: expected a Pose, PoseStamped, PoseWithCovariance'
                       f'(Stamped) or Odometry (no pose with position and orientation found)')


def transform_to_rt(msg: Any) -> tuple[np.ndarray, np.ndarray]:
    """``geometry_msgs/TransformStamped`` (or ``Transform``) → (R (3, 3) child-to-parent rotation,
    t (3,) the child's origin in the parent frame, its unit).

    MessageError for a non-finite translation or rotation, or a quaternion whose norm is not 1
    within QUATERNION_NORM_TOL.
    """
    transform = getattr(msg, 'transform', msg)
    return _rigid(transform, 'translation', 'rotation', 'Transform')


def _rigid(msg: Any, where: str, turn: str, what: str) -> tuple[np.ndarray, np.ndarray]:
    """A Pose (``position``, ``orientation``) or Transform (``translation``, ``rotation``) → (R
    (3, 3) float64, the rotation; c (3,) float64, the position, its unit); MessageError naming
    ``what`` for a missing field, a non-finite position or a quaternion not of norm 1."""
    try:
        v, q = getattr(msg, where), getattr(msg, turn)
        c = np.array([v.x, v.y, v.z], dtype=float)
        quat = (q.x, q.y, q.z, q.w)
    except (AttributeError, TypeError, ValueError) as exc:
        raise MessageError(f'{what}: expected {where} (x, y, z) and {turn} (x, y, z, w) '
                           f'({exc})') from exc
    if not np.isfinite(c).all():
        raise MessageError(f'{what}: {where} is not finite: {c.tolist()}')
    try:
        R = quat_to_matrix(*quat)
    except MessageError as exc:
        raise MessageError(f'{what}: {turn}: {exc}') from exc
    return R, c


def _vector(v: Any, what: str) -> tuple[float, float, float]:
    """A finite 3-vector as Python floats (rclpy float fields refuse numpy scalars)."""
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError) as exc:
        raise MessageError(f'{what}: expected 3 numbers ({exc})') from exc
    if a.shape != (3,):
        raise MessageError(f'{what}: expected shape (3,), got {a.shape}')
    if not np.isfinite(a).all():
        raise MessageError(f'{what} is not finite: {a.tolist()}')
    x, y, z = a.tolist()
    return x, y, z


def _covariance(cov: Any, what: str) -> np.ndarray:
    """(6, 6) or (36,) → (36,) float64 row-major (ROS order x, y, z, rot x, rot y, rot z)."""
    if cov is None:
        return np.zeros(36)
    try:
        a = np.array(cov, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise MessageError(f'{what}: expected a (6, 6) matrix ({exc})') from exc
    if a.shape not in ((6, 6), (36,)):
        raise MessageError(f'{what}: expected shape (6, 6) or (36,), got {a.shape}')
    return a.reshape(36)


def rt_to_pose(R: np.ndarray, c: np.ndarray, types: MessageTypes) -> Any:
    """(R (3, 3) child-to-parent rotation, c (3,) child origin in the parent frame) → Pose."""
    x, y, z, w = matrix_to_quat(R)
    px, py, pz = _vector(c, 'position')
    return types.get('geometry_msgs/msg/Pose')(
        position=types.get('geometry_msgs/msg/Point')(x=px, y=py, z=pz),
        orientation=types.get('geometry_msgs/msg/Quaternion')(x=x, y=y, z=z, w=w))


def rt_to_pose_stamped(R: np.ndarray, c: np.ndarray, stamp_ns: int, frame_id: str,
                       types: MessageTypes) -> Any:
    """Camera-to-``frame_id`` (R_wc (3, 3), c (3,) in ``frame_id``'s unit) → PoseStamped."""
    return types.get('geometry_msgs/msg/PoseStamped')(
        header=make_header(stamp_ns, frame_id, types), pose=rt_to_pose(R, c, types))


def _pose_with_covariance(R: np.ndarray, c: np.ndarray, covariance: Any, what: str,
                          types: MessageTypes) -> Any:
    return types.get('geometry_msgs/msg/PoseWithCovariance')(
        pose=rt_to_pose(R, c, types), covariance=_covariance(covariance, what))


def rt_to_pose_with_covariance_stamped(R: np.ndarray, c: np.ndarray, stamp_ns: int,
                                       frame_id: str, types: MessageTypes,
                                       covariance: Any = None) -> Any:
    """``geometry_msgs/PoseWithCovarianceStamped``: R (3, 3) child-to-``frame_id`` rotation, c (3,)
    child origin in ``frame_id`` (its unit), covariance (6, 6) or None (zeros), ROS order."""
    return types.get('geometry_msgs/msg/PoseWithCovarianceStamped')(
        header=make_header(stamp_ns, frame_id, types),
        pose=_pose_with_covariance(R, c, covariance, 'PoseWithCovarianceStamped: covariance',
                                   types))


def rt_to_odometry(R: np.ndarray, c: np.ndarray, stamp_ns: int, frame_id: str, child_frame_id: str,
                   types: MessageTypes, covariance: Any = None, linear: Any = None,
                   angular: Any = None, twist_covariance: Any = None) -> Any:
    """``nav_msgs/Odometry``: the pose of ``child_frame_id`` in ``frame_id``.

    R: (3, 3) child-to-parent rotation; c: (3,) child origin in ``frame_id`` (its unit);
    covariance: pose covariance (6, 6) or None (zeros); linear: (3,) m/s and angular: (3,) rad/s
    in the child frame, or None (zeros); twist_covariance: (6, 6) or None (zeros).
    """
    t = types
    vx, vy, vz = (0.0, 0.0, 0.0) if linear is None else _vector(linear, 'Odometry: linear velocity')
    wx, wy, wz = (0.0, 0.0, 0.0) if angular is None else _vector(angular,
                                                                 'Odometry: angular velocity')
    Vector3 = t.get('geometry_msgs/msg/Vector3')
    return t.get('nav_msgs/msg/Odometry')(
        header=make_header(stamp_ns, frame_id, t), child_frame_id=child_frame_id,
        pose=_pose_with_covariance(R, c, covariance, 'Odometry: covariance', t),
        twist=t.get('geometry_msgs/msg/TwistWithCovariance')(
            twist=t.get('geometry_msgs/msg/Twist')(linear=Vector3(x=vx, y=vy, z=vz),
                                                   angular=Vector3(x=wx, y=wy, z=wz)),
            covariance=_covariance(twist_covariance, 'Odometry: twist covariance')))


def rt_to_transform_stamped(R: np.ndarray, t: np.ndarray, stamp_ns: int, frame_id: str,
                            child_frame_id: str, types: MessageTypes) -> Any:
    """``geometry_msgs/TransformStamped`` (tf): ``child_frame_id`` → ``frame_id``.

    R: (3, 3) child-to-parent rotation; t: (3,) child origin in ``frame_id`` (its unit).
    """
    x, y, z, w = matrix_to_quat(R)
    tx, ty, tz = _vector(t, 'translation')
    return types.get('geometry_msgs/msg/TransformStamped')(
        header=make_header(stamp_ns, frame_id, types), child_frame_id=child_frame_id,
        transform=types.get('geometry_msgs/msg/Transform')(
            translation=types.get('geometry_msgs/msg/Vector3')(x=tx, y=ty, z=tz),
            rotation=types.get('geometry_msgs/msg/Quaternion')(x=x, y=y, z=z, w=w)))
