"""hac_node's intake: messages taken off DDS at once, processed in arrival order, no backlog.

The executor's thread only receives: each input message (raw bytes) goes into an :class:`Inbox`
with its arrival time (``time.monotonic``). One processing thread (:class:`Processor`) takes the
items in arrival order and hands them to the calibrator. Without drops or coalesced poses the
calibrator sees exactly the messages, in exactly the order, of the replay's feed (docs/node.md,
"What the node does with each message": Overload). These rules keep a backlog from building:

- **Joints frames** (``joints_backlog_max``, in input periods of work). When a frame arrives and
  more than ``joints_backlog_max`` frames wait, the oldest are dropped (counted by the node as
  ``frames_dropped``) unless the frames waiting can be processed within ``joints_backlog_max``
  input periods: their number times the processing time per frame (the median of the recent
  frames, the poses and CameraInfo between them included) against the mean interval between the
  recent arrivals. A node that processes slower than frames come keeps ``joints_backlog_max``
  frames waiting, as before; a burst of frames that arrived together after a stall of the
  publisher, the network or the node itself (seen at 1x on a loaded 2-core machine: seven frames
  within 1.5 ms) is processed, not dropped, since the node takes milliseconds for what the input
  took 30 ms a frame to send. Until the cost and the period are measured (a first frame
  processed, five arrived), STARTUP_FRAMES may wait.
- **Poses** are not dropped for themselves, but a stream faster than 1 / ``pose_coalesce_s`` (100 Hz
  by default) is thinned: a pose stamped within ``pose_coalesce_s`` after the last pose queued for
  the calibrator is held back, and the next pose replaces it (the held one is coalesced, counted)
  while it too is within ``pose_coalesce_s`` of the last one queued; otherwise, or when another
  input comes (a joints frame needs its poses first), or when no input comes for ``pose_coalesce_s``
  of wall time, the held pose goes into the queue. So the calibrator gets a pose at least every
  ``pose_coalesce_s`` of stamp time, the newest always, and the pose just before each joints frame;
  at camera rates (poses further apart) nothing is held or coalesced. At 1 kHz the node processes
  about 100 poses a second whatever the machine's load, so it keeps up with the stream instead of
  falling behind it (the odometry of the coalesced poses is not published: a documented difference
  from the replay, which processes every pose). Which poses are kept depends on their stamps and
  arrival order, not on how busy the processing thread is (only a pause of the input releases the
  newest pose early).

- **Maps** (``cloud_mode: replace``): a map put into the inbox supersedes the maps still waiting
  that no joints frame waits behind (the calibrator would replace each by the next before any
  frame measured against it). A node that processes slower than maps come then keeps at most one
  map per waiting joints frame, instead of a queue of indexed maps that grows without bound (seen:
  2.7 GB after an hour of stamps played at 10x on a slow machine). The map builder supersedes the
  clouds not yet built the same way (:mod:`hac_ros.ros.map_intake`).
- **Overload**: when a joints frame is dropped, what waited for it goes too. Between the joints
  frames still waiting on either side of it, only the newest supersedable map is kept, and a pose
  directly followed by another pose is coalesced (counted as above; a gap in the poses is no jump:
  the pose stream judges speeds). A node slower than its poses (seen: 300 poses a second played
  to a node that processes 250) thus keeps about one pose and one map per waiting joints frame;
  without this rule the poses, and the maps between them, queued without bound (+540 % memory
  over an accelerated hour, every frame dropped once the node was minutes behind).

CameraInfo, the maps of ``cloud_mode: accumulate`` and the transforms of ``pose_source: tf``
(``call`` items) are never dropped.
"""
from __future__ import annotations

import statistics
import struct
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hac_ros.core.basics.numeric import NS
from hac_ros.ros.liveness import LoadStats

