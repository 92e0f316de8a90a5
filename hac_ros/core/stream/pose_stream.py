"""The SLAM pose stream of one segment: jumps, isolated outliers, and the pose at a joints stamp.

A monocular SLAM that re-initialises jumps to a new pose and stays there; a glitch jumps and comes
back. :class:`PoseTrack` tells them apart (docs/interface.md, "Processing order"): a pose whose
speed is far above the recent ones (``reset_jump_factor`` times their median) over a step that is a
fraction of the trajectory's extent (``reset_jump_min_rel``) and of the map's (JUMP_MIN_MAP_REL) is
a *suspect*; if the next poses come back near the old trajectory the suspects were outliers, if
``reset_confirm_poses`` of them continue from the jump the SLAM re-initialised. Speeds, not steps:
keyframe-rate SLAMs publish irregularly, and a long gap between two poses is not a jump.

The first poses of a stream have no history to be judged by, so nothing is anchored on them until
they are judged together (:meth:`PoseTrack.start`): a glitched first pose, or first two, is refused
like a glitch mid-run. A SLAM that lost tracking repeats its last pose bit for bit (a *freeze*);
the pose it resumes with is its true pose in the same map, not a jump
(:meth:`PoseTrack.repetition`). Two SLAMs on one topic in one frame (two robots in one domain
without namespaces) interleave their poses: each near the one two before it, far from the one
before (:class:`ZigzagWatch`).

Poses are camera-to-map (docs/interface.md, "Conventions"): ``R_wc`` (3, 3) rotates the camera
optical frame into the SLAM map frame, ``c_map`` (3,) is the camera centre in SLAM units, map frame.
"""
from __future__ import annotations

import bisect
import itertools
import math
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np

from hac_ros.core.basics.numeric import NS, median_of
from hac_ros.core.basics.transforms import interpolate_pose
from hac_ros.core.rules.params import HacParams

JUMP_HISTORY = 30  # recent pose speeds whose median is the "normal" speed
JUMP_MIN_HISTORY = 5  # steps needed before a jump can be told from normal motion
# ... and a jump is at least this fraction of the map's extent: a camera that stood still has no
# speed and no extent to judge its first motion by, while a re-initialisation jumps across the scene
JUMP_MIN_MAP_REL = 0.01
START_POSES_MAX_FACTOR = 4  # the first poses: decided after at most this many times
                            # reset_confirm_poses + 1 of them, whatever they look like
FREEZE_MIN_NS = 1_000_000_000  # a pose repeated bit for bit this long (stamp time) is a freeze


@dataclass
class Pose:
    """One SLAM pose: stamp (int ns), R_wc (3, 3) camera to map, c_map (3,) SLAM units, map
    frame."""

    stamp_ns: int
    R_wc: np.ndarray
    c_map: np.ndarray


@dataclass
class Verdict:
    """What :meth:`PoseTrack.follow` decided for a pose that came after a jump.

    ``outliers``: suspects that came back (rejected); ``reset``: the first pose of a new segment
    (the SLAM re-initialised there) and ``confirmed``: the suspects to accept after it, in order.
    Neither: the jump is not decided yet (the pose is kept as a suspect).
    """

    outliers: list[Pose]
    reset: Pose | None = None
    confirmed: tuple[Pose, ...] = ()


