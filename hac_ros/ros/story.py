"""hac_node's log tells the story of a run at INFO, one line each (docs/node.md, "The log").

- each input, once seen for FIRST_SEEN_S (or when the status line comes first): its topic, type
  and rate (``input /slam/pose (geometry_msgs/msg/PoseStamped): 30.0 Hz``);
- waiting for a first SLAM pose while joints come: INFO, naming the topic (waiting for the first
  map is the calibrator's notice, ``no_map``);
- the first map, with its size and the time it took to decode and index;
- convergence, each time the estimate converges: the scale, its spread, the samples, and the
  stamp seconds since the first joints frame, or since the first after a reset (``converged:
  scale 1.2411 +- 0.004 m per SLAM unit (31 samples), 1.03 s after the first joints``);
- every change of the ``/diagnostics`` level, with its reasons;
- every ``log_period_s`` (wall clock; 0 = off) a status line: the last status's level, scale,
  spread and samples, and the joints frames received, processed and dropped (received =
  processed + dropped + waiting) and the poses coalesced.

Every string that came from outside (topic names, frame ids, type names) is escaped
(:func:`hac_ros.core.basics.printable.printable`) before it reaches the log. The calls come from the
executor's thread (:meth:`Story.seen`, :meth:`Story.tick`) and from the processing thread (the
rest); each line is written whole.
"""
from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import Status
from hac_ros.core.basics.printable import printable
from hac_ros.core.rules.health import LEVEL_NAMES, Health, HealthMonitor
from hac_ros.ros.intake import Inbox

FIRST_SEEN_S = 2.0  # an input's rate is given after this long (wall seconds since its first)


@dataclass
class Input:
    """One input as the log names it: its topic (resolved) and message type."""

    topic: str
    msgtype: str


class WatchedHealth(HealthMonitor):
    """The node's HealthMonitor: every status it assesses also goes to ``on_health``."""

    def __init__(self, gravity_wanted: bool, on_health: Callable[[Health, Status], None]) -> None:
        super().__init__(gravity_wanted)
        self.on_health = on_health

    def peek(self, status: Status, extra: Any = ()) -> Health:
        health = super().peek(status, extra)
        self.on_health(health, status)
        return health


