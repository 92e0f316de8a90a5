"""The SLAM pose stream of one segment: jumps, isolated outliers, and the pose at a joints stamp.

A monocular SLAM that re-initialises jumps to a new pose and stays there; a glitch jumps and comes
back. :class:`PoseTrack` tells them apart (docs/interface.md, "Processing order"): a pose whose
speed is far above the recent ones (``reset_jump_factor`` times their median) over a step that is a
fraction of the trajectory's extent (``reset_jump_min_rel``) and of the map's (JUMP_MIN_MAP_REL) is
a *suspect*; if the next poses come back near the old trajectory the suspects were outliers, if
``reset_confirm_poses`` of them continue from the jump the SLAM re-initialised. Speeds, not steps:
keyframe-rate SLAMs publish irregularly, and a long gap between two poses is not a jump.

Poses are camera-to-map (docs/interface.md, "Conventions"): ``R_wc`` (3, 3) rotates the camera
optical frame into the SLAM map frame, ``c_map`` (3,) is the camera centre in SLAM units, map frame.
"""
from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass

import numpy as np

from hac_ros.core.transforms import interpolate_pose

JUMP_HISTORY = 30  # recent pose speeds whose median is the "normal" speed
JUMP_MIN_HISTORY = 5  # steps needed before a jump can be told from normal motion
# ... and a jump is at least this fraction of the map's extent: a camera that stood still has no
# speed and no extent to judge its first motion by, while a re-initialisation jumps across the scene
JUMP_MIN_MAP_REL = 0.01


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

    def __init__(self, buffer: int, jump_factor: float, jump_min_rel: float, confirm_poses: int,
                 slop_ns: int, max_gap_ns: float) -> None:
        self.jump_factor = jump_factor
        self.jump_min_rel = jump_min_rel
        self.confirm_poses = confirm_poses
        self.slop_ns = slop_ns
        self.max_gap_ns = max_gap_ns
        self.poses: deque[Pose] = deque(maxlen=buffer)
        self._stamps: deque[int] = deque(maxlen=buffer)  # parallel to poses
        self.suspects: list[Pose] = []
        self._speeds: deque[float] = deque(maxlen=JUMP_HISTORY)
        # the camera centres' bounding box (SLAM units, map frame): lower and upper corners
        self._bbox: tuple[np.ndarray, np.ndarray] | None = None  # camera centres' box, SLAM units

    @property
    def last(self) -> Pose | None:
        """The last accepted pose."""
        return self.poses[-1] if self.poses else None

    @property
    def newest_stamp_ns(self) -> int | None:
        """The stamp of the newest pose seen (accepted or suspect): later poses must be after it."""
        newest = self.suspects[-1] if self.suspects else self.last
        return None if newest is None else newest.stamp_ns

    def clear(self) -> None:
        """Forget the segment (SLAM re-initialisation); suspects are the caller's to settle."""
        self.poses.clear()
        self._stamps.clear()
        self._speeds.clear()
        self._bbox = None

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
        typical = float(np.median(self._speeds))
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
        """Accept ``pose``; ``move``: its :meth:`step` (None for the first pose of a segment)."""
        if move is not None:
            self._speeds.append(move[1])
        self.poses.append(pose)
        self._stamps.append(pose.stamp_ns)
        if self._bbox is None:
            self._bbox = (pose.c_map.copy(), pose.c_map.copy())
        else:
            lo, hi = self._bbox
            self._bbox = (np.minimum(lo, pose.c_map), np.maximum(hi, pose.c_map))

    def at(self, stamp_ns: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The camera pose (R_wc, c_map) at a joints stamp: the nearest accepted pose within the
        slop, else interpolated between its neighbours (gap <= max_gap_ns), else None."""
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
            return self.poses[best].R_wc, self.poses[best].c_map
        if 0 < i < len(stamps) and stamps[i] - stamps[i - 1] <= self.max_gap_ns:
            a, b = self.poses[i - 1], self.poses[i]
            return interpolate_pose(stamp_ns, a.stamp_ns, a.R_wc, a.c_map,
                                    b.stamp_ns, b.R_wc, b.c_map)
        return None
