"""The Calibrator's state and its frame loop: what happens once a SLAM pose is accepted.

:class:`FrameLoop` holds everything one calibration knows (the estimator, the ground model, the
maps, the pose track, the counters) and runs the processing order of docs/interface.md from an
accepted pose on: the frames before its stamp, its odometry, the frame of its stamp; per frame the
map in use, then every person's scale sample (docs/method.md, steps 1-6); resets and new segments;
the metric records handed to the metric stage (online) or kept in the journal (offline); the
status. :class:`hac_ros.core.calibrator.Calibrator` adds the inputs: stamps judged, poses vetted,
frames queued until their pose is known.
"""
from __future__ import annotations

import functools
import math
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np

from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import MapRescaleOut, NoticeOut, ResetOut, Status
from hac_ros.core.bodies.convention_check import ConventionCheck
from hac_ros.core.bodies.conventions import Conventions
from hac_ros.core.bodies.human_filter import PersonTracker, RootFilter
from hac_ros.core.estimate.estimator import RollingScale
from hac_ros.core.geometry.ground import GroundModel
from hac_ros.core.geometry.map_shape import PLANE_JUDGE_BODIES, MapShape, plane_problem
from hac_ros.core.geometry.reference import MapIndex
from hac_ros.core.person_step import PersonStep
from hac_ros.core.rules.params import HacParams, HumanFilter
from hac_ros.core.rules.reasons import text as reason_text
from hac_ros.core.stream.map_book import MapBook
from hac_ros.core.stream.metric_stage import MetricStage, ScaleAt, StageConfig, finite_scale
from hac_ros.core.stream.pending import (
    Pending,
    PendingFrame,
    PendingMap,
    PendingOdometry,
    PendingSegment,
    PendingStatus,
    Record,
)
from hac_ros.core.stream.pose_stream import FreezeWatch, Pose, PoseTrack, ZigzagWatch
from hac_ros.core.stream.services import ServiceRequests
from hac_ros.core.stream.stamp_reach import UNMATCHED, StampReach
from hac_ros.core.stream.timeline import Stamped, Timeline

GROUND_SHARE_SAMPLES = 30  # recent samples whose sources say whether the ground plane carries
# resets that keep the map in use, and the ground model: the same SLAM map goes on
KEEPS_MAP = ('map_overlap', 'service', 'time_jump_ahead')
KEEPS_GROUND = ('service', 'time_jump_ahead')
# rejections that correct runs meet: their first notice is INFO (a sample the outlier gate kept
# out, a person sitting down)
ROUTINE_REJECTIONS = ('gated', 'not_standing')


@dataclass
class Frame:
    """One image's HMR joints, waiting for (or matched to) its SLAM pose."""
    stamp_ns: int
    joints_cam: np.ndarray  # (P, K, 3) metres, camera optical frame (K: the joint layout's)


