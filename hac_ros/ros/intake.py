"""hac_node's intake: messages taken off DDS at once, processed in arrival order, no backlog.

The executor's thread only receives: each input message (raw bytes) goes into an :class:`Inbox`
with its arrival time, in microseconds. One processing thread (:class:`Processor`) takes the items
in arrival order and hands them to the calibrator. When input comes faster than it is processed,
the inbox never lets a backlog build: beyond ``joints_backlog_max`` joints frames waiting, the
oldest are dropped (counted by the node as ``frames_dropped``). Poses, CameraInfo and maps are
never dropped: the odometry and the jump detector need every pose, and they cost microseconds.
Without drops the calibrator sees exactly the messages, in exactly the order, of the replay's
feed (docs/node.md, "What the node does with each message": Overload).

:class:`LoadStats` keeps what ``/diagnostics`` reports of it: the latency from arrival to
processed of the recent joints frames (wall clock, the node's own), and the backlog. Wall time
is only used here and for the node's stale-input status (the documented exception to stamp time).
"""
from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hac_ros.core.health import STALE, WARN, Finding
from hac_ros.core.params import HacParams

# the reasons of the statuses the node's steady-clock timer republishes (Liveness.stale)
NO_INPUT, NO_STATUS = 'no_input', 'no_status'
STEADY_CLOCK_REASONS = (NO_INPUT, NO_STATUS)
LATENCY_FRAMES = 300  # the recent joints frames whose latency /diagnostics reports (10 s at 30 Hz)


@dataclass
class Item:
    """One input for the calibrator: ``kind`` (``pose``, ``joints``, ``camera_info``, or ``call``:
    a function to run on the processing thread), its data, and its arrival (time.monotonic)."""

    kind: str
    data: Any
    arrived_s: float


class Inbox:
    """The items waiting for the processing thread, in arrival order (thread-safe).

    backlog_max: joints frames that may wait; beyond, the oldest are dropped as new ones come.
    """

    def __init__(self, backlog_max: int) -> None:
        self.backlog_max = backlog_max
        self._items: deque[Item] = deque()
        self._joints = 0  # joints frames among the items
        self._ready = threading.Condition()
        self._closed = False
        self.dropped: list[Item] = []  # joints frames dropped, not yet counted by the node
        self.received: dict[str, int] = {}  # items put, by kind

    def put(self, kind: str, data: Any) -> None:
        with self._ready:
            self.received[kind] = self.received.get(kind, 0) + 1
            self._items.append(Item(kind, data, time.monotonic()))
            if kind == 'joints':
                self._joints += 1
                if self._joints > self.backlog_max:
                    self._drop_oldest_joints()
            self._ready.notify()

    def _drop_oldest_joints(self) -> None:
        for k, item in enumerate(self._items):
            if item.kind == 'joints':
                del self._items[k]
                self._joints -= 1
                self.dropped.append(item)
                return

    def get(self) -> tuple[Item | None, list[Item], int]:
        """The next item (None once closed), the joints frames dropped since the last call, and
        how many joints frames are still waiting behind it. Blocks until there is one."""
        with self._ready:
            while not self._items and not self._closed:
                self._ready.wait()
            if self._closed:
                return None, [], 0
            item = self._items.popleft()
            if item.kind == 'joints':
                self._joints -= 1
            dropped, self.dropped = self.dropped, []
            return item, dropped, self._joints

    def close(self) -> None:
        with self._ready:
            self._closed = True
            self._items.clear()
            self._ready.notify_all()


