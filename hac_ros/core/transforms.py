"""SE(3)/Sim(3) helpers, the metric camera and the world-frame humans (SPEC, method step 6).

Without a reset the metric frame is the SLAM map frame scaled: camera centre ``s·c_t`` and world
joints ``R_wc J + s·c_t``. After a SLAM re-initialisation the new map is *anchored*: an SE(3)
``(R_anchor, p_anchor)`` and a reference centre ``c_ref`` (in the new map's SLAM units) chosen so
that the camera's metric pose is continuous at the reset whatever the new scale turns out to be:
``p_metric = p_anchor + R_anchor · s · (c − c_ref)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation, Slerp


@dataclass
class Anchor:
    """Places one SLAM map (one segment between re-initialisations) in the metric frame.

    rotation: (3, 3), SLAM map frame to metric frame; position_metric: (3,) metres, metric frame,
    where ``centre_slam`` lands; centre_slam: (3,) SLAM units, SLAM map frame.
    """

    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    position_metric: np.ndarray = field(default_factory=lambda: np.zeros(3))
    centre_slam: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        # the anchor of the first map is the identity: the metric frame is the map frame scaled
        self._identity = bool(np.array_equal(self.rotation, np.eye(3))
                              and not np.any(self.position_metric) and not np.any(self.centre_slam))

    def camera(self, R_wc: np.ndarray, c_map: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
        """Metric camera pose: (R camera→metric (3,3), centre (3,) metres, metric frame).

        R_wc: (3, 3) camera to SLAM map; c_map: (3,) camera centre, SLAM units, map frame.
        """
        if self._identity:
            return R_wc, scale * c_map
        R_metric = self.rotation @ R_wc
        p_metric = self.position_metric + self.rotation @ (scale * (np.asarray(c_map) - self.centre_slam))
        return R_metric, p_metric

    def joints(self, R_wc: np.ndarray, c_map: np.ndarray, scale: float,
               joints_cam: np.ndarray) -> np.ndarray:
        """World joints ``R J + p`` (SPEC: J^w = R_tᵀ J + s·o_t), every person.

        joints_cam: (P, 24, 3) metres, camera optical frame. Returns (P, 24, 3) metres, metric frame.
        """
        R_metric, p_metric = self.camera(R_wc, c_map, scale)
        return np.asarray(joints_cam) @ R_metric.T + p_metric

    @classmethod
    def continuing(cls, R_metric_prev: np.ndarray, p_metric_prev: np.ndarray,
                   R_wc_new: np.ndarray, c_new: np.ndarray) -> 'Anchor':
        """The anchor of a new map whose first pose (R_wc_new, c_new) continues the last metric pose."""
        rotation = np.asarray(R_metric_prev) @ np.asarray(R_wc_new).T
        return cls(rotation, np.asarray(p_metric_prev, dtype=float).copy(),
                   np.asarray(c_new, dtype=float).copy())


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


def rotation_angle(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle (rad) of the relative rotation R_aᵀ R_b."""
    cos = (np.trace(np.asarray(R_a).T @ np.asarray(R_b)) - 1.0) * 0.5
    return float(np.arccos(np.clip(cos, -1.0, 1.0)))


def rotation_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) rad of R (closed form; scipy beyond 3 rad where it is ill-conditioned)."""
    return rotation_log_entries(*np.asarray(R, dtype=float).ravel().tolist())


def rotation_log_entries(a: float, b: float, c: float, d: float, e: float, f: float, g: float,
                         h: float, i: float) -> np.ndarray:
    """:func:`rotation_log` of the rotation matrix with these entries (row-major, plain floats),
    for a caller that computed them in plain floats."""
    angle = math.acos(min(max((a + e + i - 1.0) * 0.5, -1.0), 1.0))
    skew = np.array([h - f, c - g, d - b])
    if angle < 1e-8:
        return 0.5 * skew
    if angle > 3.0:
        return Rotation.from_matrix([[a, b, c], [d, e, f], [g, h, i]]).as_rotvec()
    return skew * (angle / (2.0 * math.sin(angle)))


def rotation_defects(R: np.ndarray) -> tuple[float, float] | None:
    """(max |RᵀR − I|, det R) of a (3, 3) float matrix, or None when it is not finite.

    Plain floats: ~5x faster than the numpy calls for one matrix (every pose in and out).
    """
    a, b, c, d, e, f, g, h, i = R.ravel().tolist()
    if not math.isfinite(a + b + c + d + e + f + g + h + i):
        return None
    orthogonality = max(abs(a * a + d * d + g * g - 1.0), abs(b * b + e * e + h * h - 1.0),
                        abs(c * c + f * f + i * i - 1.0), abs(a * b + d * e + g * h),
                        abs(a * c + d * f + g * i), abs(b * c + e * f + h * i))
    return orthogonality, a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


def is_rotation(R: np.ndarray, tol: float = 1e-6) -> bool:
    """Is R a finite proper rotation (3, 3): max |RᵀR − I| <= tol and det R > 0?"""
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3):
        return False
    defects = rotation_defects(R)
    return defects is not None and defects[0] <= tol and defects[1] > 0.0
