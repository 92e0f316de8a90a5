"""The metric stage: a scale applied to SLAM poses and HMR joints (SPEC, method step 6).

The :class:`~hac_ros.core.calibrator.Calibrator` decides *what* is published and *when* (SPEC's
processing order); this stage decides *with which scale*. It owns what depends on the published
scale: the anchor of each SLAM map (so that the metric camera is continuous across a SLAM
re-initialisation) and the last metric camera pose (for the velocities and the next anchor).

The calibrator hands it ``Pending*`` records that hold the SLAM-unit quantities of an output.
Online (``hac_node``, ``hac replay --mode online``) each record is resolved at once with the
current estimate. Offline (the replay's default mode) the calibrator *defers*: it returns the
records among its other outputs, and once the whole recording's schedule is known
:meth:`MetricStage.resolve` turns them, in their order, into the very outputs a second run with that
schedule would give, so the second pass needs neither the recording nor its maps again.

Pure numpy. Stamps are int nanoseconds; scales are metres per SLAM unit (None: nothing metric).
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable, Iterable

import numpy as np

from hac_ros.core.humans import RootFilter
from hac_ros.core.numeric import NS
from hac_ros.core.outputs import (PENDING, DiagnosticsOut, HumanJointsOut, OdometryOut, Output,
                                  PendingFrame, PendingOdometry, PendingReset, PendingStatus,
                                  ScaleOut, Status)
from hac_ros.core.transforms import Anchor, rotation_log_entries

POSITION_VARIANCE_FLOOR = 1e-6  # m², keeps the published covariance positive definite

# stamp ns -> published scale (metres per SLAM unit); None, NaN or <= 0: nothing metric then
ScaleAt = Callable[[int], 'float | None']





class MetricStage:
    """Applies a published scale to pending outputs, keeping the anchor and the last metric pose.

    base_from_camera: the base's pose in the camera frame (R (3, 3), t (3,) metres), or None to
    publish the camera itself; orientation_variance: rad², the odometry's orientation covariance;
    humans: the online filter of the world humans (hac_ros.core.humans.RootFilter) or None.
    """

    def __init__(self, base_from_camera: tuple[np.ndarray, np.ndarray] | None,
                 orientation_variance: float, humans: RootFilter | None = None) -> None:
        self.anchor = Anchor()
        self.base_from_camera = base_from_camera
        self.orientation_variance = orientation_variance
        self.humans = humans
        # camera, metric frame: (stamp ns, R camera->metric (3, 3), centre (3,) metres)
        self.last_metric: tuple[int, np.ndarray, np.ndarray] | None = None
        # the odometry covariance without the scale's share: position floor, orientation variance
        self._covariance_floor = np.diag([POSITION_VARIANCE_FLOOR] * 3 + [orientation_variance] * 3)

    def fresh(self) -> 'MetricStage':
        """A new stage with this one's configuration (identity anchor, no metric pose yet), for
        resolving deferred outputs: without the online filter of the humans (offline they are
        smoothed over the whole recording, :func:`hac_ros.core.humans.smooth_people`)."""
        return MetricStage(self.base_from_camera, self.orientation_variance)

    def resolve(self, outputs: Iterable[Output], scale_at: ScaleAt,
                error_at: Callable[[int], float] | None = None) -> list[Output]:
        """Outputs with every pending record replaced by its metric output(s), in order.

        error_at: stamp -> standard error of that scale (metres per SLAM unit), for the odometry's
        covariance; None: the online estimate's, recorded in each pending odometry.
        """
        out: list[Output] = []
        for output in outputs:
            if isinstance(output, PENDING):
                out += self.apply(output, scale_at, error_at)
            else:
                out.append(output)
        return out

    def apply(self, pending: object, scale_at: ScaleAt,
              error_at: Callable[[int], float] | None = None) -> list[Output]:
        """One pending record -> its outputs with the scale ``scale_at`` gives at its stamp."""
        if isinstance(pending, PendingOdometry):
            sigma = pending.sigma_scale if error_at is None else error_at(pending.stamp_ns)
            return self._odometry(pending, finite_scale(scale_at(pending.stamp_ns)), sigma)
        if isinstance(pending, PendingFrame):
            scale = finite_scale(scale_at(pending.stamp_ns))
            if scale is None:
                return []
            joints = self.anchor.joints(pending.R_wc, pending.c_map, scale, pending.joints_cam)
            if self.humans is not None:
                joints = self.humans.update(pending.stamp_ns, joints)
            return [HumanJointsOut(pending.stamp_ns, joints),
                    ScaleOut(pending.stamp_ns, scale, pending.spread)]
        if isinstance(pending, PendingReset):
            if self.last_metric is not None:
                _, R_metric, p_metric = self.last_metric
                self.anchor = Anchor.continuing(R_metric, p_metric, pending.R_wc, pending.c_map)
            return []
        if isinstance(pending, PendingStatus):
            scale = finite_scale(scale_at(pending.status.stamp_ns))
            return [DiagnosticsOut(self.status(pending, scale))]
        raise TypeError(f'not a pending output: {type(pending).__name__}')

    def status(self, pending: PendingStatus, scale: float | None) -> Status:
        """The status with its metric ground plane: the down normal and the plane point below the
        camera, in the metric frame (None before a scale or without a plane)."""
        plane, c_map = pending.plane, pending.c_map
        if plane is None or c_map is None or scale is None:
            return pending.status
        foot_map = c_map + (plane.offset - plane.normal @ c_map) * plane.normal
        return replace(pending.status, ground_normal_metric=self.anchor.rotation @ plane.normal,
                       ground_point_metric=self.anchor.camera(np.eye(3), foot_map, scale)[1])

    def _odometry(self, pending: PendingOdometry, scale: float | None,
                  sigma_scale: float) -> list[Output]:
        if scale is None:
            return []
        stamp = pending.stamp_ns
        R_metric, p_metric = self.anchor.camera(pending.R_wc, pending.c_map, scale)
        last = self.last_metric
        self.last_metric = (stamp, R_metric, p_metric)
        R_out, p_out = R_metric, p_metric
        if self.base_from_camera is not None:
            R_cb, t_cb = self.base_from_camera  # base pose in the camera frame
            R_out, p_out = R_metric @ R_cb, p_metric + R_metric @ t_cb
        linear, angular = np.zeros(3), np.zeros(3)
        if last is not None and last[0] < stamp:
            dt = (stamp - last[0]) / NS
            R_prev, p_prev = last[1], last[2]
            if self.base_from_camera is not None:
                R_prev, p_prev = R_prev @ R_cb, p_prev + R_prev @ t_cb
            linear, angular = _velocities(R_prev, p_prev, R_out, p_out, dt)
        # position uncertainty from the scale's: sigma_s * |metric lever arm per unit scale|
        # (a scale without a known error, e.g. a given one before any sample: the floor alone)
        cov = self._covariance_floor.copy()
        if math.isfinite(sigma_scale):
            lever = self.anchor.rotation @ (pending.c_map - self.anchor.centre_slam)
            cov[:3, :3] += sigma_scale ** 2 * (lever[:, None] * lever)
        return [OdometryOut(stamp, pending.child_frame_id, R_out, p_out, cov, linear, angular)]


def _velocities(R_a: np.ndarray, p_a: np.ndarray, R_b: np.ndarray, p_b: np.ndarray,
                dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Twist from pose a to pose b, dt seconds apart, in b's frame: linear (3,) m/s
    ``R_bᵀ (p_b − p_a) / dt`` and angular (3,) rad/s ``log(R_aᵀ R_b) / dt``.

    R_a, R_b: (3, 3) child frame to metric frame; p_a, p_b: (3,) metres, metric frame. Plain
    Python floats: every published pose pays for this, and numpy's per-call cost dominates 3x3
    algebra (the same values as numpy to rounding: numpy's products may use fused multiply-adds).
    """
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = R_a.ravel().tolist()
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = R_b.ravel().tolist()
    x, y, z = (p_b - p_a).tolist()
    linear = np.array([(b0 * x + b3 * y + b6 * z) / dt, (b1 * x + b4 * y + b7 * z) / dt,
                       (b2 * x + b5 * y + b8 * z) / dt])
    # M = R_aᵀ R_b, row-major
    m = [a0 * b0 + a3 * b3 + a6 * b6, a0 * b1 + a3 * b4 + a6 * b7, a0 * b2 + a3 * b5 + a6 * b8,
         a1 * b0 + a4 * b3 + a7 * b6, a1 * b1 + a4 * b4 + a7 * b7, a1 * b2 + a4 * b5 + a7 * b8,
         a2 * b0 + a5 * b3 + a8 * b6, a2 * b1 + a5 * b4 + a8 * b7, a2 * b2 + a5 * b5 + a8 * b8]
    return linear, rotation_log_entries(*m) / dt


def finite_scale(value: float | None) -> float | None:
    """A published scale, or None when there is none or it is not a finite positive number."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) and value > 0.0 else None