class LoadStats:
    """Latency (s, arrival to processed) of the recent joints frames and the largest backlog
    since the last report (joints frames waiting)."""

    def __init__(self) -> None:
        self._latency: deque[float] = deque(maxlen=LATENCY_FRAMES)
        self._backlog = 0
        self._lock = threading.Lock()

    def frame(self, latency_s: float, waiting: int) -> None:
        with self._lock:
            self._latency.append(latency_s)
            self._backlog = max(self._backlog, waiting)

    def report(self) -> tuple[float, float, int]:
        """(p50, p99 latency in s, NaN before any frame; the largest backlog since the last
        report), and the backlog starts again."""
        with self._lock:
            values = sorted(self._latency)
            backlog, self._backlog = self._backlog, 0
        if not values:
            return float('nan'), float('nan'), backlog
        return (values[len(values) // 2], values[min(len(values) - 1, int(0.99 * len(values)))],
                backlog)


class Liveness:
    """What only the node knows of its input, for /diagnostics (wall clock): the latency and
    backlog of its joints frames (:class:`LoadStats`), when each kind of input last came, and
    when the last stamp-time status went out."""

    def __init__(self) -> None:
        self.load = LoadStats()
        self.arrived: dict[str, float] = {}  # input kind -> time.monotonic of its last message
        self.started_s = time.monotonic()
        self.status_sent_s = self.started_s
        self.first_arrival_s = float('inf')  # when input first came

    def arrival(self, kind: str) -> None:
        """A message of ``kind`` came now."""
        now = time.monotonic()
        self.arrived[kind] = now
        self.first_arrival_s = min(self.first_arrival_s, now)

    def findings(self, p: HacParams) -> tuple[list[Finding], list[tuple[str, str]]]:
        """The findings (hac_ros.core.health) and key-values added to each status: latency over
        ``latency_warn_s``, a backlog at ``joints_backlog_max``, one kind of input silent for
        ``stale_after_s`` while the other comes."""
        p50, p99, backlog = self.load.report()
        found: list[Finding] = []
        if p99 > p.latency_warn_s:  # NaN (no frame yet) is not
            found.append(Finding('latency', f'latency p99 {1e3 * p99:.0f} ms over '
                                 f'latency_warn_s ({1e3 * p.latency_warn_s:.0f} ms)'))
        if backlog >= p.joints_backlog_max:
            found.append(Finding('backlog', f'input faster than processing: {backlog} joints '
                                 'frames waiting'))
        now = time.monotonic()
        quiet = {kind: now - self.arrived.get(kind, self.started_s) for kind in ('pose', 'joints')}
        for kind, other, reason, text in (('joints', 'pose', 'no_joints', 'no HMR joints'),
                                          ('pose', 'joints', 'no_poses', 'no SLAM pose')):
            if quiet[kind] > p.stale_after_s and quiet[other] <= p.stale_after_s:
                found.append(Finding(reason, f'{text} for {quiet[kind]:.0f} s'))
        values = [('latency_p50_ms', f'{1e3 * p50:.1f}'), ('latency_p99_ms', f'{1e3 * p99:.1f}'),
                  ('backlog', str(backlog))]
        return found, values

    def stale(self, p: HacParams) -> Finding | None:
        """When no stamp-time status went out for ``stale_after_s``: STALE ``no_input`` if no
        input came for that long either (or ever), else WARN ``no_status`` (input comes, but no
        SLAM pose to make a status of, or the processing is that far behind); None otherwise."""
        now = time.monotonic()
        since = now - self.status_sent_s
        if since < p.stale_after_s:
            return None
        if not self.arrived:
            return Finding(NO_INPUT, 'no input yet', STALE)
        quiet = now - max(self.arrived.values())
        if quiet >= p.stale_after_s:
            return Finding(NO_INPUT, f'no input for {quiet:.0f} s', STALE)
        if now - self.first_arrival_s < p.stale_after_s:
            return None  # input has only just begun
        return Finding(NO_STATUS, f'no status for {since:.0f} s while input comes', WARN)


class Processor:
    """The processing thread: items from ``inbox`` to ``handle`` (called holding ``lock``, the
    lock every other access to the calibrator takes), in arrival order; ``on_dropped`` for each
    joints frame the inbox dropped. ``stats`` gets each joints frame's latency."""

    def __init__(self, inbox: Inbox, handle: Callable[[Item], None],
                 on_dropped: Callable[[Item], None], lock: threading.RLock,
                 stats: LoadStats) -> None:
        self.inbox, self.handle, self.on_dropped = inbox, handle, on_dropped
        self.lock, self.stats = lock, stats
        self.processed = 0  # items handled
        self._thread = threading.Thread(target=self._run, name='hac_processing', daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while True:
            item, dropped, waiting = self.inbox.get()
            if item is None:
                return
            with self.lock:
                for frame in dropped:
                    self.on_dropped(frame)
                self.handle(item)
                self.processed += 1
            if item.kind == 'joints':
                self.stats.frame(time.monotonic() - item.arrived_s, waiting)

    def close(self) -> None:
        """Stop after the item being handled (those still waiting are dropped)."""
        self.inbox.close()
        if self._thread is not threading.current_thread():
            self._thread.join()
