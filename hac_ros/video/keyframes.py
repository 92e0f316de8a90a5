"""Keyframes of a video: the frames ``hac video`` reconstructs (docs/video.md, "What it runs").

By motion (the default): corners are tracked frame to frame from the last keyframe (Lucas-Kanade
on the grey image reduced to ``TRACK_WIDTH`` pixels); a frame becomes a keyframe when their median
shift since the keyframe passes ``motion`` of the image width, when fewer than ``MIN_TRACKED`` of
them survive, or when ``max_gap_s`` has passed since the last keyframe (a still camera still gets
one keyframe per ``max_gap_s``). At a fixed ``rate_hz``: a keyframe whenever the next frame would
be more than 1 / ``rate_hz`` after the last keyframe. Either way the first and the last frame are
keyframes and no two follow each other more than ``max_gap_s`` apart; the corners are tracked in
both, so that a camera that never moved is known (:attr:`MotionKeyframes.most_motion`).

Frame i is stamped ``start + i / fps`` seconds, as ``hac people`` stamps it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hac_ros.core.basics.errors import ArgumentError

TRACK_WIDTH = 320  # pixels: the width motion is measured at
CORNERS = 300  # corners tracked from each keyframe
MIN_TRACKED = 0.5  # share of a keyframe's corners that must survive (else: a keyframe)
DEFAULT_MOTION = 0.06  # median corner shift, share of the image width, that makes a keyframe
MAX_GAP_S = 1.0  # seconds: the longest a video goes without a keyframe


@dataclass
class KeyframeChoice:
    """``index`` (N,) int: the frames chosen, increasing; ``frames`` how many the video has;
    ``why`` (N,) str: 'first', 'motion', 'tracks', 'gap', 'rate' or 'last'."""

    index: np.ndarray
    frames: int
    why: list[str]


def check_rate(rate_hz: float | None, max_gap_s: float = MAX_GAP_S) -> None:
    """ArgumentError naming ``keyframe_rate`` unless it is None or keeps gaps <= ``max_gap_s``."""
    if rate_hz is None:
        return
    if not (math.isfinite(rate_hz) and rate_hz >= 1.0 / max_gap_s):
        raise ArgumentError(f'{{keyframe_rate}} {rate_hz!r}: at least {1.0 / max_gap_s:g} '
                            f'keyframe per second (no gap over {max_gap_s:g} s)', 'keyframe_rate')


class MotionKeyframes:
    """The choice (module docstring), fed one frame at a time: ``fps`` the video's rate;
    ``motion`` the median corner shift (share of the width) that makes a keyframe; ``rate_hz``
    keyframes per second instead (None: by motion); ``max_gap_s``. Needs OpenCV (the [people]
    extra)."""

    def __init__(self, fps: float, *, motion: float = DEFAULT_MOTION,
                 rate_hz: float | None = None, max_gap_s: float = MAX_GAP_S) -> None:
        from hac_ros.people.extra import opencv

        cv2 = opencv()
        check_rate(rate_hz, max_gap_s)
        self.rate_hz = rate_hz
        self.most_motion = 0.0  # the largest median corner shift seen, share of the width
        if not 0.0 < motion < 1.0:
            raise ArgumentError(f'{{keyframe_motion}} {motion!r}: a share of the image width in '
                                '(0, 1)', 'keyframe_motion')
        self.cv2, self.fps, self.motion, self.max_gap_s = cv2, fps, motion, max_gap_s
        self.index: list[int] = []
        self.why: list[str] = []
        self._count = 0
        self._last_grey: np.ndarray | None = None
        self._start: np.ndarray | None = None  # (M, 2) the keyframe's corners, tracking pixels
        self._now: np.ndarray | None = None  # (M, 2) where they are in the last frame
        self._detected = 0  # corners found in the last keyframe
        self._pending = -1  # the last frame seen, when it is not a keyframe (for 'last')

    def _grey(self, rgb: np.ndarray) -> np.ndarray:
        cv2 = self.cv2
        height, width = rgb.shape[:2]
        size = (TRACK_WIDTH, max(1, round(height * TRACK_WIDTH / width)))
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        return cv2.resize(grey, size, interpolation=cv2.INTER_AREA) if width > TRACK_WIDTH else grey

    def _keep(self, i: int, grey: np.ndarray, why: str) -> None:
        self.index.append(i)
        self.why.append(why)
        corners = self.cv2.goodFeaturesToTrack(grey, CORNERS, 0.01, 7)
        self._start = (np.zeros((0, 2), np.float32) if corners is None
                       else corners.reshape(-1, 2).astype(np.float32))
        self._now = self._start.copy()
        self._detected = len(self._start)
        self._pending = -1

    def add(self, rgb: np.ndarray) -> bool:
        """Takes the next frame, (H, W, 3) uint8 RGB; True when it is a keyframe."""
        i = self._count
        self._count += 1
        grey = self._grey(rgb)
        last, self._last_grey = self._last_grey, grey
        if last is None or self._start is None or self._now is None:
            self._keep(i, grey, 'first')
            return True
        why = ''
        if len(self._now):
            moved, status, _ = self.cv2.calcOpticalFlowPyrLK(
                last, grey, self._now.reshape(-1, 1, 2), None, winSize=(21, 21), maxLevel=3)
            ok = status.reshape(-1).astype(bool)
            self._start, self._now = self._start[ok], moved.reshape(-1, 2)[ok]
        shift = (float(np.median(np.linalg.norm(self._now - self._start, axis=1)))
                 / grey.shape[1] if len(self._now) else math.inf)
        self.most_motion = max(self.most_motion, shift)
        since = (i - self.index[-1]) / self.fps  # seconds since the last keyframe
        if self.rate_hz is not None:
            why = 'rate' if since + 1.0 / self.fps > 1.0 / self.rate_hz + 1e-9 else ''
        elif len(self._now) < MIN_TRACKED * self._detected:
            why = 'tracks'
        elif shift > self.motion:
            why = 'motion'
        elif since + 1.0 / self.fps > self.max_gap_s + 1e-9:
            why = 'gap'
        if why:
            self._keep(i, grey, why)
            return True
        self._pending = i
        return False

    def finish(self) -> KeyframeChoice:
        """The choice, the last frame added as a keyframe if it was not one."""
        if self._pending >= 0:
            self.index.append(self._pending)
            self.why.append('last')
            self._pending = -1
        return KeyframeChoice(np.array(self.index, dtype=int), self._count, list(self.why))