COST_FRAMES = 31  # recent joints frames whose processing time gives the cost of a frame (median)
PERIOD_FRAMES = 30  # recent joints arrivals whose mean interval gives the input period
PERIOD_MIN_FRAMES = 5  # arrivals needed before the input period is known
# joints frames that may wait before the processing time per frame and the input period are
# known (1 s at 30 Hz): the first frames wait while the node makes its first outputs, and a
# start-up burst (seen: the first three frames before the first was processed, on a loaded
# machine) is not dropped for want of a measurement
STARTUP_FRAMES = 30
MAX_QUEUED_S = 60.0  # longer in the middleware's queue than this: a clock changed, not a wait
# the first bytes of a CDR message: its representation (little or big endian), then 2 options
CDR_ORDER = {b'\x00\x01': '<', b'\x00\x03': '<', b'\x00\x00': '>', b'\x00\x02': '>'}


def arrival_s(info: Any) -> float:
    """When the middleware received a message (time.monotonic), from rclpy's message info
    (``received_timestamp``: ns of the system clock); now when it is missing or implausible
    (more than MAX_QUEUED_S ago, or ahead)."""
    now = time.monotonic()
    received = info.get('received_timestamp', 0) if isinstance(info, dict) else 0
    if not received:
        return now
    waited = (time.time_ns() - received) / 1e9
    return now - waited if 0.0 <= waited <= MAX_QUEUED_S else now


def header_stamp_ns(data: bytes) -> int | None:
    """``header.stamp`` (ns) of the CDR bytes of a message that starts with a std_msgs/Header
    (PoseStamped, Odometry), read without deserializing; None when the bytes are too short or not
    CDR (the calibrator then judges the message as it comes)."""
    order = CDR_ORDER.get(bytes(data[:2]))
    if order is None or len(data) < 12:
        return None
    sec, nanosec = struct.unpack_from(order + 'iI', data, 4)
    return sec * NS + nanosec


@dataclass
class Item:
    """One input for the calibrator: ``kind`` (``pose``, ``joints``, ``camera_info``, ``map``, or
    ``call``: a function to run on the processing thread), its data, its arrival
    (time.monotonic), and for a pose its header stamp (ns, None when unknown)."""

    kind: str
    data: Any
    arrived_s: float
    stamp_ns: int | None = None
    supersedable: bool = False  # a map a newer one may replace (module docstring)


@dataclass
class Taken:
    """What the processing thread takes at once: the next item (None once the inbox is closed),
    the joints frames dropped and the poses coalesced since the last take, and the joints frames
    still waiting behind the item."""

    item: Item | None
    dropped: list[Item]
    coalesced: list[Item]
    waiting: int


@dataclass
class Counts:
    """A consistent snapshot of the inbox, by kind: received = processed + waiting + in hand +
    dropped (joints), coalesced (poses) or superseded (maps)."""

    received: dict[str, int]
    processed: dict[str, int]
    waiting: dict[str, int]
    in_hand: dict[str, int]
    dropped: int
    coalesced: int
    superseded: int = 0


