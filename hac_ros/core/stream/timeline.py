"""Header time that jumps: a recording played again, a clock reset, one stamp far off.

Stamps are the clock (docs/interface.md, "Processing order"), so the calibrator must tell a late
message from time itself jumping. :class:`Timeline` judges each SLAM pose's stamp against the
newest stamp of the stream so far:

- not after it by at most ``time_jump_back_s``: a late pose (refused, ``pose_out_of_order``; a
  late joints frame is ``late_frame``);
- before it by more than ``time_jump_back_s``: a *suspect* jump back. If ``reset_confirm_poses``
  poses follow it in its new timeline, time jumped back (``ros2 bag play --loop``, a restarted
  recording or simulator): a **new stream** starts at it, as tf2 clears its buffer on a jump back
  in time (``restart``). If the stream goes on where it was instead, the suspects were late poses;
- after it by more than ``time_jump_ahead_s``: a suspect jump ahead. Poses that go on from it make
  it a jump forward that persists (``ahead``: a new segment); the next pose back in the old
  timeline makes it one stamp far ahead of the rest (refused, ``pose_stamp_outlier``).

While a jump back is suspect, joints frames older than the stream by more than the tolerance are
*held*: they belong to the new stream if it is confirmed (so that its first frames are calibrated
too) and are late otherwise. A map never decides a jump in time: maps are slow by nature (stamped
with the keyframe they came from, built or carried for seconds), so a map older than the stream is
used by the current stream when it is the newest one (hac_ros.core.stream.map_book) and also held,
in case the poses confirm a jump back (a looped recording's latched map arrives before its poses).
Stamps are int nanoseconds.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from hac_ros.core.stream.pose_stream import Pose

HELD_FRAMES_MAX = 600  # joints frames held for a suspected new stream (20 s at 30 Hz)


@dataclass
class Stamped:
    """A SLAM pose as it came: the pose, its map frame and child frame."""

    pose: Pose
    frame_id: str = ''
    child_frame_id: str = ''


@dataclass
class TimeVerdict:
    """What :meth:`Timeline.judge` decided for a pose.

    kind: ``ok`` (go on in the current stream), ``late`` (refuse it: ``pose_out_of_order``),
    ``held`` (a suspect; nothing yet), ``restart`` (time jumped back: a new stream from
    ``poses``, the current pose last) or ``ahead`` (time jumped ahead: a new segment from
    ``poses``). refused: earlier suspects that turned out wrong, each refused as ``reason``.
    """

    kind: str
    poses: list[Stamped] = field(default_factory=list)
    refused: list[Stamped] = field(default_factory=list)
    reason: str = ''


class Timeline:
    """The stream's time: suspects of a jump, and the inputs held for a suspected new stream.

    back_ns, ahead_ns: ``time_jump_back_s`` and ``time_jump_ahead_s`` in ns; confirm:
    ``reset_confirm_poses``.
    """

    def __init__(self, back_ns: int, ahead_ns: int, confirm: int) -> None:
        self.back_ns = back_ns
        self.ahead_ns = ahead_ns
        self.confirm = confirm
        self.suspects: list[Stamped] = []
        self.direction = ''  # 'back' or 'ahead' while there are suspects
        self.frames: list[Any] = []  # joints frames held for a new stream, in arrival order
        self.map: Any = None  # the newest map older than the stream, for a new stream

    def judge(self, item: Stamped, newest_ns: int | None) -> TimeVerdict:
        """``item``'s pose against ``newest_ns``, the newest pose stamp of the current stream
        (None before the first)."""
        if self.suspects:
            return self._follow(item, newest_ns)
        return self._first(item, newest_ns)

    def _first(self, item: Stamped, newest_ns: int | None) -> TimeVerdict:
        stamp = item.pose.stamp_ns
        if newest_ns is None:
            return TimeVerdict('ok')
        if stamp <= newest_ns:
            if newest_ns - stamp <= self.back_ns:
                return TimeVerdict('late')
            self.suspects, self.direction = [item], 'back'
            return TimeVerdict('held')
        if stamp - newest_ns > self.ahead_ns:
            self.suspects, self.direction = [item], 'ahead'
            return TimeVerdict('held')
        return TimeVerdict('ok')

    def _follow(self, item: Stamped, newest_ns: int | None) -> TimeVerdict:
        stamp, last = item.pose.stamp_ns, self.suspects[-1].pose.stamp_ns
        in_old = newest_ns is not None and stamp > newest_ns and (
            self.direction == 'back' or stamp < self.suspects[0].pose.stamp_ns)
        if in_old:  # the stream went on where it was: the suspects were stray stamps
            refused, self.suspects = self.suspects, []
            reason = 'pose_out_of_order' if self.direction == 'back' else 'pose_stamp_outlier'
            verdict = self._first(item, newest_ns)
            verdict.refused, verdict.reason = refused, reason
            return verdict
        if stamp <= last:
            return TimeVerdict('late')
        self.suspects.append(item)
        if len(self.suspects) <= self.confirm:
            return TimeVerdict('held')
        poses, self.suspects = self.suspects, []
        return TimeVerdict('restart' if self.direction == 'back' else 'ahead', poses)

    @property
    def suspect_back(self) -> bool:
        return bool(self.suspects) and self.direction == 'back'

    def newest_suspect_ns(self) -> int | None:
        return self.suspects[-1].pose.stamp_ns if self.suspects else None

    # ------------------------------------------------------------------ held inputs
    def is_before(self, stamp_ns: int, stream_ns: int) -> bool:
        """A stamp before the stream's (``stream_ns``) by more than the tolerance."""
        return stream_ns - stamp_ns > self.back_ns

    def hold_frame(self, frame: Any) -> list[Any]:
        """Hold a joints frame (anything with a ``stamp_ns``) for a suspected new stream; the
        frames that no longer fit (the oldest, beyond HELD_FRAMES_MAX) are returned: late."""
        self.frames.append(frame)
        overflow = self.frames[:-HELD_FRAMES_MAX]
        self.frames = self.frames[-HELD_FRAMES_MAX:]
        return overflow

    def take_held(self) -> tuple[list[Any], Any]:
        """The held frames (in arrival order) and map, handed over and forgotten."""
        frames, held_map = self.frames, self.map
        self.frames, self.map = [], None
        return frames, held_map

    def release(self, with_suspects: bool = False) -> list[tuple[str, int]]:
        """No new stream after all: what was held is late, as (reason, stamp) to count; with
        ``with_suspects`` (the end of the input) the suspects too, as stray stamps."""
        out: list[tuple[str, int]] = []
        if with_suspects:
            reason = 'pose_out_of_order' if self.direction == 'back' else 'pose_stamp_outlier'
            out += [(reason, item.pose.stamp_ns) for item in self.suspects]
            self.suspects = []
        frames, _ = self.take_held()  # the map was counted (or used) when it came
        out += [('late_frame', frame.stamp_ns) for frame in frames]
        return out