class FrameLoop(PersonStep):
    """The state of one calibration and the per-frame loop (the base of Calibrator, which
    documents ``schedule`` and ``offline``); each person's sample is :class:`PersonStep`'s."""

    def __init__(self, params: HacParams | None = None, schedule: ScaleAt | None = None,
                 offline: bool = False) -> None:
        self.params = params or HacParams()
        self.schedule = schedule
        self.journal: list[Record] | None = [] if offline else None
        p = self.params
        self._cos_min = math.cos(math.radians(p.cone_angle_deg))
        self.rejected: Counter[str] = Counter()
        self.events: Counter[str] = Counter()  # time jumps (hac_ros.core.stream.timeline)
        self._noticed: set[str] = set()
        self._map_seen = False  # a map was in use for a frame (before: no_map is waiting for it)
        self.reach = StampReach()  # joints and poses stamped apart
        # (hac_ros.core.stream.stamp_reach)
        self.frames = self.people = self.map_hits = self.ground_fallbacks = self.resets = 0
        self._K: np.ndarray | None = None
        self._image_size = (0, 0)
        self._camera_frame = p.camera_frame
        self._child_frame = p.camera_frame
        self.segment = -1  # the current segment (one SLAM map between re-initialisations)
        self._init_stream()
        self.services = ServiceRequests()  # ~/reset, ~/freeze
        self.layout = p.layout()  # which joint is which (joint_layout)
        self.conventions = Conventions(p.pose_to_optical, p.hmr_focal_px, self.layout)
        self.check = ConventionCheck()  # warns when the geometry says a convention is wrong
        # what depends on the published scale: the segments' placements, the continuous
        # odometry, the cloud (hac_ros.core.stream.metric_stage)
        self.metric = MetricStage(StageConfig.from_params(p),
                                  RootFilter(self.layout)
                                  if p.human_filter == HumanFilter.SMOOTH else None)

    def _init_stream(self) -> None:
        """The state of one stream of header time, as at start-up (a jump back in time starts
        a new one: hac_ros.core.stream.timeline); the counters, the camera and the conventions
        stay."""
        p = self.params
        self.estimator = RollingScale.from_params(p)
        self.ground = GroundModel.from_params(p)
        self.followed = PersonTracker()  # a fixed camera's people, by their roots (camera frame)
        self._static_normal: np.ndarray | None = None  # its floor's normal the samples used
        self._map_frame: str | None = None
        # poses in another frame than the map's, in a row: a SLAM re-initialised in a new frame
        # once reset_confirm_poses more follow, else another publisher's (hac_ros.core.calibrator)
        self._frame_run: list[Stamped] = []
        self.track = PoseTrack.from_params(p)
        self.timeline = Timeline(int(p.time_jump_back_s * NS), int(p.time_jump_ahead_s * NS),
                                 p.reset_confirm_poses)
        self._pending: list[Frame] = []  # sorted by stamp
        self.maps = MapBook(p)  # waiting, in use (hac_ros.core.stream.map_book)
        self._last_frame_ns = -1
        self._diag_second: int | None = None
        self._segment_starts: str | None = ''  # the cause of a segment starting at the next pose
        self._sources: deque[bool] = deque(maxlen=GROUND_SHARE_SAMPLES)  # True: a ground sample
        self.freeze = FreezeWatch()
        self.zigzag = ZigzagWatch()  # two sources interleaved on the pose topic

    # ================================================================== state
    @property
    def converged(self) -> bool:
        return self.estimator.converged

    @property
    def scale(self) -> float:
        """The current estimate, metres per SLAM unit (RollingScale.current: the window's median
        and the drift filter's level, weighed by the evidence of drift)."""
        return self.estimator.current()

    def published_scale(self, stamp_ns: int) -> float | None:
        """The scale the metric outputs use at ``stamp_ns``, metres per SLAM unit (None: nothing
        metric yet): the ``schedule``'s if one was given, else the online one."""
        if self.schedule is not None:
            return finite_scale(self.schedule(stamp_ns))
        return self.online_scale()

    def online_scale(self) -> float | None:
        """The online scale, which the samples use (the map distance bound, the contacts' ground):
        the estimate from the segment's first convergence on (RollingScale.publishing), the held
        one while frozen (and after, until the fresh window converges)."""
        return self.services.scale(self.scale if self.estimator.publishing else None)

    def published_spread(self) -> float:
        """The ``±`` a user reads, metres per SLAM unit: the estimator's own uncertainty and the
        joint layout's prior for the biases no sample shows, in quadrature (docs/method.md, "The
        two parts of the ±")."""
        return self.scale * math.hypot(self.estimator.estimate().rel_sigma,
                                       self.layout.sys_rel_sigma)

    def status(self, stamp_ns: int | None = None) -> Status:
        """A snapshot of the estimator at ``stamp_ns`` (default: the last frame's stamp)."""
        pending = self.pending_status(stamp_ns)
        return self.metric.status(pending, self.published_scale(pending.status.stamp_ns))

    def pending_status(self, stamp_ns: int | None = None) -> PendingStatus:
        """The status before the metric stage places its ground plane in the metric frame."""
        plane = self.ground.plane(self.map)
        status = Status(
            stamp_ns=int(self._last_frame_ns if stamp_ns is None else stamp_ns),
            converged=self.converged, scale=self.scale, spread=self.published_spread(),
            spread_stat=self.estimator.spread(), publishing=self.estimator.publishing,
            samples=self.estimator.samples, frames=self.frames, people=self.people,
            map_hits=self.map_hits, ground_fallbacks=self.ground_fallbacks, resets=self.resets,
            rejected=dict(self.rejected), map_points=len(self.map) if self.map is not None else 0,
            ground_normal_map=None if plane is None else plane.normal,
            ground_offset_slam=float('nan') if plane is None else plane.offset,
            drifting=self.estimator.drifting, frozen=self.services.holding,
            services=dict(self.services.counts), suspects=dict(self.check.suspects),
            events=dict(self.events), conditions=self.conditions(),
            pose_matches=dict(self.track.matches))
        last = self.track.last
        return PendingStatus(status, plane, None if last is None else last.c_map,
                             None if last is None else last.R_wc, self.segment)

    def conditions(self) -> dict[str, str]:
        """What holds now and makes /diagnostics WARN (hac_ros.core.rules.health): reason ->
        text."""
        out = {}
        if self.freeze.holds:
            out['slam_frozen'] = reason_text('slam_frozen')
        if self.zigzag.holds:
            out['pose_zigzag'] = reason_text('pose_zigzag')
        if self.maps.degenerate:
            out['map_degenerate'] = self.maps.degenerate
        estimator = self.estimator
        for reason, holds in (('relocking', estimator.relocking),
                              ('map_rescaled', estimator.map_rescaled),
                              ('lagging', estimator.lagging), ('unverified', estimator.unverified)):
            if holds:
                out[reason] = reason_text(reason)
        if self.ground.floor_missing:
            out['floor_unknown'] = reason_text('floor_unknown')
        return out

    @property
    def map(self) -> MapIndex | None:
        """The map in use (SLAM units, map frame), or None."""
        return self.maps.in_use

    @property
    def child_frame_id(self) -> str:
        return self.params.base_frame or self._child_frame

    def _reject(self, reason: str, stamp_ns: int = -1, detail: str = '') -> list[Record]:
        """Count a rejection; the first of each reason is announced with ``detail`` (else the
        reason's text)."""
        self.rejected[reason] += 1
        out: list[Record] = []
        if reason in UNMATCHED:  # a frame without its pose: two clocks? (said once)
            track = self.track
            first = (track.poses[0] if track.poses else
                     track.candidates[0] if track.candidates else None)
            out += self.reach.judge(int(stamp_ns), None if first is None else first.stamp_ns,
                                    track.newest_stamp_ns, self.frames)
        if reason in self._noticed:
            return out
        self._noticed.add(reason)
        if reason == 'no_map' and not self._map_seen:
            return [*out, NoticeOut(int(stamp_ns), reason, 'waiting for the first map: joints '
                                    'frames give no scale sample until it comes (counted as '
                                    'rejected.no_map in /diagnostics)', 'info')]
        text = detail or reason_text(reason)
        return [*out, NoticeOut(int(stamp_ns), reason, f'rejected input ({reason}): {text}; '
                                'further ones are counted in /diagnostics',
                                self._notice_level(reason))]

    def _notice_level(self, reason: str) -> str:
        """The level of a reason's first notice: ``info`` for what correct runs meet (the
        outlier gate at work, people sitting, a ray that meets nothing while the ground plane is
        still being found; waiting for the first map is said above), ``warn`` otherwise."""
        waiting = reason == 'no_reference' and self.ground.normal() is None
        return 'info' if reason in ROUTINE_REJECTIONS or waiting else 'warn'

    # ================================================================== poses
    def _accept_pose(self, pose: Pose, move: tuple[float, float] | None = None,
                     measured: bool = True) -> list[Record]:
        """Take ``pose`` as the camera's next one; ``move``: its step, if computed; ``measured``:
        False when its step is not the camera's motion (a frozen SLAM's)."""
        out: list[Record] = self._take_requests(pose) if self.services.queue else []
        if self._segment_starts is not None:  # the stream's first pose starts its first segment
            out += self._new_segment(pose, self._segment_starts)
            self._segment_starts = None
        self.track.append(pose, (self.track.step(pose) if move is None else move)
                          if measured else None)
        # frames before this stamp first, then this pose's map and odometry, then the frame of
        # this stamp (a map is in use from its stamp on: its odometry and status see it too)
        while self._pending and self._pending[0].stamp_ns < pose.stamp_ns:
            out += self._process(self._pending.pop(0))
        out += self._activate_map(pose.stamp_ns, pose.R_wc, pose.c_map)
        out += self._odometry(pose)
        while self._pending and self._pending[0].stamp_ns <= pose.stamp_ns:
            out += self._process(self._pending.pop(0))
        return out

    def _take_requests(self, pose: Pose) -> list[Record]:
        out: list[Record] = []
        for action, notice in self.services.take(pose.stamp_ns,
                                                 lambda: self.published_scale(pose.stamp_ns)):
            if action == 'reset':
                out += self._reset(pose, 'service', 'requested (~/reset)')
            elif action == 'release':
                self.estimator.reset()  # a fresh window; the held scale serves until it converges
            out.append(notice)
        return out

    # ================================================================== reset
    def _new_segment(self, first_pose: Pose, cause: str) -> list[Record]:
        self.segment += 1
        keeps_map = cause in KEEPS_MAP
        out = self._metric(PendingSegment(first_pose.stamp_ns, self.segment, first_pose.R_wc,
                                          first_pose.c_map, keeps_map, cause))
        if keeps_map and self.map is not None:
            self.maps.unhanded = True  # the kept map, placed by the new segment
        return out

    def _reset(self, first_pose: Pose, cause: str, text: str) -> list[Record]:
        """Forget the old map's scale and anchor the new map at ``first_pose``; a ``service`` reset
        keeps the map and the ground model (the same map, only a new estimate)."""
        self.estimator.reset()
        if cause not in KEEPS_GROUND:
            self.ground.reset()
        self.resets += 1
        self._sources.clear()
        self.services.clear()  # a held scale belongs to the old segment
        out: list[Record] = self._new_segment(first_pose, cause)
        self.track.clear()
        if cause not in KEEPS_MAP:
            self.maps.drop(first_pose.stamp_ns)
            self.check.new_map_frame()
        # frames before the reset belong to the old map: their poses are gone
        stale = [f for f in self._pending if f.stamp_ns < first_pose.stamp_ns]
        self._pending = [f for f in self._pending if f.stamp_ns >= first_pose.stamp_ns]
        out += [ResetOut(first_pose.stamp_ns, cause),
                NoticeOut(first_pose.stamp_ns, 'reset', f'estimator reset ({cause}): {text}',
                          'info')]  # what a SLAM does; /diagnostics counts it
        for frame in stale:
            out += self._reject('no_pose', frame.stamp_ns)
        return out

    # ================================================================== frames
    def _activate_map(self, stamp_ns: int, R_wc: np.ndarray, c_map: np.ndarray) -> list[Record]:
        """Make the latest map not after ``stamp_ns`` the current one (the processing order); a
        map that does not overlap the previous one is a SLAM re-initialisation; a plane map that
        cannot be the floor is refused (hac_ros.core.geometry.map_shape; the camera ``R_wc`` (3, 3),
        at ``c_map`` (3,), SLAM units), and a plane map in use is judged once the bodies give
        their axis. A new map that overlaps is measured against the old one along the camera's
        view (MapIndex.rescale_against): the estimator follows a map that changed its scale."""
        # the bodies' axis, only when a map is judged (an eigen-decomposition per pose otherwise)
        axis = functools.cache(lambda: self.ground.body_axis(PLANE_JUDGE_BODIES))
        previous = self.map

        def problem(index: MapIndex, shape: MapShape) -> str:
            return plane_problem(shape, index.sample, c_map, axis())
        chosen, lost, refused = self.maps.activate(stamp_ns, problem)
        if refused:
            return self._reject('map_degenerate', stamp_ns, refused)
        if self.maps.plane_unjudged and self.map is not None and self.maps.shape is not None:
            why = plane_problem(self.maps.shape, self.map.sample, c_map, axis())
            if why:  # its samples measured a wall or the camera's own plane: dropped too
                self.maps.refuse_in_use(why)
                self.estimator.restart()
                return self._reject('map_degenerate', stamp_ns, self.maps.degenerate +
                                    ' (refused)')
            if axis() is not None:
                self.maps.plane_judged()
            else:  # until judged, converge only on a plane the first bodies take for the floor
                rough = self.ground.body_axis()
                self.estimator.may_converge = rough is not None and not plane_problem(
                    self.maps.shape, self.map.sample, c_map, rough)
        if not self.maps.plane_unjudged:
            self.estimator.may_converge = True
        pose = self.track.last
        current = self.map
        if (chosen is not None and not lost and previous is not None and current is not None
                and current is not previous):
            measured = current.rescale_against(previous, c_map, R_wc[:, 2])
            factor = self.estimator.map_changed(stamp_ns, *(measured or (None,)))
            if factor is not None:  # the samples before it were in the old unit (offline too)
                self.services.rescale(factor)
                notice = NoticeOut(stamp_ns, 'map_rescaled', f'the new map has another scale: '
                                   f'the scale is now {factor:.4g} times what it was (the '
                                   'estimate follows it)', 'info')
                return [MapRescaleOut(stamp_ns, factor, previous.stamp_ns), notice]
        if chosen is None or not lost or pose is None:
            return []
        out = self._reset(pose, 'map_overlap', 'the new map does not overlap the previous one: '
                          'SLAM re-initialised')
        self.track.append(pose, None)  # the new segment starts at the last pose
        return out

    def _hand_map(self, stamp_ns: int) -> list[Record]:
        """The map in use to the metric stage (for /hac/cloud), at most once per
        ``cloud_min_period_s`` (MapBook.to_hand)."""
        points = self.maps.to_hand(stamp_ns)
        return [] if points is None else self._metric(PendingMap(stamp_ns, self.segment, points))

    def _process(self, frame: Frame) -> list[Record]:
        """One frame (docs/method.md, steps 1–6) for every person in it."""
        out: list[Record] = []
        stamp = frame.stamp_ns
        pose = self.track.at(stamp)
        if pose is None:
            return self._reject('no_pose', stamp)
        out += self._activate_map(stamp, *pose)
        out += self._hand_map(stamp)
        self._map_seen = self._map_seen or self.map is not None
        R_wc, c_map = pose
        self._last_frame_ns = stamp
        self.frames += 1
        if not self.services.holding:  # frozen: nothing expires
            self.estimator.advance(stamp)
        self.check.view_map(stamp, self.map, R_wc, c_map, self._K, self._image_size)
        if (not self.params.static_camera  # a fixed camera's pose repeats: not a frozen SLAM
                and self.freeze.frame(self.track.frozen(stamp), frame.joints_cam)):
            out += self._reject('slam_frozen', stamp)  # its pose is not the camera's
        else:
            followed = (self.followed.follow(stamp, self.layout.root_of(frame.joints_cam))
                        if self.params.static_camera and self.map is None
                        and len(frame.joints_cam) else [-1] * len(frame.joints_cam))
            for person, joints in enumerate(frame.joints_cam):
                out += self._person(stamp, person, R_wc, c_map, joints, followed[person])
        out += self.check.notices(stamp)
        if self.journal is not None or self.published_scale(stamp) is not None:
            plane = self.ground.plane(self.map)
            out += self._metric(PendingFrame(stamp, self.segment, R_wc, c_map, frame.joints_cam,
                                             self.published_spread(), plane))
        return out

    # ================================================================== outputs
    def _odometry(self, pose: Pose) -> list[Record]:
        """Every accepted pose (the odometry integrates them all, also while a segment
        converges)."""
        # the position's uncertainty comes from the published ± (MetricStage); the evidence ages
        if not self.services.holding:
            self.estimator.advance(pose.stamp_ns)
        sigma_scale = self.published_spread()
        share = sum(self._sources) / len(self._sources) if self._sources else 0.0
        plane = self.ground.plane(self.map)
        return self._metric(PendingOdometry(pose.stamp_ns, self.child_frame_id, self.segment,
                                            pose.R_wc, pose.c_map, sigma_scale, plane, share))

    def _metric(self, pending: Pending) -> list[Record]:
        """A metric record: kept as it is offline (resolved at the end), else resolved at once."""
        if self.journal is not None:
            return [pending]
        return list(self.metric.apply(pending, self.published_scale))

    def _diagnostics(self, stamp_ns: int) -> list[Record]:
        second = stamp_ns // NS
        if self._diag_second is not None and second <= self._diag_second:
            return []
        self._diag_second = second
        return self._metric(self.pending_status(stamp_ns))