class PoseTrack:
    """The accepted poses of the current segment (the last ``buffer`` of them) and the suspects.

    jump_factor, jump_min_rel, confirm_poses: ``reset_jump_factor``, ``reset_jump_min_rel``,
    ``reset_confirm_poses``; slop_ns: the joints/pose match tolerance; max_gap_ns: the largest
    gap a joints stamp may be interpolated across.
    """

    def __init__(self, *, buffer: int, jump_factor: float, jump_min_rel: float,
                 confirm_poses: int, slop_ns: int, max_gap_ns: float) -> None:
        self.jump_factor = jump_factor
        self.jump_min_rel = jump_min_rel
        self.confirm_poses = confirm_poses
        self.slop_ns = slop_ns
        self.max_gap_ns = max_gap_ns
        # how joints stamps found their pose (:meth:`at`): 'exact' within the slop, 'interpolated'
        self.matches: Counter[str] = Counter()
        self.poses: deque[Pose] = deque(maxlen=buffer)
        self._stamps: deque[int] = deque(maxlen=buffer)  # parallel to poses
        self.suspects: list[Pose] = []
        self._speeds: deque[float] = deque(maxlen=JUMP_HISTORY)
        # the camera centres' bounding box (SLAM units, map frame): lower and upper corners
        self._bbox: tuple[np.ndarray, np.ndarray] | None = None  # camera centres' box, SLAM units
        self.vetting = True  # the stream's first poses are still to be judged (start)
        self.candidates: list[Pose] = []  # ... the poses so far
        self.repeated_since_ns: int | None = None  # the stamp a bit-for-bit repetition began

    @classmethod
    def from_params(cls, params: HacParams, buffer: int | None = None) -> PoseTrack:
        """The track ``params`` ask for (``pose_buffer`` poses, or ``buffer``)."""
        return cls(buffer=params.pose_buffer if buffer is None else buffer,
                   jump_factor=params.reset_jump_factor, jump_min_rel=params.reset_jump_min_rel,
                   confirm_poses=params.reset_confirm_poses,
                   slop_ns=int(params.sync_slop_s * NS), max_gap_ns=params.interp_max_gap_s * NS)

    @property
    def last(self) -> Pose | None:
        """The last accepted pose."""
        return self.poses[-1] if self.poses else None

    @property
    def newest_stamp_ns(self) -> int | None:
        """The stamp of the newest pose seen (accepted, suspect or candidate): later poses must be
        after it."""
        newest = (self.suspects[-1] if self.suspects else
                  self.candidates[-1] if self.candidates else self.last)
        return None if newest is None else newest.stamp_ns

    def clear(self) -> None:
        """Forget the segment (SLAM re-initialisation); suspects are the caller's to settle."""
        self.poses.clear()
        self._stamps.clear()
        self._speeds.clear()
        self._bbox = None
        self.repeated_since_ns = None

    # ------------------------------------------------------------------ the first poses
    def start(self, pose: Pose | None, map_extent: float = 0.0, final: bool = False
              ) -> list[Pose] | None:
        """Judge the stream's first poses together before anything is anchored on them.

        Collects ``pose`` (None: none more); once the newest run of them (the poses since the
        last jump, judged by their median speed as :meth:`is_jump` judges) holds
        ``confirm_poses + 1`` poses, returns the poses to accept in order: that run, and every
        earlier pose that is no jump from its first (a glitch came back). The rest are left in
        ``candidates``: the caller refuses them (``pose_outlier``). None: not decided yet.
        ``final``: decide with what there is (the end of the input).
        """
        if pose is not None:
            self.candidates.append(pose)
        poses = self.candidates
        enough = self.confirm_poses + 1
        if not poses or (not final and len(poses) < enough):
            return None
        speeds = [_speed(a, b) for a, b in itertools.pairwise(poses)]
        typical = median_of(speeds) if speeds else 0.0
        run = [poses[-1]]
        for earlier in reversed(poses[:-1]):  # the newest run: back to the last jump
            if self._start_jump(earlier, run[0], typical, map_extent):
                break
            run.insert(0, earlier)
        if not final and len(run) < enough and len(poses) < START_POSES_MAX_FACTOR * enough:
            return None
        accepted = [p for p in poses[:len(poses) - len(run)]
                    if not self._start_jump(p, run[0], typical, map_extent)] + run
        self.candidates = [p for p in poses if not any(p is a for a in accepted)]
        self.vetting = False
        return accepted

    def _start_jump(self, a: Pose, b: Pose, typical: float, map_extent: float) -> bool:
        step = float(np.linalg.norm(b.c_map - a.c_map))
        return (_speed(a, b) > self.jump_factor * typical and step > 0.0
                and step > JUMP_MIN_MAP_REL * map_extent)

    # ------------------------------------------------------------------ a frozen SLAM
    def repetition(self, pose: Pose) -> str:
        """``repeat``: ``pose`` repeats the last accepted one bit for bit (a SLAM that lost
        tracking); ``resume``: the first pose that differs after a freeze (the SLAM's true pose in
        the same map: no jump, and its step is not the camera's speed); '' otherwise."""
        last = self.last
        if last is None:
            return ''
        if np.array_equal(pose.c_map, last.c_map) and np.array_equal(pose.R_wc, last.R_wc):
            if self.repeated_since_ns is None:
                self.repeated_since_ns = last.stamp_ns
            return 'repeat'
        resumed = self.frozen(last.stamp_ns)
        self.repeated_since_ns = None
        return 'resume' if resumed else ''

    def frozen(self, stamp_ns: int) -> bool:
        """The SLAM has repeated its pose for FREEZE_MIN_NS up to ``stamp_ns``."""
        since = self.repeated_since_ns
        return since is not None and stamp_ns - since >= FREEZE_MIN_NS

    # ------------------------------------------------------------------ jumps
    def step(self, pose: Pose) -> tuple[float, float] | None:
        """The camera's step from the last accepted pose (SLAM units) and its speed (SLAM units
        per stamp ns); None before the first pose."""
        last = self.last
        if last is None:
            return None
        step = float(np.linalg.norm(pose.c_map - last.c_map))
        return step, step / max(pose.stamp_ns - last.stamp_ns, 1)

    def is_jump(self, move: tuple[float, float] | None, map_extent: float = 0.0) -> bool:
        """A speed far above the recent ones, over a step that is a fraction of the trajectory
        and of the map (``map_extent``, SLAM units; 0 without a map).

        move: the new pose's :meth:`step`.
        """
        if move is None or len(self._speeds) < JUMP_MIN_HISTORY:
            return False
        step, speed = move
        typical = median_of(self._speeds)
        assert self._bbox is not None  # set with the first accepted pose
        extent = float(np.linalg.norm(self._bbox[1] - self._bbox[0]))
        return (speed > self.jump_factor * typical and step > self.jump_min_rel * extent
                and step > JUMP_MIN_MAP_REL * map_extent)

    def follow(self, pose: Pose) -> Verdict:
        """After a jump: back near the old trajectory (the suspects were outliers) or continuing
        from the jump (a reset once ``confirm_poses`` poses followed it)."""
        good, suspect = self.poses[-1], self.suspects[-1]
        if np.linalg.norm(pose.c_map - suspect.c_map) >= np.linalg.norm(pose.c_map - good.c_map):
            outliers, self.suspects = self.suspects, []
            return Verdict(outliers)
        self.suspects.append(pose)
        if len(self.suspects) <= self.confirm_poses:
            return Verdict([])
        first, rest = self.suspects[0], self.suspects[1:-1]
        self.suspects = []
        return Verdict([], first, (first, *rest))  # the caller accepts ``pose`` itself

    # ------------------------------------------------------------------ accepted poses
    def append(self, pose: Pose, move: tuple[float, float] | None) -> None:
        """Accept ``pose``; ``move``: its :meth:`step` (None for the first pose of a segment, a
        repeated pose and the pose a frozen SLAM resumes with: no speed of the camera's)."""
        if move is not None:
            self._speeds.append(move[1])
        self.vetting = False
        self.poses.append(pose)
        self._stamps.append(pose.stamp_ns)
        if self._bbox is None:
            self._bbox = (pose.c_map.copy(), pose.c_map.copy())
        else:
            lo, hi = self._bbox
            self._bbox = (np.minimum(lo, pose.c_map), np.maximum(hi, pose.c_map))

    def at(self, stamp_ns: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The camera pose (R_wc, c_map) at a joints stamp: the nearest accepted pose within the
        slop, else interpolated between its neighbours (gap <= max_gap_ns), else None (never
        extrapolated); each case counted in :attr:`matches` (None: the caller's ``no_pose``)."""
        stamps = self._stamps
        if not stamps:
            return None
        i = bisect.bisect_left(stamps, stamp_ns)
        best = None
        for j in (i - 1, i):
            if (0 <= j < len(stamps) and abs(stamps[j] - stamp_ns) <= self.slop_ns
                    and (best is None or abs(stamps[j] - stamp_ns) < abs(stamps[best] - stamp_ns))):
                best = j
        if best is not None:
            self.matches['exact'] += 1
            return self.poses[best].R_wc, self.poses[best].c_map
        if 0 < i < len(stamps) and stamps[i] - stamps[i - 1] <= self.max_gap_ns:
            self.matches['interpolated'] += 1
            a, b = self.poses[i - 1], self.poses[i]
            return interpolate_pose(stamp_ns, a.stamp_ns, a.R_wc, a.c_map,
                                    b.stamp_ns, b.R_wc, b.c_map)
        return None


def _speed(a: Pose, b: Pose) -> float:
    """SLAM units per stamp ns from ``a`` to ``b``."""
    return float(np.linalg.norm(b.c_map - a.c_map)) / max(abs(b.stamp_ns - a.stamp_ns), 1)


PEOPLE_MOVED_M = 0.25  # joints that moved this far (metres, camera frame) during a freeze ...
PEOPLE_MOVED_SHARE = 0.1  # ... this share of them or more: the people are moving


class FreezeWatch:
    """``slam_frozen``: the SLAM repeats its pose bit for bit while the people in view keep
    moving (a still camera with still people is not frozen). Judged per frame on the people's
    joints in the camera frame (metres) against the first frame of the freeze: a body that walks
    moves its limbs even when a following camera keeps it in the middle of the image."""

    def __init__(self) -> None:
        self._people_at_start: np.ndarray | None = None
        self.holds = False

    def frame(self, frozen: bool, joints_cam: np.ndarray) -> bool:
        """One frame: ``frozen`` (PoseTrack.frozen at its stamp), its joints (P, K, 3) metres,
        camera optical frame. True while the SLAM is frozen and the people moved."""
        if not frozen:
            self._people_at_start, self.holds = None, False
            return False
        start = self._people_at_start
        if start is None:
            self._people_at_start = np.array(joints_cam, dtype=float)
        elif start.shape != joints_cam.shape:
            self.holds = True  # people came or went
        else:
            moved = np.linalg.norm(joints_cam - start, axis=-1)
            moved = moved[np.isfinite(moved)]
            if moved.size and np.mean(moved > PEOPLE_MOVED_M) >= PEOPLE_MOVED_SHARE:
                self.holds = True
        return self.holds


ZIGZAG_POSES = 30  # the last poses judged ...
ZIGZAG_SHARE = 0.8  # ... this share of them back near the pose two before ...
ZIGZAG_BACK_REL = 0.25  # ... closer to it than this fraction of the step from the one before


class ZigzagWatch:
    """``pose_zigzag``: the SLAM pose goes back and forth, pose after pose: each closer to the
    pose two before it than ZIGZAG_BACK_REL of its step from the one before, for ZIGZAG_SHARE of
    the last ZIGZAG_POSES poses. Ratios of steps: no unit, no speed. A camera that moves goes on
    (the pose two before is about two steps away), a still one's noise is as far from either,
    and a freeze does not step; two interleaved sources step back every time."""

    def __init__(self) -> None:
        self._last: deque[tuple[float, float, float]] = deque(maxlen=2)  # two before, one before
        self._backs: deque[bool] = deque(maxlen=ZIGZAG_POSES)
        self.holds = False

    def pose(self, c_map: np.ndarray) -> None:
        """The next pose's centre (3,) SLAM units, as it came (judged or not)."""
        here = (float(c_map[0]), float(c_map[1]), float(c_map[2]))
        if len(self._last) == 2:
            step = math.dist(here, self._last[1])
            self._backs.append(step > 0.0 and math.dist(here, self._last[0])
                               < ZIGZAG_BACK_REL * step)
            self.holds = (len(self._backs) == ZIGZAG_POSES
                          and sum(self._backs) >= ZIGZAG_SHARE * ZIGZAG_POSES)
        self._last.append(here)
