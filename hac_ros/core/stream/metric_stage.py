"""The metric stage: a scale and an alignment applied to SLAM poses, maps and HMR joints.

The :class:`~hac_ros.core.calibrator.Calibrator` decides *what* is published and *when* (the
processing order, docs/interface.md); this stage decides *with which scale and where*. It owns
everything that depends on the published scale:

- each segment's placement in the metric frame (:mod:`hac_ros.core.geometry.alignment`), anchored
  on the last published ``/hac/pose`` when a SLAM re-initialisation starts a new segment;
- ``/hac/pose`` (:class:`PoseOut`): the globally consistent metric pose, which moves when the
  estimate or the alignment moves, as a localisation correction does;
- ``/hac/odometry`` (:class:`OdometryOut`, :mod:`hac_ros.core.stream.odometry`): continuous, never
  jumps;
- ``/hac/human_joints`` (and the online filter of the humans) and ``/hac/scale``;
- ``/hac/cloud`` (:class:`CloudOut`): the current map in the metric frame, republished when a new
  map is used, when the estimate moved by more than ``cloud_republish_rel`` or the alignment by
  more than 1° or 1 cm since the last one, at most once per ``cloud_min_period_s`` of stamp time.

The calibrator hands it metric records (:mod:`hac_ros.core.stream.pending`) that hold the SLAM-unit
quantities of an output. Online (``hac_node``, ``hac replay --mode online``) each record is
resolved at once with the current estimate and the current ground plane. Offline (the replay's
default mode) the calibrator keeps them in its journal: once the whole recording's schedule is
known :meth:`MetricStage.resolve` turns the records, in their order, into the outputs a second run
with that schedule would give; each segment then has one final alignment (its last ground plane,
``final_planes``).

Pure numpy. Stamps are int nanoseconds; scales are metres per SLAM unit (None: nothing metric).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace

import numpy as np

from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import (
    CloudOut,
    DiagnosticsOut,
    HumanJointsOut,
    NoticeOut,
    OdometryOut,
    Output,
    PoseOut,
    ScaleOut,
    Status,
)
from hac_ros.core.basics.transforms import base_from_camera
from hac_ros.core.bodies.human_filter import RootFilter
from hac_ros.core.geometry import alignment as align
from hac_ros.core.geometry.alignment import Alignment
from hac_ros.core.geometry.plane import Plane
from hac_ros.core.geometry.plausibility import sane, sane_rows
from hac_ros.core.rules.params import FrameAlignment, HacParams
from hac_ros.core.stream.odometry import POSITION_VARIANCE_FLOOR, ContinuousOdometry
from hac_ros.core.stream.pending import (
    PENDING,
    Pending,
    PendingFrame,
    PendingMap,
    PendingOdometry,
    PendingSegment,
    PendingStatus,
    Record,
)

CLOUD_MOVE_DEG = 1.0  # the alignment moved this much since the last cloud: republish it
CLOUD_MOVE_M = 0.01
GROUND_CARRIES = 0.5  # when the ground plane gives more than this share of the samples ...
GROUND_INFLATION = 4.0  # ... /hac/pose's position variance is this many times larger

# stamp ns -> published scale (metres per SLAM unit); None, NaN or <= 0: nothing metric then
ScaleAt = Callable[[int], 'float | None']


@dataclass
class StageConfig:
    """What the stage needs of the parameters (hac_ros.core.rules.params.HacParams)."""

    alignment: str = 'gravity'  # metric_frame_alignment
    base_from_camera: tuple[np.ndarray, np.ndarray] | None = None  # the base's pose in the camera
    orientation_variance: float = 1e-4  # rad²
    publish_cloud: bool = True
    cloud_republish_rel: float = 0.01
    cloud_min_period_ns: int = 5 * NS
    output_max_m: float = 1e5  # no output value beyond this, metres

    @classmethod
    def from_params(cls, p: HacParams) -> StageConfig:
        base = base_from_camera(p.base_to_camera) if p.base_frame else None
        return cls(p.metric_frame_alignment, base, p.orientation_variance, p.publish_cloud,
                   p.cloud_republish_rel, int(p.cloud_min_period_s * NS), p.output_max_m)


@dataclass
class _Segment:
    """One segment's placement: its first pose, the anchor it continues from (the last published
    /hac/pose: camera rotation to metric, position metres; None for the first), and whether it
    fell back to the SLAM's axes."""

    first_R: np.ndarray
    first_c: np.ndarray
    anchor: tuple[np.ndarray, np.ndarray] | None
    anchor_variance: float = 0.0  # m², /hac/pose's position variance at the anchor
    slam: bool = False
    cache: tuple[object, Alignment] | None = None  # (the plane it was made for, alignment)


