"""The Calibrator: SLAM poses, maps and HMR joints in (in the processing order of
docs/interface.md), metric results out.

One object owns all the state; the node and the replay feed it the same inputs and get the same
outputs, because everything is decided by header stamps, never by the wall clock:

- Poses are the clock. A joints frame is processed once a pose at or after its stamp is known (or
  at :meth:`flush`), matched to the pose of the same stamp (within ``sync_slop_s``) or interpolated
  between its neighbours; frames are processed in stamp order, and one older than the last
  processed frame is late (dropped, counted).
- A frame uses the latest map whose stamp is not after the frame's stamp.
- Odometry for the pose of stamp t uses the estimate from the frames before t; the joints and the
  scale of frame t use the estimate including frame t. Nothing metric before convergence.
- A SLAM re-initialisation (a pose jump that persists, a new map frame_id, a map that no longer
  overlaps the previous one) resets the estimator and anchors the new map so that the camera's
  metric pose is continuous; an isolated outlier pose (jump and back) is rejected.

Every rejection is counted by reason and announced once per cause with a :class:`NoticeOut`.
"""
from __future__ import annotations

import bisect
import functools
import math
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Concatenate, ParamSpec

import numpy as np

from hac_ros.core.convention_check import ConventionCheck
from hac_ros.core.conventions import Conventions
from hac_ros.core.estimator import RollingScale
from hac_ros.core.ground import GroundModel
from hac_ros.core.human_filter import RootFilter
from hac_ros.core.map_book import MapBook
from hac_ros.core.metric_stage import MetricStage, ScaleAt, StageConfig, finite_scale
from hac_ros.core.numeric import MEDIAN_STD_ERROR, NS
from hac_ros.core.outputs import REASONS, NoticeOut, Output, ResetOut, SampleOut, Status
from hac_ros.core.params import HacParams
from hac_ros.core.pending import (
    Pending,
    PendingFrame,
    PendingMap,
    PendingOdometry,
    PendingSegment,
    PendingStatus,
    Record,
    outputs_only,
)
from hac_ros.core.plausibility import body_unit_problem
from hac_ros.core.pose_stream import FreezeWatch, Pose, PoseTrack
from hac_ros.core.reference import MapIndex
from hac_ros.core.sample import Scene, person_sample
from hac_ros.core.services import ServiceRequests
from hac_ros.core.timeline import Stamped, Timeline
from hac_ros.core.transforms import is_rotation

GROUND_SHARE_SAMPLES = 30  # recent samples whose sources say whether the ground plane carries
# resets that keep the map in use, and the ground model: the same SLAM map goes on
KEEPS_MAP = ('map_overlap', 'service', 'time_jump_ahead')
KEEPS_GROUND = ('service', 'time_jump_ahead')


_P = ParamSpec('_P')


def _public(method: Callable[Concatenate[Calibrator, _P], list[Record]]
            ) -> Callable[Concatenate[Calibrator, _P], list[Output]]:
    """A public call: its outputs go to the caller; offline, the records it made (outputs and
    metric records, in order) also go to the journal. Public methods never call each other."""
    @functools.wraps(method)
    def call(self: Calibrator, *args: _P.args, **kwargs: _P.kwargs) -> list[Output]:
        records = method(self, *args, **kwargs)
        if self.journal is not None:
            self.journal.extend(records)
        return outputs_only(records)
    return call


@dataclass
class _Frame:
    stamp_ns: int
    joints_cam: np.ndarray  # (P, K, 3) metres, camera optical frame (K: the joint layout's)


