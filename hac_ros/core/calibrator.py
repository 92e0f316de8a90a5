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
This module judges the inputs; the state and what happens once a pose is accepted (frames,
people, resets, outputs, status) are :class:`hac_ros.core.frame_loop.FrameLoop`'s.
"""
from __future__ import annotations

import bisect
import functools
from collections.abc import Callable
from typing import Concatenate, ParamSpec

import numpy as np

from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import NoticeOut, Output, ResetOut
from hac_ros.core.basics.transforms import is_rotation
from hac_ros.core.frame_loop import Frame, FrameLoop
from hac_ros.core.geometry.reference import MapIndex
from hac_ros.core.stream.pending import Record, outputs_only
from hac_ros.core.stream.pose_stream import Pose
from hac_ros.core.stream.timeline import Stamped

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


def _wrong_frame(what: str, frame_id: str, others: str, expected: str | None) -> str:
    """The notice of an input refused for its frame, naming both frames (repr: escaped, and
    cut at 200 characters)."""
    return f'{what} in frame {frame_id[:200]!r}, {others} in {(expected or "")[:200]!r}: refused'


class Calibrator(FrameLoop):
    """Feed it inputs with ``add_*``; each call returns the outputs it produced, in order.

    schedule: stamp ns -> the scale (metres per SLAM unit; None: nothing metric) the metric
    outputs use, instead of the online estimate; the samples still use the online estimate.
    offline: the metric outputs (odometry and pose, world joints, scale, cloud, diagnostics) are
    held back: each call returns the others, and :attr:`journal` keeps every record in order until
    :func:`hac_ros.core.offline.resolve_offline` resolves the run with the whole recording's
    schedule.
    """

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

        Its stamp is judged first (hac_ros.core.stream.timeline: late, a jump back that starts a new
        stream, one stamp far ahead, a jump ahead), then the pose in its stream (pose_stream)."""
        return self._add_pose(stamp_ns, R_wc, c_map, frame_id, child_frame_id)

    def _add_pose(self, stamp_ns: int, R_wc: np.ndarray, c_map: np.ndarray, frame_id: str = '',
                  child_frame_id: str = '') -> list[Record]:
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

    def _wrong_frame_poses(self) -> list[Record]:
        """The poses of a run in another frame that no new map confirmed: refused."""
        run, self._frame_run = self._frame_run, []
        return [o for held in run for o in self._reject(
            'pose_wrong_frame', held.pose.stamp_ns, _wrong_frame(
                'SLAM pose', held.frame_id, 'the poses before and after it', self._map_frame)
            + ' (two SLAMs on pose_topic?)')]

    def _stream_pose(self, item: Stamped) -> list[Record]:
        """A pose whose stamp belongs to the current stream: the map frame, the stream's first
        poses, jumps and outliers, a frozen SLAM (hac_ros.core.stream.pose_stream)."""
        pose, frame_id, track = item.pose, item.frame_id, self.track
        if item.child_frame_id and not self.params.camera_frame and self.conventions.optical_poses:
            self._child_frame = item.child_frame_id
        out: list[Record] = []
        move = None  # the pose's step, when the jump test computed it
        measured = True  # the step is the camera's motion (not a freeze's)
        if self._map_frame is None:
            self._map_frame = frame_id
            out += [o for m in self.maps.refuse_foreign(frame_id)
                    for o in self._reject('cloud_wrong_frame', m.stamp_ns, _wrong_frame(
                        'map cloud', m.frame_id, 'the SLAM poses', frame_id))]
        elif frame_id != self._map_frame:
            run = self._frame_run
            if run and run[0].frame_id != frame_id:  # a third frame: the run was no new map's
                out += self._wrong_frame_poses()
            run.append(item)
            if len(run) <= self.params.reset_confirm_poses:
                return out  # held until confirmed (or refused)
            self._frame_run = []
            out += self._reset(run[0].pose, 'map_frame', f'SLAM map frame changed '
                               f'{self._map_frame!r} -> {frame_id!r}: SLAM re-initialised')
            self._map_frame = frame_id
            foreign, self.maps.foreign = self.maps.foreign, None
            if foreign is not None and foreign.frame_id == frame_id:  # it came first: adopted
                out += self._add_map_index(foreign)
            for held in run[:-1]:
                out += self._stream_pose(held)
        elif self._frame_run:  # back in the map's frame: the run was another publisher's
            out += self._wrong_frame_poses()
        self.zigzag.pose(pose.c_map)
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
        if self.params.static_camera and self._map_frame == '':
            self._map_frame = index.frame_id  # poses made for a fixed camera: the map's frame
        if self._map_frame is not None and index.frame_id != self._map_frame:
            self.maps.foreign = index
            return self._reject('cloud_wrong_frame', index.stamp_ns,
                                _wrong_frame('map cloud', index.frame_id, 'the SLAM poses',
                                             self._map_frame))
        judged, reason, why = self.maps.judge(index, None if self.track.last is None
                                              else self.track.last.c_map)
        if judged is None:  # values no SLAM produces, or no surface (plausibility, map_shape)
            return self._reject(reason, index.stamp_ns, why)
        if self.maps.before_segment(judged.stamp_ns):
            return self._reject('map_old_segment', judged.stamp_ns)
        stream_ns = max(self.map.stamp_ns if self.map is not None else -1, self._last_frame_ns,
                        self.track.newest_stamp_ns or -1)
        out = [] if self.maps.add(judged) else self._reject('map_superseded', judged.stamp_ns)
        if self.timeline.is_before(judged.stamp_ns, stream_ns):
            # a map that lags the poses (maps are slow) is used now if it is the newest; it is
            # also held, in case the poses confirm that time jumped back (timeline)
            self.timeline.map = judged
        return out

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
                return self._reject('joints_wrong_frame', stamp_ns,
                                    _wrong_frame('joints', frame_id, 'the first joints',
                                                 self._camera_frame))
        stream_ns = max(self._last_frame_ns, self.track.newest_stamp_ns or -1)
        back = self.timeline.is_before(stamp_ns, stream_ns)
        if stamp_ns <= self._last_frame_ns and not back:
            return self._reject('late_frame', stamp_ns)
        joints_cam, notices = self.conventions.joints(stamp_ns, joints_cam, self._K)
        out: list[Record] = [*notices]
        frame = Frame(int(stamp_ns), joints_cam)
        if back:  # older than the stream: a new stream's if time jumped back (timeline)
            for late in self.timeline.hold_frame(frame):
                out += self._reject('late_frame', late.stamp_ns)
            return out
        if self.params.static_camera:
            out += self._static_pose(int(stamp_ns))
        return out + self._queue_frame(frame)

    def _static_pose(self, stamp_ns: int) -> list[Record]:
        """A fixed camera (``static_camera``): the pose at a joints stamp is the last one given
        (the camera has not moved), or the map's origin before any, added as a SLAM pose unless
        one at or after the stamp came; in the frame of the poses, else of the map, else ''."""
        last = self.track.last
        if last is not None and last.stamp_ns >= stamp_ns:
            return []
        R_wc, c_map = (last.R_wc, last.c_map) if last is not None else (np.eye(3), np.zeros(3))
        maps = [m for m in (self.maps.in_use, *self.maps.waiting) if m is not None]
        frame = self._map_frame if self._map_frame is not None else (
            maps[-1].frame_id if maps else '')
        return self._add_pose(stamp_ns, R_wc, c_map, frame)

    def _queue_frame(self, frame: Frame) -> list[Record]:
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

    # ================================================================== time
    def _restart(self, first_pose: Pose) -> list[Record]:
        """Time jumped back (hac_ros.core.stream.timeline): a new stream from ``first_pose``, its
        state, maps, ground and anchor as at start-up; the odometry goes on (a zero step) and the
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