class Inbox:
    """The items waiting for the processing thread, in arrival order (thread-safe).

    backlog_max: ``joints_backlog_max``; coalesce_s: ``pose_coalesce_s`` (module docstring).
    """

    def __init__(self, backlog_max: int, coalesce_s: float = 0.0) -> None:
        self.backlog_max = backlog_max
        self.coalesce_s = coalesce_s
        # processing time per joints frame (s, median of the recent ones; NaN before the first),
        # set by the Processor
        self.frame_cost_s = float('nan')
        self._items: deque[Item] = deque()
        self._joints = 0  # joints frames among the items
        self._ready = threading.Condition()
        self._closed = False
        self._arrivals: deque[float] = deque(maxlen=PERIOD_FRAMES)  # of joints frames
        self._kept_ns: int | None = None  # stamp of the last pose queued for the calibrator
        self._held: Item | None = None  # a pose held back, in case the next one replaces it
        self._in_hand: Item | None = None  # taken, not yet done
        self.dropped: list[Item] = []  # joints frames dropped, not yet counted by the node
        self.coalesced: list[Item] = []  # poses coalesced, not yet counted by the node
        self.received: Counter[str] = Counter()  # items put, by kind
        self.processed: Counter[str] = Counter()  # items done, by kind
        self.dropped_total = 0
        self.coalesced_total = 0
        self.superseded_total = 0  # maps (module docstring)

    def put(self, kind: str, data: Any, stamp_ns: int | None = None,
            arrived_s: float | None = None, supersede: bool = False) -> None:
        """An input arrived (``arrived_s``, time.monotonic: now by default); ``stamp_ns``: a
        pose's header stamp, for coalescing; ``supersede``: a map that replaces the maps waiting
        with no joints frame behind them, and that a newer one may replace (module docstring;
        not a map that carries a rejection to count)."""
        with self._ready:
            self.received[kind] += 1
            item = Item(kind, data, time.monotonic() if arrived_s is None else arrived_s, stamp_ns,
                        supersede)
            if kind == 'pose':
                self._pose(item)
            else:
                self._release()  # the pose held came first
                if supersede:
                    self._supersede_maps()
                self._items.append(item)
            if kind == 'joints':
                self._joints += 1
                self._arrivals.append(item.arrived_s)
                while self._joints > self.backlog_max and not self._catches_up():
                    self._drop_oldest_joints()
            self._ready.notify()

    def input_period_s(self) -> float:
        """The mean interval between the recent joints arrivals (s), NaN until known."""
        with self._ready:
            return self._period()

    def _period(self) -> float:
        n = len(self._arrivals)
        if n < PERIOD_MIN_FRAMES:
            return float('nan')
        return (self._arrivals[-1] - self._arrivals[0]) / (n - 1)

    def _catches_up(self) -> bool:
        """Whether the joints frames waiting can be processed within ``backlog_max`` input
        periods; while the cost or the period is not yet known, whether at most STARTUP_FRAMES
        wait."""
        cost, period = self.frame_cost_s, self._period()
        if cost != cost or period != period:  # NaN: not measured yet
            return self._joints <= STARTUP_FRAMES
        return self._joints * cost <= self.backlog_max * period

    def _drop_oldest_joints(self) -> None:
        for k, item in enumerate(self._items):
            if item.kind == 'joints':
                del self._items[k]
                self._joints -= 1
                self.dropped.append(item)
                self.dropped_total += 1
                self._close_gap(k)
                return

    def _close_gap(self, k: int) -> None:
        """A joints frame was dropped at position ``k``: between the joints frames waiting on
        either side of it, the supersedable maps but the newest are superseded, and a pose
        directly followed by another pose is coalesced (no frame waits between them any more;
        module docstring, "Overload")."""
        items = list(self._items)
        lo = next((i + 1 for i in range(k - 1, -1, -1) if items[i].kind == 'joints'), 0)
        hi = next((i for i in range(k, len(items)) if items[i].kind == 'joints'), len(items))
        gap = items[lo:hi]
        maps = [item for item in gap if item.supersedable]
        gap = [item for item in gap if not item.supersedable or item is maps[-1]]
        self.superseded_total += len(maps) - min(len(maps), 1)
        kept = []
        for n, item in enumerate(gap):
            if item.kind == 'pose' and n + 1 < len(gap) and gap[n + 1].kind == 'pose':
                self.coalesced.append(item)
                self.coalesced_total += 1
            else:
                kept.append(item)
        self._items = deque(items[:lo] + kept + items[hi:])

    def _supersede_maps(self) -> None:
        """Drop the supersedable maps waiting behind the last joints frame waiting (all of them,
        when none waits)."""
        kept: list[Item] = []
        while self._items and self._items[-1].kind != 'joints':
            item = self._items.pop()
            if item.supersedable:
                self.superseded_total += 1
            else:
                kept.append(item)
        self._items.extend(reversed(kept))

    def _pose(self, pose: Item) -> None:
        """A pose stamped within ``coalesce_s`` after the last pose queued is held back; the next
        pose replaces it (coalesced) while it too is within ``coalesce_s`` of that one, and
        releases it into the queue otherwise (module docstring)."""
        held = self._held
        if held is not None:
            if (self._kept_ns is not None and pose.stamp_ns is not None
                    and held.stamp_ns is not None and held.stamp_ns < pose.stamp_ns
                    and pose.stamp_ns - self._kept_ns <= self.coalesce_s * NS):
                self._held = None
                self.coalesced.append(held)
                self.coalesced_total += 1
            else:
                self._release()
        if (self.coalesce_s > 0 and self._kept_ns is not None and pose.stamp_ns is not None
                and 0 < pose.stamp_ns - self._kept_ns <= self.coalesce_s * NS):
            self._held = pose
        else:
            self._queue_pose(pose)

    def _queue_pose(self, pose: Item) -> None:
        self._items.append(pose)
        if pose.stamp_ns is not None:
            self._kept_ns = pose.stamp_ns

    def _release(self) -> None:
        """The pose held back goes into the queue (the next input is not a pose that replaces
        it, or none came within ``coalesce_s`` of wall time)."""
        if self._held is not None:
            held, self._held = self._held, None
            self._queue_pose(held)

    def get(self) -> Taken:
        """The next item and what was dropped or coalesced since the last call; blocks until
        there is an item or the inbox is closed."""
        with self._ready:
            while not self._items and not self._closed:
                if self._held is None:
                    self._ready.wait()
                elif not self._ready.wait(self.coalesce_s):  # no other input: the pose goes on
                    self._release()
            if self._closed:
                return Taken(None, [], [], 0)
            item = self._items.popleft()
            if item.kind == 'joints':
                self._joints -= 1
            self._in_hand = item
            dropped, self.dropped = self.dropped, []
            coalesced, self.coalesced = self.coalesced, []
            return Taken(item, dropped, coalesced, self._joints)

    def done(self, item: Item) -> None:
        """The processing thread is done with ``item``."""
        with self._ready:
            self.processed[item.kind] += 1
            self._in_hand = None

    def oldest_arrival_s(self) -> float | None:
        """The arrival (time.monotonic) of the oldest input not yet processed (in hand or
        waiting), None when there is none."""
        with self._ready:
            head = self._items[0] if self._items else None
            times = [i.arrived_s for i in (self._in_hand, head, self._held) if i is not None]
            return min(times, default=None)

    def counts(self) -> Counts:
        """A consistent snapshot of what the inbox received, processed, holds and left out."""
        with self._ready:
            waiting = Counter(item.kind for item in self._items)
            waiting['pose'] += self._held is not None
            waiting = +waiting  # no zero counts
            in_hand = {self._in_hand.kind: 1} if self._in_hand is not None else {}
            return Counts(dict(self.received), dict(self.processed), dict(waiting), in_hand,
                          self.dropped_total, self.coalesced_total, self.superseded_total)

    def close(self) -> None:
        with self._ready:
            self._closed = True
            self._items.clear()
            self._ready.notify_all()


