"""``/hac/odometry``: continuous metric odometry, a running sum of metric steps (docs/interface.md,
"Topics").

REP-105 odometry must not jump. Each step is the SLAM's own step taken with the scale of its
moment, so a change of the estimate (or of the metric frame's alignment) changes no past step:

    orientation_t = orientation_{t-1} · (R_wc,t-1ᵀ R_wc,t)
    position_t    = position_{t-1} + R_odom,t-1 · R_wc,t-1ᵀ · s_t · (c_t − c_{t-1})

with R_wc, c the SLAM camera-to-map pose and s_t the estimate published with pose t. It starts at
the first published ``/hac/pose``. Across a SLAM re-initialisation the step counts as zero (two
maps have no common frame); while the new segment converges the odometry pauses, and at convergence
the steps since the reset are summed with the new scale and it resumes from there, its first
message with zero twist and a covariance that covers the gap. A rejected outlier pose never reaches
here: the next step starts from the last accepted pose.

Covariance (odometry semantics): the position's variance grows with the distance travelled,
``floor + (σ_rel · distance)²`` per axis, σ_rel combining the scale's relative standard error and
the SLAM's own drift per metre (:data:`SLAM_DRIFT_REL`); the orientation's with the rotation
travelled. The twist's covariance follows the same relative error. Pure numpy; metres, radians.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import OdometryOut
from hac_ros.core.basics.transforms import rotation_log

POSITION_VARIANCE_FLOOR = 1e-6  # m², keeps the covariance positive definite
SLAM_DRIFT_REL = 0.01  # a monocular SLAM's relative drift per metre travelled
ROTATION_DRIFT_REL = 0.01  # ... and per radian turned
TWIST_VARIANCE_FLOOR = 1e-4  # (m/s)², (rad/s)²


@dataclass
class _Pose:
    stamp_ns: int
    R_wc: np.ndarray  # (3, 3) camera to SLAM map
    c_map: np.ndarray  # (3,) SLAM units


class ContinuousOdometry:
    """The odometry of the camera (or of the base: ``base_from_camera``, the base's pose in the
    camera frame (R (3, 3), t (3,) metres)); ``orientation_variance``: rad², the floor of each
    orientation axis."""

    def __init__(self, base_from_camera: tuple[np.ndarray, np.ndarray] | None,
                 orientation_variance: float) -> None:
        self.base_from_camera = base_from_camera
        self.orientation_variance = orientation_variance
        self.rotation: np.ndarray | None = None  # camera to odom frame (3, 3)
        self.position = np.zeros(3)  # camera centre, metres, odom frame
        self.distance = 0.0  # metres travelled
        self.turned = 0.0  # radians turned
        self._last: _Pose | None = None  # the last pose integrated (in the current segment)
        self._gap: list[_Pose] = []  # poses of a new segment waiting for its scale
        self._out: tuple[int, np.ndarray, np.ndarray] | None = None  # last output: stamp, R, p

    @property
    def started(self) -> bool:
        return self.rotation is not None

    def new_segment(self) -> None:
        """A SLAM re-initialisation: the next pose's step counts as zero."""
        self._last = None
        self._gap = []

    def update(self, stamp_ns: int, child_frame_id: str, R_wc: np.ndarray, c_map: np.ndarray,
               scale: float | None, sigma_rel: float,
               start: tuple[np.ndarray, np.ndarray] | None) -> OdometryOut | None:
        """One SLAM pose. scale: the estimate published with it (None: not converged: pause);
        sigma_rel: the scale's relative standard error; start: the pose's ``/hac/pose`` (camera
        to metric rotation, centre metres), where the odometry starts. None when nothing is
        published for this pose."""
        pose = _Pose(int(stamp_ns), np.asarray(R_wc, dtype=float), np.asarray(c_map, dtype=float))
        if not self.started:
            if scale is None or start is None:
                return None
            self.rotation = np.array(start[0], dtype=float)
            self.position = np.array(start[1], dtype=float)
            self._last = pose
            return self._output(pose.stamp_ns, child_frame_id, sigma_rel, still=True)
        if self._last is None:  # the first pose of a new segment: a zero step from the last one
            self._last = pose
            if scale is None:
                self._gap = [pose]
                return None
            return self._output(pose.stamp_ns, child_frame_id, sigma_rel, still=True)
        if scale is None:  # a segment converging: integrated once its scale is known
            self._gap.append(pose)
            return None
        resumed = bool(self._gap)
        for waiting in self._gap[1:]:
            self._step(waiting, scale)
        self._gap = []
        self._step(pose, scale)
        return self._output(pose.stamp_ns, child_frame_id, sigma_rel, still=resumed)

    def _step(self, pose: _Pose, scale: float) -> None:
        last = self._last
        assert last is not None and self.rotation is not None
        step_camera = last.R_wc.T @ (pose.c_map - last.c_map) * scale  # metres, camera frame at t-1
        turn = last.R_wc.T @ pose.R_wc
        self.position = self.position + self.rotation @ step_camera
        self.rotation = self.rotation @ turn
        self.distance += float(np.linalg.norm(step_camera))
        self.turned += float(np.linalg.norm(rotation_log(turn)))
        self._last = pose

    def _output(self, stamp_ns: int, child_frame_id: str, sigma_rel: float,
                still: bool) -> OdometryOut:
        """The message of the current state; ``still``: zero twist (the first message, or the
        first after a gap)."""
        assert self.rotation is not None
        R, p = self.rotation, self.position
        if self.base_from_camera is not None:
            R_cb, t_cb = self.base_from_camera
            R, p = R @ R_cb, p + R @ t_cb
        linear, angular = np.zeros(3), np.zeros(3)
        last = self._out
        if not still and last is not None and last[0] < stamp_ns:
            linear, angular = velocities(last[1], last[2], R, p, (stamp_ns - last[0]) / NS)
        self._out = (stamp_ns, R, p)
        rel = math.hypot(SLAM_DRIFT_REL, sigma_rel if math.isfinite(sigma_rel) else 0.0)
        orientation_variance = (self.orientation_variance
                                + (ROTATION_DRIFT_REL * self.turned) ** 2)
        pose_cov = np.diag([POSITION_VARIANCE_FLOOR + (rel * self.distance) ** 2] * 3
                           + [orientation_variance] * 3)
        twist_cov = np.diag([TWIST_VARIANCE_FLOOR + (rel * float(np.linalg.norm(linear))) ** 2] * 3
                            + [TWIST_VARIANCE_FLOOR] * 3)
        return OdometryOut(stamp_ns, child_frame_id, R, p, pose_cov, linear, angular, twist_cov)


def velocities(R_a: np.ndarray, p_a: np.ndarray, R_b: np.ndarray, p_b: np.ndarray,
               dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Twist from pose a to pose b, dt seconds apart, in b's frame: linear (3,) m/s
    ``R_bᵀ (p_b − p_a) / dt`` and angular (3,) rad/s ``log(R_aᵀ R_b) / dt``.

    R_a, R_b: (3, 3) child frame to odom frame; p_a, p_b: (3,) metres.
    """
    return R_b.T @ (p_b - p_a) / dt, rotation_log(R_a.T @ R_b) / dt
