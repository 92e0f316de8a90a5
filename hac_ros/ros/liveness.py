"""What only hac_node knows of its input, for ``/diagnostics``: how far behind it is, its backlog,
which input stopped coming (wall clock, the node's own).

:class:`LoadStats` keeps the latency from arrival to processed of the recent joints frames and
the largest backlog; :class:`Liveness` turns them, the lag (now minus the arrival of the oldest
input not yet processed, poses included: :meth:`hac_ros.ros.intake.Inbox.oldest_arrival_s`) and
the arrival times of each kind of input into findings (:mod:`hac_ros.core.rules.health`). Wall time
is only used here, for the node's log and for its stale-input status (the documented exception to
stamp time).
"""
from __future__ import annotations

import threading
import time
from collections import deque

from hac_ros.core.rules.health import STALE, WARN, Finding
from hac_ros.core.rules.params import HacParams

# the reasons of the statuses the node's steady-clock timer republishes (Liveness.stale)
NO_INPUT, NO_STATUS = 'no_input', 'no_status'
STEADY_CLOCK_REASONS = (NO_INPUT, NO_STATUS)
LATENCY_FRAMES = 300  # the recent joints frames whose latency /diagnostics reports (10 s at 30 Hz)


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
    """The latency and backlog of the node's joints frames (:class:`LoadStats`), when each kind of
    input first and last came and how many, and when the last stamp-time status went out."""

    def __init__(self) -> None:
        self.load = LoadStats()
        self.arrived: dict[str, float] = {}  # input kind -> time.monotonic of its last message
        self.first: dict[str, float] = {}  # input kind -> time.monotonic of its first message
        self.started_s = time.monotonic()
        self.status_sent_s = self.started_s
        self.first_arrival_s = float('inf')  # when input first came

    def arrival(self, kind: str) -> None:
        """A message of ``kind`` came now."""
        now = time.monotonic()
        self.arrived[kind] = now
        self.first.setdefault(kind, now)
        self.first_arrival_s = min(self.first_arrival_s, now)

    def findings(self, p: HacParams, lag_s: float = 0.0
                 ) -> tuple[list[Finding], list[tuple[str, str]]]:
        """The findings (hac_ros.core.rules.health) and key-values added to each status: behind by
        more than ``latency_warn_s`` (``lag_s``: now minus the arrival of the oldest input not yet
        processed; or the p99 of the recent joints frames), a backlog at ``joints_backlog_max``,
        one kind of input silent for ``stale_after_s`` while the other comes."""
        p50, p99, backlog = self.load.report()
        found: list[Finding] = []
        if lag_s > p.latency_warn_s:
            found.append(Finding('latency', f'behind by {1e3 * lag_s:.0f} ms (the oldest input '
                                 f'waiting) over latency_warn_s ({1e3 * p.latency_warn_s:.0f} ms)'))
        elif p99 > p.latency_warn_s:  # NaN (no frame yet) is not
            found.append(Finding('latency', f'latency p99 {1e3 * p99:.0f} ms over '
                                 f'latency_warn_s ({1e3 * p.latency_warn_s:.0f} ms)'))
        if backlog >= p.joints_backlog_max:
            found.append(Finding('backlog', f'input faster than processing: {backlog} joints '
                                 'frames waiting'))
        now = time.monotonic()
        quiet = {kind: now - self.arrived.get(kind, self.started_s) for kind in ('pose', 'joints')}
        for kind, other, reason, text in (('joints', 'pose', 'no_joints', 'no HMR joints'),
                                          ('pose', 'joints', 'no_poses', 'no SLAM pose')):
            if kind == 'pose' and p.static_camera:
                continue  # a fixed camera needs no SLAM pose
            if quiet[kind] > p.stale_after_s and quiet[other] <= p.stale_after_s:
                found.append(Finding(reason, f'{text} for {quiet[kind]:.0f} s'))
        values = [('latency_p50_ms', f'{1e3 * p50:.1f}'), ('latency_p99_ms', f'{1e3 * p99:.1f}'),
                  ('lag_ms', f'{1e3 * lag_s:.1f}'), ('backlog', str(backlog))]
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