class Processor:
    """The processing thread: items from ``inbox`` to ``handle`` (called holding ``lock``, the
    lock every other access to the calibrator takes), in arrival order; ``on_dropped`` for each
    joints frame the inbox dropped and ``on_coalesced`` for each pose it coalesced (both holding
    the lock). ``stats`` gets each joints frame's latency; the inbox gets the processing time per
    frame (its ``frame_cost_s``)."""

    def __init__(self, inbox: Inbox, handle: Callable[[Item], None],
                 on_dropped: Callable[[Item], None], on_coalesced: Callable[[Item], None],
                 lock: threading.RLock, stats: LoadStats) -> None:
        self.inbox, self.handle, self.lock, self.stats = inbox, handle, lock, stats
        self.on_dropped, self.on_coalesced = on_dropped, on_coalesced
        self._costs: deque[float] = deque(maxlen=COST_FRAMES)
        self._thread = threading.Thread(target=self._run, name='hac_processing', daemon=True)
        self._thread.start()

    def _run(self) -> None:
        cycle_s = 0.0  # processing time since the last joints frame
        while True:
            taken = self.inbox.get()
            item = taken.item
            if item is None:
                return
            start = time.monotonic()
            with self.lock:
                for frame in taken.dropped:
                    self.on_dropped(frame)
                for pose in taken.coalesced:
                    self.on_coalesced(pose)
                self.handle(item)
            end = time.monotonic()
            self.inbox.done(item)
            cycle_s += end - start
            if item.kind == 'joints':
                self._costs.append(cycle_s)
                cycle_s = 0.0
                self.inbox.frame_cost_s = statistics.median(self._costs)
                self.stats.frame(end - item.arrived_s, taken.waiting)

    def close(self) -> None:
        """Stop after the item being handled (those still waiting are dropped)."""
        self.inbox.close()
        if self._thread is not threading.current_thread():
            self._thread.join()