@dataclass
class _CloudState:
    points: np.ndarray | None = None  # (N, 3) float32, SLAM units, the current segment's map
    new_map: bool = False
    last: tuple[int, float, Alignment] | None = None  # stamp, scale, alignment of the last one
    due: bool = False  # a change waits for the rate limit
    centre: np.ndarray = field(default_factory=lambda: np.zeros(3))  # the map's centre, SLAM units


class MetricStage:
    """Applies a published scale (and the segment's alignment) to pending outputs."""

    def __init__(self, config: StageConfig, humans: RootFilter | None = None) -> None:
        self.config = config
        self.humans = humans
        self.odometry = ContinuousOdometry(config.base_from_camera, config.orientation_variance)
        self.segments: dict[int, _Segment] = {}
        self.segment = -1
        self.last_pose: tuple[np.ndarray, np.ndarray, float] | None = None  # camera R, p, variance
        self.cloud = _CloudState()
        self.final_planes: dict[int, Plane | None] | None = None
        self._warned: set[int] = set()
        self.suppressed = 0  # outputs held back or trimmed: output_implausible

    # ------------------------------------------------------------------ resolving
    def resolve(self, records: Iterable[Record], scale_at: ScaleAt,
                error_at: Callable[[int], float] | None = None,
                final_planes: dict[int, Plane | None] | None = None) -> list[Output]:
        """The outputs of ``records``, each metric record replaced by its output(s), in order.

        error_at: stamp -> the ``±`` of that scale (metres per SLAM unit), for the covariances
        and /hac/scale's spread; None: the online one, recorded in each pending record.
        final_planes: segment -> its final ground plane (offline: one alignment per segment).
        """
        if final_planes is not None:
            self.final_planes = final_planes
        out: list[Output] = []
        for record in records:
            if isinstance(record, PENDING):
                out += self.apply(record, scale_at, error_at)
            else:
                out.append(record)
        return out

    def apply(self, pending: Pending, scale_at: ScaleAt,
              error_at: Callable[[int], float] | None = None) -> list[Output]:
        """One pending record -> its outputs with the scale ``scale_at`` gives at its stamp, never
        a non-finite value or one beyond ``output_max_m`` (:meth:`_sane`)."""
        return self._sane(self._apply(pending, scale_at, error_at))

    def _apply(self, pending: Pending, scale_at: ScaleAt,
               error_at: Callable[[int], float] | None) -> list[Output]:
        if isinstance(pending, PendingOdometry):
            sigma = pending.sigma_scale if error_at is None else error_at(pending.stamp_ns)
            return self._pose(pending, finite_scale(scale_at(pending.stamp_ns)), sigma)
        if isinstance(pending, PendingFrame):
            spread = pending.spread if error_at is None else error_at(pending.stamp_ns)
            return self._frame(pending, finite_scale(scale_at(pending.stamp_ns)), spread)
        if isinstance(pending, PendingSegment):
            self._new_segment(pending)
            return []
        if isinstance(pending, PendingMap):
            self.cloud.points = pending.points_slam
            points = pending.points_slam
            self.cloud.centre = points.mean(axis=0) if len(points) else np.zeros(3)
            self.cloud.new_map = True
            return []
        if isinstance(pending, PendingStatus):
            scale = finite_scale(scale_at(pending.status.stamp_ns))
            return [DiagnosticsOut(self.status(pending, scale))]
        raise TypeError(f'not a pending output: {type(pending).__name__}')

    def _sane(self, outputs: list[Output]) -> list[Output]:
        """The outputs with nothing non-finite or beyond ``output_max_m`` metres
        (hac_ros.core.geometry.plausibility): such a pose, odometry, scale or joints message is
        suppressed and a cloud loses those points, each counted as ``output_implausible``; in the
        joints a NaN joint is one not seen and stays NaN, and a person with an infinite joint
        (counted as such) or none seen is left out."""
        bound, out = self.config.output_max_m, []
        for output in outputs:
            ok = True
            if isinstance(output, (PoseOut, OdometryOut)):
                ok = sane(output.position_metric, bound) and sane(output.covariance, math.inf)
            elif isinstance(output, ScaleOut):
                ok = math.isfinite(output.scale) and output.scale > 0.0
            elif isinstance(output, HumanJointsOut):  # NaN joints: not seen, kept NaN
                people = output.joints_metric
                seen = np.isfinite(people).all(axis=2)
                keep = ~np.isinf(people).any(axis=(1, 2)) & seen.any(axis=1)
                if not keep.all():
                    output = replace(output, joints_metric=people[keep])
                    seen = seen[keep]
                ok = sane(output.joints_metric[seen], bound)
            elif isinstance(output, CloudOut):
                points = sane_rows(output.points_metric, bound)
                if len(points) < len(output.points_metric):
                    self.suppressed += 1
                    output = replace(output, points_metric=points)
            if ok:
                out.append(output)
            else:
                self.suppressed += 1
        return out

    # ------------------------------------------------------------------ segments and alignment
    def _new_segment(self, pending: PendingSegment) -> None:
        if pending.cause == 'time_jump_back':  # a new stream: placed afresh, as at start-up
            self.last_pose, self.cloud = None, _CloudState()
            if self.humans is not None:
                self.humans = RootFilter(self.humans.layout)
        anchor = variance = None
        if self.last_pose is not None:
            anchor, variance = self.last_pose[:2], self.last_pose[2]
        self.segments[pending.index] = _Segment(np.asarray(pending.R_wc), np.asarray(pending.c_map),
                                                anchor, variance or 0.0,
                                                slam=self.config.alignment == FrameAlignment.SLAM)
        self.segment = pending.index
        if pending.index > 0:
            self.odometry.new_segment()
            if not pending.keeps_map:
                self.cloud.points = None

    def alignment(self, segment: int,
                  plane: Plane | None) -> tuple[Alignment, list[NoticeOut]]:
        """The segment's placement with this ground plane (or its final one, offline), and a
        notice when it has to fall back to the SLAM's axes (no usable ground normal)."""
        seg = self.segments[segment]
        if self.final_planes is not None:
            plane = self.final_planes.get(segment)
        notices: list[NoticeOut] = []
        if not seg.slam:
            if seg.cache is not None and (plane is None or seg.cache[0] is plane):
                return seg.cache[1], notices  # no plane now: keep the last levelled one
            level = align.levelled(plane, seg.first_R, seg.first_c) if plane is not None else None
            if level is not None:
                yaw, x, y = 0.0, 0.0, 0.0
                if seg.anchor is not None:
                    yaw = align.heading(seg.anchor[0]) - align.heading(level.rotation @ seg.first_R)
                    x, y = float(seg.anchor[1][0]), float(seg.anchor[1][1])
                placed = align.placed(level, yaw, x, y)
                seg.cache = (plane, placed)
                return placed, notices
            seg.slam = True  # no usable normal when the segment first needs its frame
            if segment not in self._warned:
                self._warned.add(segment)
                notices.append(NoticeOut(-1, 'alignment_slam', 'metric_frame_alignment gravity: '
                                         'no usable ground normal yet, the metric frame keeps the '
                                         'SLAM map\'s axes for this segment', 'warn'))
        if seg.cache is None:
            placed = (align.slam_continuing(*seg.anchor, seg.first_R, seg.first_c)
                      if seg.anchor is not None else Alignment.identity())
            seg.cache = (None, placed)
        return seg.cache[1], notices

    # ------------------------------------------------------------------ poses
    def _pose(self, pending: PendingOdometry, scale: float | None, sigma_scale: float
              ) -> list[Output]:
        if scale is None or pending.segment not in self.segments:
            self.odometry.update(pending.stamp_ns, pending.child_frame_id, pending.R_wc,
                                 pending.c_map, None, math.nan, None)
            return []
        placed, notices = self.alignment(pending.segment, pending.plane)
        for notice in notices:
            notice.stamp_ns = pending.stamp_ns
        out: list[Output] = list(notices)
        R_cam, p_cam = placed.camera(pending.R_wc, pending.c_map, scale)
        rel = sigma_scale / scale if math.isfinite(sigma_scale) else math.nan
        seg = self.segments[pending.segment]
        first = placed.point(seg.first_c, scale)
        from_anchor = float(np.linalg.norm(p_cam - first))
        variance = (POSITION_VARIANCE_FLOOR + seg.anchor_variance
                    + ((rel if math.isfinite(rel) else 0.0) * from_anchor) ** 2)
        if pending.ground_share > GROUND_CARRIES:
            variance *= GROUND_INFLATION
        self.last_pose = (R_cam, p_cam, variance)
        R_out, p_out = R_cam, p_cam
        if self.config.base_from_camera is not None:
            R_cb, t_cb = self.config.base_from_camera
            R_out, p_out = R_cam @ R_cb, p_cam + R_cam @ t_cb
        covariance = np.diag([variance] * 3 + [self.config.orientation_variance] * 3)
        odometry = self.odometry.update(pending.stamp_ns, pending.child_frame_id, pending.R_wc,
                                        pending.c_map, scale, rel, (R_cam, p_cam))
        if odometry is not None:
            out.append(odometry)
        out.append(PoseOut(pending.stamp_ns, pending.child_frame_id, R_out, p_out, covariance))
        return out

    # ------------------------------------------------------------------ frames
    def _frame(self, pending: PendingFrame, scale: float | None, spread: float) -> list[Output]:
        if scale is None or pending.segment not in self.segments:
            return []
        placed, notices = self.alignment(pending.segment, pending.plane)
        out: list[Output] = list(notices)
        R_cam, p_cam = placed.camera(pending.R_wc, pending.c_map, scale)
        joints = np.asarray(pending.joints_cam) @ R_cam.T + p_cam
        if self.humans is not None:
            joints = self.humans.update(pending.stamp_ns, joints)
        out += [HumanJointsOut(pending.stamp_ns, joints),
                ScaleOut(pending.stamp_ns, scale, spread)]
        return out + self._cloud(pending.stamp_ns, scale, placed)

    def _cloud(self, stamp_ns: int, scale: float, placed: Alignment) -> list[Output]:
        """The map in the metric frame when a change is due and the rate limit allows it."""
        cloud, config = self.cloud, self.config
        if not config.publish_cloud or cloud.points is None:
            return []
        if cloud.new_map or cloud.last is None:
            cloud.due, cloud.new_map = True, False
        else:
            _, last_scale, last_placed = cloud.last
            degrees, metres = placed.moved_from(last_placed, scale, cloud.centre)
            if (abs(scale / last_scale - 1.0) > config.cloud_republish_rel
                    or degrees > CLOUD_MOVE_DEG or metres > CLOUD_MOVE_M):
                cloud.due = True
        if not cloud.due or (cloud.last is not None
                             and stamp_ns - cloud.last[0] < config.cloud_min_period_ns):
            return []
        cloud.due = False
        cloud.last = (stamp_ns, scale, placed)
        return [CloudOut(stamp_ns, placed.point(cloud.points, scale).astype(np.float32),
                         placed.levelled)]

    # ------------------------------------------------------------------ diagnostics
    def status(self, pending: PendingStatus, scale: float | None) -> Status:
        """The status with its metric ground plane: the down normal and the plane point below the
        camera, in the metric frame (None before a scale or without a plane)."""
        plane, c_map = pending.plane, pending.c_map
        status = pending.status
        if self.suppressed:
            status = replace(status, rejected={**status.rejected,
                                               'output_implausible': self.suppressed})
        if pending.segment in self.segments:
            seg = self.segments[pending.segment]
            status = replace(status, alignment='slam' if seg.slam else self.config.alignment)
        if plane is None or c_map is None or scale is None or pending.segment not in self.segments:
            return status
        placed, _ = self.alignment(pending.segment, plane)
        below = float(plane.offset - plane.normal @ c_map)  # SLAM units, the camera above it
        foot_map = c_map + below * plane.normal
        status = replace(status, ground_normal_metric=placed.rotation @ plane.normal,
                         ground_point_metric=placed.point(foot_map, scale),
                         camera_height_m=below * scale)
        if pending.R_wc is not None:
            down_cam = pending.R_wc.T @ plane.normal  # down in the camera optical frame
            status = replace(
                status, camera_pitch_deg=math.degrees(math.asin(max(-1.0, min(1.0, float(
                    down_cam[2]))))),
                camera_roll_deg=math.degrees(math.atan2(float(down_cam[0]), float(down_cam[1]))))
        return status


def finite_scale(value: float | None) -> float | None:
    """A published scale, or None when there is none or it is not a finite positive number."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) and value > 0.0 else None