class Story:
    """What the node's log says of a run (module docstring). ``logger``: the node's rclpy logger;
    ``inputs``: kind -> :class:`Input` of the subscriptions (updated by the node when they change);
    ``inbox``: the node's inbox (counts)."""

    def __init__(self, logger: Any, inbox: Inbox) -> None:
        self.log = logger
        self.inbox = inbox
        self.inputs: dict[str, Input] = {}
        self._first: dict[str, float] = {}  # kind -> time.monotonic of its first message
        self._last: dict[str, float] = {}
        self._count: Counter[str] = Counter()
        self._told: set[str] = set()  # inputs whose first-seen line was written
        self._waiting_told = False
        self.pose_needed = True  # False for a fixed camera (static_camera): no SLAM pose
        self.map_told = False
        self.first_joints_ns: int | None = None  # the first joints frame (since the last reset)
        self._since = 'the first joints'
        self.converged = False
        self._level: int | None = None
        self.status: Status | None = None  # the last status assessed
        self.health: Health | None = None
        self._line_due_s = float('nan')

    # ------------------------------------------------------------------ executor thread
    def seen(self, kind: str) -> None:
        """A message of input ``kind`` arrived now."""
        now = time.monotonic()
        self._first.setdefault(kind, now)
        self._last[kind] = now
        self._count[kind] += 1

    def tick(self, log_period_s: float) -> None:
        """Steady-clock timer: the inputs' first-seen lines, the waits, the status line."""
        now = time.monotonic()
        for kind, first in list(self._first.items()):
            if kind not in self._told and now - first >= FIRST_SEEN_S:
                self._tell_input(kind)
        if 'joints' in self._told and 'pose' in self.inputs and 'pose' not in self._first \
                and not self._waiting_told and self.pose_needed:
            # (the first map's wait is the calibrator's notice)
            self._waiting_told = True
            self.log.info(f'waiting for the first SLAM pose on '
                          f'{printable(self.inputs["pose"].topic)}: joints come, nothing metric '
                          'until it does')
        if log_period_s <= 0:
            self._line_due_s = float('nan')
            return
        if not now < self._line_due_s:  # NaN: the first tick, or the period was switched on
            if self._line_due_s == self._line_due_s:  # not NaN: the period has passed
                self.log.info(self.status_line())
            self._line_due_s = now + log_period_s

    def _tell_input(self, kind: str) -> None:
        self._told.add(kind)
        what = self.inputs.get(kind)
        if what is None:
            return
        n, span = self._count[kind], self._last[kind] - self._first[kind]
        rate = (f'{(n - 1) / span:.1f} Hz over its first {span:.1f} s' if n > 1 and span > 0
                else f'{n} message in its first {FIRST_SEEN_S:g} s')
        self.log.info(f'input {printable(what.topic)} ({printable(what.msgtype)}): {rate}')

    def status_line(self) -> str:
        """The periodic status line (module docstring)."""
        counts = self.inbox.counts()
        received, processed = counts.received.get('joints', 0), counts.processed.get('joints', 0)
        waiting = counts.waiting.get('joints', 0) + counts.in_hand.get('joints', 0)
        frames = (f'joints frames received {received} = processed {processed} + dropped '
                  f'{counts.dropped} + waiting {waiting}')
        poses = self._count['pose']  # also the transforms of pose_source tf
        poses_text = f'; SLAM poses received {poses}' + (
            f', coalesced {counts.coalesced}' if counts.coalesced else '')
        if counts.superseded:  # the node was behind the maps (hac_ros.ros.intake)
            poses_text += f'; maps superseded while waiting {counts.superseded}'
        s, health = self.status, self.health
        if s is None or health is None:
            state = 'no status yet (no SLAM pose processed)' if self._first else 'no input yet'
        else:
            level = LEVEL_NAMES.get(health.level, str(health.level))
            estimate = (f'scale {s.scale:.6g} +- {s.spread:.2g}'
                        + ('' if s.converged else ' (published, not converged)')
                        if s.publishing else 'not converged')
            reasons = f' ({", ".join(health.reasons)})' if health.reasons else ''
            state = f'{level}{reasons}: {estimate}, {s.samples} samples'
        return f'status {state}; {frames}{poses_text}'

    # ------------------------------------------------------------------ processing thread
    def on_health(self, health: Health, status: Status) -> None:
        """A /diagnostics status was assessed: a change of level is told with its reasons."""
        self.status, self.health = status, health
        if health.level != self._level:
            before = LEVEL_NAMES.get(self._level, '-') if self._level is not None else 'none'
            self._level = health.level
            self.log.info(f'status {before} -> {LEVEL_NAMES.get(health.level, health.level)}'
                          f' ({", ".join(health.reasons) or "all clear"}): '
                          f'{printable(health.message)}')

    def joints_frame(self, stamp_ns: int) -> None:
        """A joints frame of header stamp ``stamp_ns`` went to the calibrator."""
        if self.first_joints_ns is None:
            self.first_joints_ns = stamp_ns

    def first_map(self, points: int, frame_id: str, stamp_ns: int, build_s: float) -> None:
        """The first map decoded and indexed went to the calibrator."""
        if self.map_told:
            return
        self.map_told = True
        self.log.info(f"first map: {points} points in frame '{printable(frame_id)}' (stamp "
                      f'{stamp_ns / NS:.3f} s), decoded and indexed in {1e3 * build_s:.0f} ms')

    def scale(self, stamp_ns: int, status: Callable[[], Status]) -> None:
        """A /hac/scale went out for the frame of ``stamp_ns``; ``status``: the calibrator's
        current status (asked only while not yet converged)."""
        if self.converged:
            return
        now = status()
        if not now.converged:
            return  # a held scale (~/freeze) while a new window fills
        self.converged = True
        after = ('' if self.first_joints_ns is None else
                 f', {(stamp_ns - self.first_joints_ns) / NS:.2f} s after {self._since}')
        self.log.info(f'converged: scale {now.scale:.6g} +- {now.spread:.2g} m per SLAM unit '
                      f'({now.samples} samples){after}')

    def reset(self) -> None:
        """The estimator restarted (a reset, a rebuilt calibrator): the next convergence is
        told again, timed from the first joints frame after it."""
        self.converged = False
        self.first_joints_ns = None
        self._since = 'the first joints since the reset'