class Calibrator:
    """Feed it inputs with ``add_*``; each call returns the outputs it produced, in order.

    schedule: stamp ns -> the scale (metres per SLAM unit; None: nothing metric) the metric
    outputs use, instead of the online estimate; the samples still use the online estimate.
    offline: the metric outputs (odometry and pose, world joints, scale, cloud, diagnostics) are
    held back: each call returns the others, and :attr:`journal` keeps every record in order until
    :func:`hac_ros.core.offline.resolve_offline` resolves the run with the whole recording's
    schedule.
    """

    def __init__(self, params: HacParams | None = None, schedule: ScaleAt | None = None,
                 offline: bool = False) -> None:
        self.params = params or HacParams()
        self.schedule = schedule
        self.journal: list[Record] | None = [] if offline else None
        p = self.params
        self._cos_min = math.cos(math.radians(p.cone_angle_deg))
        self.rejected: Counter[str] = Counter()
        self.events: Counter[str] = Counter()  # time jumps (hac_ros.core.timeline)
        self._noticed: set[str] = set()
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
        # odometry, the cloud (hac_ros.core.metric_stage)
        self.metric = MetricStage(StageConfig.from_params(p),
                                  RootFilter(self.layout) if p.human_filter == 'smooth' else None)

    def _init_stream(self) -> None:
        """The state of one stream of header time, as at start-up (a jump back in time starts
        a new one: hac_ros.core.timeline); the counters, the camera and the conventions stay."""
        p = self.params
        self.estimator = RollingScale(p.window_s, p.window_max_samples, p.min_samples,
                                      p.gate_k, p.gate_min_rel)
        self.ground = GroundModel(p.ground_mode, p.ground_inlier_m, p.ground_ransac_iters, p.seed)
        self._map_frame: str | None = None
        self.track = PoseTrack(p.pose_buffer, p.reset_jump_factor, p.reset_jump_min_rel,
                               p.reset_confirm_poses, int(p.sync_slop_s * NS),
                               p.interp_max_gap_s * NS)
        self.timeline = Timeline(int(p.time_jump_back_s * NS), int(p.time_jump_ahead_s * NS),
                                 p.reset_confirm_poses)
        self._pending: list[_Frame] = []  # sorted by stamp
        self.maps = MapBook(p)  # waiting, in use (hac_ros.core.map_book)
        self._last_frame_ns = -1
        self._diag_second: int | None = None
        self._segment_starts: str | None = ''  # the cause of a segment starting at the next pose
        self._sources: deque[bool] = deque(maxlen=GROUND_SHARE_SAMPLES)  # True: a ground sample
        self.freeze = FreezeWatch()

    # ================================================================== inputs
    @_public
    def add_camera_info(self, K: np.ndarray, width: int, height: int) -> list[Record]:
        """Intrinsics of the camera: joints projecting outside the image go to the ground plane."""
        K = np.asarray(K, dtype=float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0 \
                or not 0 < width < 2**31 or not 0 < height < 2**31:  # also NaN
            return self._reject('camera_info_invalid', self._last_frame_ns)
        first = self._K is None
        self._K, self._image_size = K, (int(width), int(height))
        return [*self.conventions.camera_info_notes(self._last_frame_ns, K)] if first else []

    @_public
    def add_pose(self, stamp_ns: int, R_wc: np.ndarray, c_map: np.ndarray, frame_id: str = '',
                 child_frame_id: str = '') -> list[Record]:
        """A SLAM pose: camera-to-map rotation (3, 3) and camera centre (3,), SLAM units, map frame.

        Its stamp is judged first (hac_ros.core.timeline: late, a jump back that starts a new
        stream, one stamp far ahead, a jump ahead), then the pose in its stream (pose_stream)."""
        R_wc, c_map = np.asarray(R_wc, dtype=float), np.asarray(c_map, dtype=float)
        if not (is_rotation(R_wc, 1e-3) and c_map.shape == (3,) and np.all(np.isfinite(c_map))):
            return self._reject('pose_nonfinite', stamp_ns)
        R_wc, c_map = self.conventions.pose(R_wc, c_map)
        item = Stamped(Pose(int(stamp_ns), R_wc, c_map), frame_id, child_frame_id)
        verdict = self.timeline.judge(item, self.track.newest_stamp_ns)
        out: list[Record] = []
        for bad in verdict.refused:
            out += self._reject(verdict.reason, bad.pose.stamp_ns)
        if verdict.refused and verdict.reason == 'pose_out_of_order':  # no new stream after all
            for reason, stamp in self.timeline.release():
                out += self._reject(reason, stamp)
        if verdict.kind == 'late':
            return out + self._reject('pose_out_of_order', stamp_ns)
        if verdict.kind == 'held':
            return out
        first = verdict.poses[0].pose if verdict.poses else None
        if verdict.kind == 'restart' and first is not None:
            out += self._restart(first)
        elif verdict.kind == 'ahead' and first is not None:
            self.events['time_jump_ahead'] += 1
            out += self._reset(first, 'time_jump_ahead', 'header time jumped ahead and went on '
                               'from there: a new segment')
        for each in verdict.poses or [item]:
            out += self._stream_pose(each)
        return out

    def _stream_pose(self, item: Stamped) -> list[Record]:
        """A pose whose stamp belongs to the current stream: the map frame, the stream's first
        poses, jumps and outliers, a frozen SLAM (hac_ros.core.pose_stream)."""
        pose, frame_id, track = item.pose, item.frame_id, self.track
        if item.child_frame_id and not self.params.camera_frame and self.conventions.optical_poses:
            self._child_frame = item.child_frame_id
        out: list[Record] = []
        move = None  # the pose's step, when the jump test computed it
        measured = True  # the step is the camera's motion (not a freeze's)
        if self._map_frame is None:
            self._map_frame = frame_id
            out += [o for m in self.maps.refuse_foreign(frame_id)
                    for o in self._reject('cloud_wrong_frame', m.stamp_ns)]
        elif frame_id != self._map_frame:
            out += self._reset(pose, 'map_frame', f'SLAM map frame changed {self._map_frame!r} -> '
                               f'{frame_id!r}: SLAM re-initialised')
            self._map_frame = frame_id
            foreign, self.maps.foreign = self.maps.foreign, None
            if foreign is not None and foreign.frame_id == frame_id:  # it came first: adopted
                out += self._add_map_index(foreign)
        if track.vetting:  # nothing is anchored on the stream's first poses until judged
            accepted = track.start(pose, self.maps.extent)
            if accepted is None:
                return out
            return out + self._vetted(accepted) + self._diagnostics(pose.stamp_ns)
        if track.suspects:
            verdict = track.follow(pose)
            for bad in verdict.outliers:
                out += self._reject('pose_outlier', bad.stamp_ns)
            if verdict.reset is not None:
                out += self._reset(verdict.reset, 'pose_jump',
                                   'SLAM pose jumped and stayed: SLAM re-initialised')
                for confirmed in verdict.confirmed:
                    out += self._accept_pose(confirmed)
            elif track.suspects:
                return out + self._diagnostics(pose.stamp_ns)
        elif track.repetition(pose):  # a repeated pose, or the first one after a freeze
            measured = False
        else:
            move = track.step(pose)
            if track.is_jump(move, self.map.extent if self.map is not None else 0.0):
                track.suspects = [pose]
                return out + self._diagnostics(pose.stamp_ns)
        out += self._accept_pose(pose, move, measured)
        return out + self._diagnostics(pose.stamp_ns)

    def _vetted(self, accepted: list[Pose] | None) -> list[Record]:
        """The stream's first poses judged (PoseTrack.start): the others refused as outliers."""
        out: list[Record] = []
        refused, self.track.candidates = self.track.candidates, []
        for bad in refused:
            out += self._reject('pose_outlier', bad.stamp_ns)
        for good in accepted or []:
            out += self._accept_pose(good)
        return out

    @_public
    def add_map(self, stamp_ns: int, points_map: np.ndarray, frame_id: str = '') -> list[Record]:
        """A map cloud, (N, 3) SLAM units, map frame (else InputError): indexed, then handed on."""
        return self._add_map_index(self.build_index(stamp_ns, points_map, frame_id))

    def build_index(self, stamp_ns: int, points_map: np.ndarray, frame_id: str = '') -> MapIndex:
        """The map index with this calibrator's parameters (thread-safe: touches no state)."""
        return MapIndex(points_map, frame_id, stamp_ns, self.params.index_max_points)

    @_public
    def add_map_index(self, index: MapIndex) -> list[Record]:
        """A map already indexed (the node builds the index off the executor's thread)."""
        return self._add_map_index(index)

    def _add_map_index(self, index: MapIndex) -> list[Record]:
        if len(index) == 0:
            return self._reject('cloud_empty', index.stamp_ns)
        if self._map_frame is not None and index.frame_id != self._map_frame:
            self.maps.foreign = index
            return self._reject('cloud_wrong_frame', index.stamp_ns)
        judged, why = self.maps.judge(index, None if self.track.last is None
                                      else self.track.last.c_map)
        if judged is None:  # values no SLAM produces (hac_ros.core.plausibility)
            return self._reject('cloud_implausible', index.stamp_ns, why)
        stream_ns = max(self.map.stamp_ns if self.map is not None else -1, self._last_frame_ns,
                        self.track.newest_stamp_ns or -1)
        if self.timeline.is_before(judged.stamp_ns, stream_ns):
            late, self.timeline.map = self.timeline.map, judged  # a new stream's, if time jumped
            return [] if late is None else self._reject('map_late', late.stamp_ns)
        return [] if self.maps.add(judged) else self._reject('map_late', judged.stamp_ns)

    @_public
    def add_joints(self, stamp_ns: int, joints_cam: np.ndarray,
                   frame_id: str = '') -> list[Record]:
        """HMR joints of one image: (P, K, 3) metres in the camera optical frame (or (P*K, 3)),
        K the layout's joints per person."""
        joints_cam = np.asarray(joints_cam, dtype=float)
        k = self.layout.joints_per_person
        if joints_cam.ndim == 2 and joints_cam.shape[1] == 3 and len(joints_cam) % k == 0:
            joints_cam = joints_cam.reshape(-1, k, 3)
        if joints_cam.ndim != 3 or joints_cam.shape[1:] != (k, 3):
            wrong_k = joints_cam.ndim in (2, 3) and joints_cam.shape[-1] == 3
            return self._reject('joints_wrong_layout' if wrong_k else 'joints_malformed', stamp_ns)
        if frame_id:
            if not self._camera_frame:
                self._camera_frame = frame_id
                if not self._child_frame:
                    self._child_frame = frame_id
            elif frame_id != self._camera_frame:
                return self._reject('joints_wrong_frame', stamp_ns)
        stream_ns = max(self._last_frame_ns, self.track.newest_stamp_ns or -1)
        back = self.timeline.is_before(stamp_ns, stream_ns)
        if stamp_ns <= self._last_frame_ns and not back:
            return self._reject('late_frame', stamp_ns)
        joints_cam, notices = self.conventions.joints(stamp_ns, joints_cam, self._K)
        out: list[Record] = [*notices]
        frame = _Frame(int(stamp_ns), joints_cam)
        if back:  # older than the stream: a new stream's if time jumped back (timeline)
            for late in self.timeline.hold_frame(frame):
                out += self._reject('late_frame', late.stamp_ns)
            return out
        return out + self._queue_frame(frame)

    def _queue_frame(self, frame: _Frame) -> list[Record]:
        """Process ``frame`` now if its pose is known, else keep it until a pose at or after it."""
        last = self.track.last
        if last is not None and last.stamp_ns >= frame.stamp_ns and not self.track.suspects:
            return self._process(frame)
        stamps = [f.stamp_ns for f in self._pending]
        pos = bisect.bisect_right(stamps, frame.stamp_ns)
        if pos and stamps[pos - 1] == frame.stamp_ns:
            return self._reject('late_frame', frame.stamp_ns)  # a repeated stamp
        out: list[Record] = []
        self._pending.insert(pos, frame)
        while len(self._pending) > self.params.pose_buffer:
            dropped = self._pending.pop(0)
            out += self._reject('pending_overflow', dropped.stamp_ns)
        return out

    @_public
    def flush(self) -> list[Record]:
        """End of input: process the frames still waiting (matched within the slop, else
        dropped)."""
        out: list[Record] = []
        for reason, stamp in self.timeline.release(with_suspects=True):  # a jump in time
            out += self._reject(reason, stamp)  # unconfirmed at the very end: stray stamps
        if self.track.vetting and self.track.candidates:  # the first poses, judged as they are
            out += self._vetted(self.track.start(None, self.maps.extent, final=True))
        if self.track.suspects:  # an unconfirmed jump at the very end: its poses are outliers
            for pose in self.track.suspects:
                out += self._reject('pose_outlier', pose.stamp_ns)
            self.track.suspects = []
        while self._pending:
            out += self._process(self._pending.pop(0))
        return out

    @_public
    def reject(self, reason: str, stamp_ns: int = -1) -> list[Record]:
        """Count a rejected input (shells use it for messages they could not decode)."""
        return self._reject(reason, stamp_ns)

    def _reject(self, reason: str, stamp_ns: int = -1, detail: str = '') -> list[Record]:
        """Count a rejection; the first of each reason is announced with ``detail`` (else the
        reason's text)."""
        self.rejected[reason] += 1
        if reason in self._noticed:
            return []
        self._noticed.add(reason)
        text = detail or REASONS.get(reason, reason)
        return [NoticeOut(int(stamp_ns), reason, f'rejected input ({reason}): {text}; '
                          'further ones are counted in /diagnostics')]

    # ================================================================== state
    @property
    def converged(self) -> bool:
        return self.estimator.converged

    @property
    def scale(self) -> float:
        """The current estimate, metres per SLAM unit (RollingScale.current: the window's median,
        or its drift trend while the scale drifts)."""
        return self.estimator.current()

    def published_scale(self, stamp_ns: int) -> float | None:
        """The scale the metric outputs use at ``stamp_ns``, metres per SLAM unit (None: nothing
        metric yet): the ``schedule``'s if one was given, else the online one."""
        if self.schedule is not None:
            return finite_scale(self.schedule(stamp_ns))
        return self.online_scale()

    def online_scale(self) -> float | None:
        """The online scale, which the samples use (the map distance bound, the contacts' ground):
        the estimate once converged, the held one while frozen (and after, until the fresh window
        converges)."""
        return self.services.scale(self.scale if self.converged else None)

    # ================================================================== services
    def request_reset(self) -> None:
        """``~/reset``: start a new segment at the next SLAM pose, as a detected re-initialisation
        does, keeping the map and the ground normal (the odometry stays continuous)."""
        self.services.request('reset')

    def request_freeze(self, frozen: bool) -> None:
        """``~/freeze``: from the next SLAM pose, ``True`` holds the current scale (samples are
        counted, not used, and nothing expires) until ``False``, which resumes with a fresh
        window (the held scale stays published until it converges)."""
        self.services.request('freeze', frozen)

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

    def status(self, stamp_ns: int | None = None) -> Status:
        """A snapshot of the estimator at ``stamp_ns`` (default: the last frame's stamp)."""
        pending = self.pending_status(stamp_ns)
        return self.metric.status(pending, self.published_scale(pending.status.stamp_ns))

    def pending_status(self, stamp_ns: int | None = None) -> PendingStatus:
        """The status before the metric stage places its ground plane in the metric frame."""
        plane = self.ground.plane(self.map)
        status = Status(
            stamp_ns=int(self._last_frame_ns if stamp_ns is None else stamp_ns),
            converged=self.converged, scale=self.scale, spread=self.estimator.spread(),
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
        return PendingStatus(status, plane, None if last is None else last.c_map, self.segment)

    def conditions(self) -> dict[str, str]:
        """What holds now and makes /diagnostics WARN (hac_ros.core.health): reason -> text."""
        out = {}
        if self.freeze.holds:
            out['slam_frozen'] = ('the SLAM pose repeats bit for bit while the people move: '
                                  'tracking lost? (frames not sampled)')
        if self.ground.floor_missing:
            out['floor_unknown'] = ('no floor found in the map: the contacts\' map hits are not '
                                    'checked against it (a table top or a step could pass for it)')
        return out

    @property
    def map(self) -> MapIndex | None:
        """The map in use (SLAM units, map frame), or None."""
        return self.maps.in_use

    @property
    def child_frame_id(self) -> str:
        return self.params.base_frame or self._child_frame

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
        self.ground.add_camera(pose.R_wc)
        # frames before this stamp first, then this pose's odometry, then the frame of this stamp
        while self._pending and self._pending[0].stamp_ns < pose.stamp_ns:
            out += self._process(self._pending.pop(0))
        out += self._odometry(pose)
        while self._pending and self._pending[0].stamp_ns <= pose.stamp_ns:
            out += self._process(self._pending.pop(0))
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
            self.maps.drop()
        # frames before the reset belong to the old map: their poses are gone
        stale = [f for f in self._pending if f.stamp_ns < first_pose.stamp_ns]
        self._pending = [f for f in self._pending if f.stamp_ns >= first_pose.stamp_ns]
        out += [ResetOut(first_pose.stamp_ns, cause),
                NoticeOut(first_pose.stamp_ns, 'reset', f'estimator reset ({cause}): {text}',
                          'warn')]
        for frame in stale:
            out += self._reject('no_pose', frame.stamp_ns)
        return out

    def _restart(self, first_pose: Pose) -> list[Record]:
        """Time jumped back (hac_ros.core.timeline): a new stream from ``first_pose``, its state,
        maps, ground and anchor as at start-up; the odometry goes on (a zero step) and the
        counters keep counting. The frames and the map held for it are its first."""
        jump_s = ((self.track.newest_stamp_ns or first_pose.stamp_ns) - first_pose.stamp_ns) / NS
        stale = self._pending
        frames, held_map = self.timeline.take_held()
        self._init_stream()
        self.services.clear()
        self.resets += 1
        self.events['time_jump_back'] += 1
        self._segment_starts = 'time_jump_back'
        out: list[Record] = [
            ResetOut(first_pose.stamp_ns, 'time_jump_back'),
            NoticeOut(first_pose.stamp_ns, 'time_jump_back', f'header time jumped back by '
                      f'{jump_s:.3f} s (a recording played again, a restarted clock?): a new '
                      'stream starts, calibrated afresh (/hac/odometry goes on)', 'warn')]
        for frame in stale:  # waiting for poses of the old stream that will not come
            out += self._reject('no_pose', frame.stamp_ns)
        if held_map is not None:
            out += self._add_map_index(held_map)
        for frame in frames:
            out += self._queue_frame(frame)
        return out

    # ================================================================== frames
    def _activate_map(self, stamp_ns: int) -> list[Record]:
        """Make the latest map not after ``stamp_ns`` the current one (the processing order); a
        map that does not overlap the previous one is a SLAM re-initialisation."""
        chosen, lost = self.maps.activate(stamp_ns)
        pose = self.track.last
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

    def _process(self, frame: _Frame) -> list[Record]:
        """One frame (docs/method.md, steps 1–6) for every person in it."""
        out: list[Record] = []
        stamp = frame.stamp_ns
        pose = self.track.at(stamp)
        if pose is None:
            return self._reject('no_pose', stamp)
        out += self._activate_map(stamp)
        out += self._hand_map(stamp)
        R_wc, c_map = pose
        self._last_frame_ns = stamp
        self.frames += 1
        if not self.services.holding:  # frozen: nothing expires
            self.estimator.advance(stamp)
        self.check.view_map(stamp, self.map, R_wc, c_map, self._K, self._image_size)
        if self.freeze.frame(self.track.frozen(stamp), frame.joints_cam):
            out += self._reject('slam_frozen', stamp)  # its pose is not the camera's
        else:
            for person, joints in enumerate(frame.joints_cam):
                out += self._person(stamp, person, R_wc, c_map, joints)
        out += self.check.notices(stamp)
        if self.journal is not None or self.published_scale(stamp) is not None:
            plane = self.ground.plane(self.map)
            out += self._metric(PendingFrame(stamp, self.segment, R_wc, c_map, frame.joints_cam,
                                             self.estimator.spread(), plane))
        return out

    def _person(self, stamp: int, person: int, R_wc: np.ndarray, c_map: np.ndarray,
                joints: np.ndarray) -> list[Record]:
        """One person's scale sample (docs/method.md, steps 1–5; hac_ros.core.sample) and its
        bookkeeping."""
        self.people += 1
        if not np.isfinite(joints).all():
            return self._rejected_sample(stamp, person, 'nonfinite_joints')
        unit = body_unit_problem(joints)
        if unit:
            return self._rejected_sample(stamp, person, 'joints_not_metres', unit)
        if not (joints[:, 2] > 0.0).any():
            return self._rejected_sample(stamp, person, 'behind_camera')
        up_cam = self.layout.up_axis(joints)
        self.ground.add_body(R_wc, up_cam)
        self.check.add_person(self.layout, R_wc, joints, up_cam, self._K, self._image_size)
        scale_now = self.online_scale()
        scene = Scene(self.map, self.ground.plane(self.map), self.ground.normal(),
                      self.ground.trusted, self._K, self._image_size, scale_now, self._cos_min)
        sample = person_sample(self.params, self.layout, scene, R_wc, c_map, joints)
        relock: list[Record] = []
        if self.ground.judge_window(sample.floor_scale, scale_now, self.estimator.samples,
                                    self.params.min_samples, self.params.plausibility_rel_tol):
            self.estimator.reset()  # it locked on what the floor now refuses: judged afresh
            relock.append(NoticeOut(stamp, 'floor_relock', 'the floor found in the map disagrees '
                                    'with the estimate (an occluder taken for the contact?): '
                                    'estimate restarted', 'warn'))
            scale_now = None
            scene = replace(scene, scale=None)
            sample = person_sample(self.params, self.layout, scene, R_wc, c_map, joints)
        if sample.reason:
            return relock + self._rejected_sample(stamp, person, sample.reason)
        if sample.source == 'map':
            self.map_hits += 1
        else:
            self.ground_fallbacks += 1
        if self.services.holding:  # counted, not used
            self.services.samples += 1
            return [*relock, SampleOut(stamp, person, sample.scale, sample.source, False)]
        accepted = self.estimator.add(stamp, sample.scale)
        out: list[Record] = [*relock, SampleOut(stamp, person, sample.scale, sample.source,
                                                accepted)]
        if not accepted:
            out += self._reject('gated', stamp)
        else:
            self._sources.append(sample.source == 'ground')
            if sample.source == 'map' and scale_now is not None:
                contact_map = c_map + R_wc @ sample.contact_cam / scale_now
                self.ground.add_contact(contact_map, scale_now)
        return out

    def _rejected_sample(self, stamp: int, person: int, reason: str, detail: str = ''
                         ) -> list[Record]:
        return [SampleOut(stamp, person, float('nan'), reason, False),
                *self._reject(reason, stamp, detail)]

    # ================================================================== outputs
    def _odometry(self, pose: Pose) -> list[Record]:
        """Every accepted pose (the odometry integrates them all, also while a segment
        converges)."""
        # the position's uncertainty comes from the scale's standard error (MetricStage)
        n = max(self.estimator.samples, 1)
        sigma_scale = MEDIAN_STD_ERROR * self.estimator.spread() / math.sqrt(n)
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
