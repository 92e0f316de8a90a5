"""``hac replay IN -o OUT``: calibrate a recording with the node's core and parameters.

The replay reads a rosbag2 recording (sqlite3 or mcap; a ROS 1 ``.bag`` too), feeds every input
message to a :class:`~hac_ros.core.calibrator.Calibrator` in log-time order with its header stamp
(SPEC, processing order) exactly as ``hac_node`` does, converts the outputs with the node's
:class:`~hac_ros.messages.OutputMessages` and writes them into OUT, each logged at its header stamp.

Modes (docs/replay.md):

- ``online``: what the node publishes, frame by frame (causal).
- ``offline`` (default): one run of the calibrator, with its metric outputs deferred
  (:mod:`hac_ros.core.metric`), keeps its accepted samples and its resets;
  :mod:`hac_ros.core.offline` turns them into a stamp -> scale schedule per segment (the median,
  or a centred rolling median where the scale drifts); the deferred outputs are then resolved with
  that schedule and written (what a second run with the schedule as
  :attr:`~hac_ros.core.calibrator.Calibrator.output_scale` would give, without reading the
  recording or indexing its maps again).

OUT is written under a temporary name beside it and renamed at the end: an error or Ctrl-C leaves
no OUT, and IN is only ever read. Besides SPEC's output topics the replay writes
``/hac/samples`` (per-frame scale samples, for ``hac plot``; see :data:`SAMPLES`).
"""
from __future__ import annotations

import argparse
import math
import os
import shutil
import sys
import tempfile
import time
from collections import Counter, deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

import numpy as np

from hac_ros.core.calibrator import Calibrator
from hac_ros.core.errors import HacError
from hac_ros.core.metric import finite_scale
from hac_ros.core.numeric import NS
from hac_ros.core.offline import OfflineScale, offline_scale
from hac_ros.core.outputs import (NoticeOut, OdometryOut, Output, ResetOut, SampleOut, Status)
from hac_ros.core.params import POSE_MSGTYPES, HacParams
from hac_ros.inputs import (IndexBuilder, MapBuilt, add_camera_info_msg, add_joints_cdr,
                            add_pose_cdr, index_cloud)
from hac_ros.messages import (OUTPUT_TOPICS, SAMPLES, Message, OutputMessages,
                              samples_message)
from msg_adapters import MessageError
from msg_adapters.cdr import RawCloud, parse_cloud_cdr

INPUT_TYPES = {'joints': 'geometry_msgs/msg/PoseArray', 'cloud': 'sensor_msgs/msg/PointCloud2',
               'camera_info': 'sensor_msgs/msg/CameraInfo'}
GT_CAMERA = ('/gt/camera_pose', 'geometry_msgs/msg/PoseStamped')
GT_JOINTS = ('/gt/human_joints', 'geometry_msgs/msg/PoseArray')
GT_SCALE = ('/gt/scale', 'std_msgs/msg/Float64')
STORAGES = ('mcap', 'sqlite3')
# Messages of the same log time are fed in this order (then any other topic): the camera's
# intrinsics and the map before the frame they serve, the pose (the clock) before its joints.
TIE_ORDER = {'camera_info': 0, 'cloud': 1, 'pose': 2, 'joints': 3}
MAPS_AHEAD = 3  # map clouds decoded and indexed ahead of the calibrator, on worker threads
MAP_WORKERS = 2  # threads indexing maps (scipy's k-d tree build releases the GIL)
# While replaying, the interpreter hands the GIL over every 0.5 ms instead of 5 ms, so that a map
# thread whose native build just finished does not wait a full interval for the calibrator's thread
# (as hac_node does; measured: ~5-10 % faster replays, docs/benchmarks.md).
GIL_SWITCH_INTERVAL_S = 0.0005
LOOKAHEAD_MESSAGES = 400  # at most this many messages read ahead of the calibrator (13 s at 30 Hz)
TUM_FILES = {'metric': 'camera_metric.tum', 'slam': 'camera_slam.tum', 'gt': 'camera_gt.tum'}


# ============================================================================ the input recording
class Recording:
    """A recording opened for reading: a rosbag2 directory, a bare .mcap/.db3 file, or a ROS 1 .bag.

    Read-only: nothing here writes to the path. Errors the user can fix raise :class:`HacError`.
    """

    def __init__(self, path: str | Path) -> None:
        from rosbags.highlevel import AnyReader

        self.path = Path(path)
        if not self.path.exists():
            raise HacError(f'input recording {self.path} does not exist')
        from rosbags.typesys import Stores, get_typestore

        try:
            self.reader = AnyReader([self.path],
                                    default_typestore=get_typestore(Stores.ROS2_JAZZY))
            self.reader.open()
        except HacError:
            raise
        except Exception as exc:  # rosbags raises several types for unreadable files
            raise HacError(f'cannot read {self.path} as a recording (rosbag2 sqlite3/mcap or ROS 1 '
                           f'bag): {_reason(exc)}') from None
        self.is_ros2 = self.reader.is2
        self.jazzy = get_typestore(Stores.ROS2_JAZZY)
        self.topics: dict[str, str | None] = {name: info.msgtype
                                              for name, info in self.reader.topics.items()}
        self.counts: dict[str, int] = {name: info.msgcount
                                       for name, info in self.reader.topics.items()}

    def close(self) -> None:
        if self.reader.stack is not None:
            self.reader.close()

    def __enter__(self) -> 'Recording':
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def describe(self) -> str:
        """What the recording holds: ``topic (type, N messages)`` for each topic."""
        if not self.topics:
            return 'no topics'
        return ', '.join(f'{t} ({self.topics[t]}, {self.counts[t]})' for t in sorted(self.topics))

    def has(self, topic: str, msgtype: str | None = None) -> bool:
        return topic in self.topics and self.counts.get(topic, 0) > 0 and (
            msgtype is None or self.topics[topic] == msgtype)

    def check_topic(self, topic: str, msgtypes: Iterable[str], what: str, hint: str = '') -> None:
        """Raise a clear error if ``topic`` is missing, empty or of another type."""
        msgtypes = list(msgtypes)
        if topic not in self.topics:
            raise HacError(f'{what} topic {topic} is not in {self.path}{hint}; the recording '
                           f'contains: {self.describe()}')
        if self.topics[topic] not in msgtypes:
            raise HacError(f'{what} topic {topic} has type {self.topics[topic]}, expected '
                           f'{" or ".join(msgtypes)}{hint}')
        if self.counts.get(topic, 0) == 0:
            raise HacError(f'{what} topic {topic} in {self.path} has no messages (empty recording?)')

    def messages(self, topics: Iterable[str]) -> Iterator[tuple[str, int, Any]]:
        """(topic, log time ns, raw bytes) of ``topics`` in log-time order."""
        wanted = set(topics)
        connections = [c for c in self.reader.connections if c.topic in wanted]
        if not connections:
            return
        try:
            for connection, log_ns, raw in self.reader.messages(connections=connections):
                yield connection.topic, log_ns, raw
        except HacError:
            raise
        except Exception as exc:  # a truncated or corrupt storage file
            raise HacError(f'{self.path} is corrupt: {_reason(exc)}') from None

    def deserialize(self, raw: Any, topic: str, log_ns: int = -1) -> Any:
        """A message of ``topic``; a ROS 1 message is converted to its ROS 2 Jazzy type first
        (``std_msgs/Header`` loses ``seq``, ``CameraInfo.K`` becomes ``k``, ...)."""
        msgtype = self.topics[topic]
        data = self.to_cdr(raw, topic, log_ns)  # raises the same HacError for a ROS 1 message
        try:
            if self.is_ros2:
                return self.reader.deserialize(data, msgtype)
            return self.jazzy.deserialize_cdr(data, msgtype)
        except Exception as exc:
            raise self._corrupt(topic, log_ns, exc) from None

    @property
    def typestore(self) -> Any:
        """The types of :meth:`to_cdr`'s bytes: the recording's own (ROS 2) or Jazzy (ROS 1)."""
        return self.reader.typestore if self.is_ros2 else self.jazzy

    def to_cdr(self, raw: Any, topic: str, log_ns: int = -1) -> Any:
        """The message bytes as ROS 2 CDR (a ROS 1 message becomes its ROS 2 Jazzy type).

        ROS 2 bytes are passed on as they are (a malformed message is then the decoder's to
        count); a ROS 1 message that does not convert raises HacError, as :meth:`deserialize`.
        """
        if self.is_ros2:
            return raw
        try:
            return self.jazzy.ros1_to_cdr(raw, self.topics[topic])
        except Exception as exc:
            raise self._corrupt(topic, log_ns, exc) from None

    def _corrupt(self, topic: str, log_ns: int, exc: BaseException) -> HacError:
        return HacError(f'{self.path} is corrupt: a {topic} message (log time {log_ns} ns) does '
                        f'not decode as {self.topics[topic]}: {_reason(exc)}')

    def read(self, topic: str) -> list[tuple[int, Any]]:
        """Every message of ``topic``, deserialized: [(log time ns, message)]."""
        return [(log_ns, self.deserialize(raw, topic, log_ns))
                for _, log_ns, raw in self.messages([topic])]


def _reason(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]


# ============================================================================ feeding the core
@dataclass
class InputTopics:
    """The input topics of one replay and their message types (SPEC: ROS 2 interface)."""

    pose: str
    pose_type: str
    joints: str
    cloud: str
    camera_info: str  # '' when off or absent from the recording

    @classmethod
    def check(cls, recording: Recording, params: HacParams) -> 'InputTopics':
        """The parameters' topics, checked against what the recording holds."""
        pose_type = POSE_MSGTYPES[params.pose_type]
        other = next(k for k, v in POSE_MSGTYPES.items() if k != params.pose_type)
        hint = ''
        if recording.topics.get(params.pose_topic) == POSE_MSGTYPES[other]:
            hint = f' (use --pose-type {other})'
        recording.check_topic(params.pose_topic, [pose_type], 'SLAM pose', hint)
        recording.check_topic(params.joints_topic, [INPUT_TYPES['joints']], 'HMR joints',
                              ' (use --joints-topic)')
        recording.check_topic(params.cloud_topic, [INPUT_TYPES['cloud']], 'map cloud',
                              ' (use --cloud-topic)')
        camera_info = params.camera_info_topic
        if camera_info and camera_info in recording.topics:
            recording.check_topic(camera_info, [INPUT_TYPES['camera_info']], 'CameraInfo')
        elif camera_info:
            camera_info = ''
        return cls(params.pose_topic, pose_type, params.joints_topic, params.cloud_topic,
                   camera_info)

    def kinds(self) -> dict[str, str]:
        """topic -> 'pose' | 'joints' | 'cloud' | 'camera_info'."""
        out = {self.pose: 'pose', self.joints: 'joints', self.cloud: 'cloud'}
        if self.camera_info:
            out[self.camera_info] = 'camera_info'
        return out


def index_after(cloud: RawCloud, build_index: IndexBuilder, previous: Future | None) -> MapBuilt:
    """:func:`hac_ros.inputs.index_cloud` on a pool thread, as ``hac_node``'s builder, with the map
    before it (the MapBuilt of ``previous``, an earlier job of the same pool: waited for) as the
    one whose overlap is computed ahead."""
    before = previous.result().index if previous is not None else None
    return index_cloud(cloud, build_index, before)


class CoreFeeder:
    """One calibrator fed from raw recording messages, the way ``hac_node`` feeds it.

    ``poses`` keeps the raw SLAM trajectory when asked (for the TUM export):
    [(stamp ns, R_wc (3, 3) camera to map, c (3,) SLAM units, map frame)]. ``map_thread=False``
    decodes and indexes maps on the calling thread (same results; for profiling).
    """

    def __init__(self, recording: Recording, topics: InputTopics, params: HacParams,
                 output_scale: Callable[[int], float] | None = None, keep_poses: bool = False,
                 map_thread: bool = True) -> None:
        self.map_thread = map_thread
        self.recording = recording
        self.topics = topics
        self.kinds = topics.kinds()
        self.params = params
        self.calibrator = Calibrator(params)
        self.calibrator.output_scale = output_scale
        self.poses: list[tuple[int, np.ndarray, np.ndarray]] | None = [] if keep_poses else None

    def run(self, on_outputs: Callable[[list[Output]], None],
            on_message: Callable[[str, int, Any], None] | None = None,
            progress: Any = None) -> None:
        """Feed every input message in log-time order, then flush. Maps are decoded and indexed
        ahead on a worker thread (they are handed to the calibrator in order, as read)."""
        pool = (ThreadPoolExecutor(max_workers=MAP_WORKERS, thread_name_prefix='hac_map') if self.map_thread
                else _InlineExecutor())
        with pool:
            for topic, log_ns, raw, item in self._lookahead(pool, on_message):
                if progress is not None:
                    progress.update(1)
                if topic is None:
                    continue
                on_outputs(self.feed(self.kinds[topic], item, log_ns))
        on_outputs(self.calibrator.flush())

    def _lookahead(self, pool: Any,
                   on_message: Callable[[str, int, Any], None] | None
                   ) -> Iterator[tuple[str | None, int, Any, Any]]:
        """Messages in order; a cloud's item is the Future of its MapBuilt, started early."""
        wanted = list(self.kinds)
        if on_message is not None:
            wanted = list(self.recording.topics)  # --copy-inputs: every topic passes through
        queue: deque[tuple[str | None, int, Any, Any]] = deque()
        maps_waiting = 0
        last_map: Future | None = None
        build_index = self.calibrator.build_index
        for topic, log_ns, raw in tie_ordered(self.recording.messages(wanted), self.kinds):
            if on_message is not None:
                on_message(topic, log_ns, raw)
            kind = self.kinds.get(topic)
            if kind is None:
                queue.append((None, log_ns, raw, None))
            elif kind == 'cloud':
                # the header here, the points on a pool thread: as hac_node (a cloud whose header
                # does not decode is rejected at its place in the order, stamp -1)
                built: Future
                try:
                    cloud = parse_cloud_cdr(self.recording.to_cdr(raw, topic, log_ns))
                except MessageError as exc:
                    built = Future()
                    built.set_result(MapBuilt(-1, None, str(exc)))
                else:
                    # what the first frame on this map will ask: its overlap with the map before
                    # it (jobs start in order: the one before is running or done, never waiting
                    # for this one). Not the floor offset: read this far ahead, the ground normal
                    # is stale by the time the map is used (the contact plane is refitted every
                    # second; measured: no offset computed ahead was ever used), so it would only
                    # be extra work.
                    built = last_map = pool.submit(index_after, cloud, build_index, last_map)
                queue.append((topic, log_ns, raw, built))
                maps_waiting += 1
            else:
                queue.append((topic, log_ns, raw, raw))
            while queue and (maps_waiting >= MAPS_AHEAD or len(queue) > LOOKAHEAD_MESSAGES):
                item = queue.popleft()
                if isinstance(item[3], Future):
                    maps_waiting -= 1
                yield item
        while queue:
            yield queue.popleft()

    def feed(self, kind: str, item: Any, log_ns: int) -> list[Output]:
        """One input message (raw bytes, or the Future of a built map) -> calibrator outputs."""
        cal = self.calibrator
        if kind == 'cloud':
            built: MapBuilt = item.result()
            if built.index is None:
                return cal.reject('cloud_malformed', built.stamp_ns)
            return cal.add_map_index(built.index)
        topic = {'pose': self.topics.pose, 'joints': self.topics.joints,
                 'camera_info': self.topics.camera_info}[kind]
        if kind == 'pose':  # poses and joints from their CDR bytes, as hac_node (hac_ros.inputs)
            outputs, pose = add_pose_cdr(cal, self.recording.to_cdr(item, topic, log_ns),
                                         self.recording.topics[topic])
            if pose is not None and self.poses is not None:
                self.poses.append((pose.stamp_ns, pose.R_wc, pose.c_map))
            return outputs
        if kind == 'joints':
            return add_joints_cdr(cal, self.recording.to_cdr(item, topic, log_ns))
        return add_camera_info_msg(cal, self.recording.deserialize(item, topic, log_ns))[0]


def tie_ordered(messages: Iterable[tuple[str, int, Any]], kinds: dict[str, str]
                ) -> Iterator[tuple[str, int, Any]]:
    """(topic, log time, raw) in log-time order, messages of equal log time in :data:`TIE_ORDER`.

    Storage formats differ in how they order messages of equal log time (a ROS 1 bag's index groups
    them by connection): a fixed order keeps the result independent of the storage. Otherwise the
    storage's order (the recorder's arrival order) is kept.
    """
    group: list[tuple[str, int, Any]] = []
    for item in messages:
        if group and item[1] != group[0][1]:
            yield from _sorted_group(group, kinds)
            group = []
        group.append(item)
    yield from _sorted_group(group, kinds)


def _sorted_group(group: list[tuple[str, int, Any]], kinds: dict[str, str]) -> list:
    if len(group) < 2:
        return group
    last = len(TIE_ORDER)
    return sorted(group, key=lambda item: TIE_ORDER.get(kinds.get(item[0], ''), last))


class _InlineExecutor:
    """``submit`` runs at once on the calling thread (CoreFeeder with ``map_thread=False``)."""

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future:
        future: Future = Future()
        future.set_result(fn(*args))
        return future

    def __enter__(self) -> '_InlineExecutor':
        return self

    def __exit__(self, *exc: Any) -> None:
        pass


# ============================================================================ the output recording
class OutputWriter:
    """Writes messages into a new rosbag2 recording, each logged at its stamp."""

    def __init__(self, path: Path, storage: str) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        self.typestore = get_typestore(Stores.ROS2_JAZZY)
        plugin = StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3
        self.writer = Writer(path, version=9, storage_plugin=plugin)
        self.writer.open()
        self._connections: dict[str, Any] = {}
        self.counts: Counter[str] = Counter()

    def connection(self, topic: str, msgtype: str, typestore: Any = None) -> Any:
        conn = self._connections.get(topic)
        if conn is None:
            conn = self.writer.add_connection(topic, msgtype, typestore=typestore or self.typestore)
            self._connections[topic] = conn
        return conn

    def write_message(self, message: Message) -> None:
        """One serialized message (CDR bytes), logged at its stamp."""
        self.write_raw(self.connection(message.topic, message.msgtype), message.stamp_ns, message.msg)

    def write_raw(self, conn: Any, stamp_ns: int, data: Any) -> None:
        self.writer.write(conn, int(stamp_ns), data)
        self.counts[conn.topic] += 1

    def close(self) -> None:
        self.writer.close()


class OutputHandler:
    """Collects what a pass needs from the calibrator's outputs and writes the messages."""

    def __init__(self, params: HacParams, writer: OutputWriter | None, printer: 'NoticePrinter',
                 keep_odometry: bool = False) -> None:
        self.messages = OutputMessages(params)
        self.writer = writer
        self.printer = printer
        self.samples: list[SampleOut] = []
        self.resets: list[ResetOut] = []
        self.odometry: list[OdometryOut] | None = [] if keep_odometry else None
        self.last_scale = math.nan

    def __call__(self, outputs: list[Output]) -> None:
        frame_samples: list[SampleOut] = []
        for output in outputs:
            if isinstance(output, NoticeOut):
                self.printer(output)
                continue
            if isinstance(output, SampleOut):
                self.samples.append(output)
                if frame_samples and frame_samples[-1].stamp_ns != output.stamp_ns:
                    self._write_samples(frame_samples)
                    frame_samples = []
                frame_samples.append(output)
                continue
            if isinstance(output, ResetOut):
                self.resets.append(output)
                continue
            if isinstance(output, OdometryOut) and self.odometry is not None:
                self.odometry.append(output)
            if self.writer is not None:
                for message in self.messages.convert(output):
                    self.writer.write_message(message)
        if frame_samples:
            self._write_samples(frame_samples)

    def _write_samples(self, samples: list[SampleOut]) -> None:
        if self.writer is not None:
            self.writer.write_message(Message(*SAMPLES, samples_message(samples),
                                              samples[0].stamp_ns))


class NoticePrinter:
    """Prints each NoticeOut once to stderr (a notice repeated with the same stamp and text is not)."""

    def __init__(self, stream: Any = None) -> None:
        self.stream = stream
        self.start_ns = 0  # stamps are printed relative to the recording's start
        self.seen: set[tuple[int, str, str]] = set()
        self.counts: Counter[str] = Counter()

    def __call__(self, notice: NoticeOut) -> None:
        key = (notice.stamp_ns, notice.cause, notice.text)
        if key in self.seen:
            return
        self.seen.add(key)
        self.counts[notice.cause] += 1
        when = f'{_seconds(notice.stamp_ns, self.start_ns)} ' if notice.stamp_ns >= 0 else ''
        line = f'hac replay: {notice.level}: {when}{notice.text}'
        _write_line(line, self.stream or sys.stderr)


def _seconds(stamp_ns: int, start_ns: int) -> str:
    """A stamp as seconds into the recording (its absolute value would be unreadable)."""
    return f't+{(stamp_ns - start_ns) / NS:.3f} s'


def _write_line(line: str, stream: Any) -> None:
    """A line on stderr that does not break an active progress bar."""
    try:
        from tqdm import tqdm

        tqdm.write(line, file=stream)
    except ImportError:  # pragma: no cover - tqdm is a dependency
        print(line, file=stream)


# ============================================================================ the replay
@dataclass
class ReplaySummary:
    """What ``hac replay`` did; printed at the end and returned to callers (tests, the demo)."""

    mode: str
    input_path: Path
    output_path: Path
    status: Status
    wall_s: float
    input_messages: int
    outputs: dict[str, int]
    resets: list[ResetOut] = field(default_factory=list)
    offline: OfflineScale | None = None
    tum: dict[str, Path] = field(default_factory=dict)
    start_ns: int = 0  # the recording's first log time: times are printed relative to it

    @property
    def frames_per_s(self) -> float:
        return self.status.frames / self.wall_s if self.wall_s > 0 else math.inf

    def text(self) -> str:
        s = self.status
        lines = [f'hac replay ({self.mode}): {self.input_path} -> {self.output_path}',
                 f'  frames {s.frames}, people {s.people}, input messages {self.input_messages}']
        if self.offline is not None:
            for k, segment in enumerate(self.offline.segments):
                lines.append(f'  segment {k} (from {_seconds(segment.start_ns, self.start_ns)}): '
                             f'{segment.describe()}')
        lines.append(f'  final scale {s.scale:.6g} m/SLAM unit, spread {s.spread:.3g} '
                     f'({s.samples} samples in the window, '
                     f'{"converged" if s.converged else "not converged"})')
        lines.append(f'  fallback rate {100 * s.fallback_rate:.1f} % (map hits {s.map_hits}, '
                     f'ground plane {s.ground_fallbacks})')
        rejected = ', '.join(f'{k} {v}' for k, v in sorted(s.rejected.items())) or 'none'
        lines.append(f'  rejected: {rejected}')
        resets = ', '.join(f'{r.cause} at {_seconds(r.stamp_ns, self.start_ns)}'
                           for r in self.resets) or 'none'
        lines.append(f'  resets {s.resets}: {resets}')
        lines.append('  written: ' + (', '.join(f'{t} {n}' for t, n in sorted(self.outputs.items()))
                                      or 'nothing'))
        for kind, path in self.tum.items():
            lines.append(f'  TUM {kind}: {path}')
        lines.append(f'  wall time {self.wall_s:.2f} s, {self.frames_per_s:.0f} frames/s')
        return '\n'.join(lines)


def replay(input_path: str | Path, output_path: str | Path, params: HacParams | None = None,
           mode: str = 'offline', storage: str = 'mcap', copy_inputs: bool = False,
           export_tum: str | Path | None = None, progress: bool | None = None,
           notices: Any = None, map_thread: bool = True) -> ReplaySummary:
    """Calibrate the recording at ``input_path`` into a new recording at ``output_path``.

    Raises :class:`HacError` (OUT exists, IN missing or unreadable, missing topics, ...). On any
    error or KeyboardInterrupt nothing is left at ``output_path``.
    """
    switch = sys.getswitchinterval()
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    try:
        return _replay(input_path, output_path, params, mode, storage, copy_inputs, export_tum,
                       progress, notices, map_thread)
    finally:
        sys.setswitchinterval(switch)


def _replay(input_path: str | Path, output_path: str | Path, params: HacParams | None, mode: str,
            storage: str, copy_inputs: bool, export_tum: str | Path | None,
            progress: bool | None, notices: Any, map_thread: bool) -> ReplaySummary:
    params = params or HacParams()
    if mode not in ('offline', 'online'):
        raise HacError(f'--mode must be offline or online, not {mode!r}')
    if storage not in STORAGES:
        raise HacError(f'--storage must be one of {", ".join(STORAGES)}, not {storage!r}')
    input_path, output_path = Path(input_path), Path(output_path)
    check_output_path(input_path, output_path)
    if progress is None:
        progress = sys.stderr.isatty()
    printer = NoticePrinter(notices)
    start = time.perf_counter()
    with Recording(input_path) as recording:
        topics = InputTopics.check(recording, params)
        start_ns = printer.start_ns = recording.reader.start_time
        if params.camera_info_topic and not topics.camera_info:
            _write_line(f'hac replay: note: no {params.camera_info_topic} in the recording: joints '
                        'are judged in view by the map cone alone', notices or sys.stderr)
        n_inputs = sum(recording.counts.get(t, 0) for t in topics.kinds())
        n_pass = sum(recording.counts.values()) if copy_inputs else n_inputs
        schedule = None
        with _staging(output_path) as staged:
            writer = OutputWriter(staged, storage)
            try:
                handler = OutputHandler(params, writer, printer, keep_odometry=export_tum is not None)
                for topic, msgtype in (*OUTPUT_TOPICS, SAMPLES):
                    if topic != '/hac/markers' or params.publish_markers:
                        writer.connection(topic, msgtype)
                feeder = CoreFeeder(recording, topics, params, keep_poses=export_tum is not None,
                                    map_thread=map_thread)
                on_message = _input_copier(recording, writer) if copy_inputs else None
                if mode == 'online':
                    with _progress(progress, n_pass, 'replay') as bar:
                        feeder.run(handler, on_message=on_message, progress=bar)
                    status = feeder.calibrator.status()
                else:
                    status, schedule = _offline(feeder, handler, on_message, progress, n_pass)
            finally:
                writer.close()
            tum: dict[str, Path] = {}
            if export_tum is not None:
                tum = write_tum_exports(Path(export_tum), handler.odometry or [], feeder.poses or [],
                                        recording)
    return ReplaySummary(mode, input_path, output_path, status, time.perf_counter() - start,
                         n_inputs, dict(writer.counts), list(handler.resets), schedule, tum,
                         start_ns)


def _offline(feeder: 'CoreFeeder', handler: 'OutputHandler',
             on_message: Callable[[str, int, Any], None] | None, progress: bool,
             n_pass: int) -> tuple[Status, OfflineScale]:
    """The offline mode: one run of the calibrator with its metric outputs deferred, the schedule
    from its accepted samples and resets, then the deferred outputs resolved with the schedule and
    written (hac_ros.core.metric: the same outputs as a second run with that schedule would give).

    Memory: the run's outputs are kept until the schedule is known (about 1.9 kB per frame of one
    person, docs/replay.md).
    """
    calibrator = feeder.calibrator
    calibrator.defer = True
    recorded: list[list[Output]] = []
    samples: list[SampleOut] = []
    resets: list[int] = []

    def record(outputs: list[Output]) -> None:
        for output in outputs:
            if isinstance(output, SampleOut):
                if output.accepted:
                    samples.append(output)
            elif isinstance(output, ResetOut):
                resets.append(output.stamp_ns)
        recorded.append(outputs)

    with _progress(progress, n_pass, 'estimate') as bar:
        feeder.run(record, on_message=on_message, progress=bar)
    p = calibrator.params
    schedule = offline_scale(np.array([s.stamp_ns for s in samples], dtype=np.int64),
                             np.array([s.scale for s in samples]), resets, p.window_s,
                             p.min_samples)
    stage = calibrator.metric.fresh()
    with _progress(progress, len(recorded), 'write') as bar:
        for outputs in recorded:
            handler(stage.resolve(outputs, schedule, schedule.error))
            if bar is not None:
                bar.update(1)
    recorded.clear()
    pending = calibrator.pending_status()
    return stage.status(pending, finite_scale(schedule(pending.status.stamp_ns))), schedule


def check_output_path(input_path: Path, output_path: Path) -> None:
    """OUT must not exist, and must not be inside IN (IN is never touched)."""
    if output_path.exists() or output_path.is_symlink():
        raise HacError(f'output {output_path} already exists (hac replay never overwrites: '
                       'remove it or choose another name)')
    if output_path.parent.exists() and not output_path.parent.is_dir():
        raise HacError(f'{output_path.parent} is not a directory')
    out, src = output_path.resolve(), input_path.resolve()
    if out == src or src in out.parents:
        raise HacError(f'output {output_path} is inside the input {input_path}')


class _staging:
    """A temporary directory beside OUT; the recording is written in it, renamed to OUT at the end.

    Missing parent directories of OUT are created. On an error or KeyboardInterrupt the temporary
    directory (and the parents it created) is removed and OUT never appears.
    """

    def __init__(self, output_path: Path) -> None:
        self.output_path = output_path
        self.tmp: Path | None = None
        self.created: list[Path] = []

    def __enter__(self) -> Path:
        parent = self.output_path.parent
        while not parent.exists():
            self.created.append(parent)
            parent = parent.parent
        self.output_path.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = Path(tempfile.mkdtemp(prefix=f'.{self.output_path.name}.', suffix='.partial',
                                         dir=self.output_path.parent))
        return self.tmp / self.output_path.name

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        assert self.tmp is not None
        done = False
        try:
            if exc_type is None:
                if self.output_path.exists():
                    raise HacError(f'output {self.output_path} appeared while replaying: not '
                                   'overwritten')
                os.rename(self.tmp / self.output_path.name, self.output_path)
                done = True
        finally:
            shutil.rmtree(self.tmp, ignore_errors=True)
            if not done:
                for directory in self.created:  # innermost first
                    try:
                        directory.rmdir()
                    except OSError:
                        break


def _input_copier(recording: Recording, writer: OutputWriter) -> Callable[[str, int, Any], None]:
    """--copy-inputs: every input topic passes into OUT unchanged, at its log time.

    A topic of IN with an output topic's name (IN is itself a replay) is not copied, nor a ROS 1
    topic whose type ROS 2 Jazzy does not have.
    """
    ours = {t for t, _ in (*OUTPUT_TOPICS, SAMPLES)}
    typestore = recording.typestore
    if not recording.is_ros2:
        ours |= {t for t, msgtype in recording.topics.items() if msgtype not in typestore.fielddefs}

    def copy(topic: str, log_ns: int, raw: Any) -> None:
        if topic in ours:
            return
        conn = writer.connection(topic, recording.topics[topic], typestore=typestore)
        writer.write_raw(conn, log_ns, recording.to_cdr(raw, topic, log_ns))
    return copy


class _progress:
    """A tqdm bar on a terminal, nothing otherwise."""

    def __init__(self, enabled: bool, total: int, desc: str) -> None:
        self.enabled, self.total, self.desc = enabled, total, desc
        self.bar: Any = None

    def __enter__(self) -> Any:
        if not self.enabled:
            return None
        from tqdm import tqdm

        self.bar = tqdm(total=self.total, desc=self.desc, unit='msg', file=sys.stderr,
                        dynamic_ncols=True, leave=False, mininterval=0.2)
        return self.bar

    def __exit__(self, *exc: Any) -> None:
        if self.bar is not None:
            self.bar.close()


# ============================================================================ TUM export
def write_tum_exports(directory: Path, odometry: list[OdometryOut],
                      poses: list[tuple[int, np.ndarray, np.ndarray]],
                      recording: Recording) -> dict[str, Path]:
    """camera_metric.tum (the metric odometry), camera_slam.tum (the raw SLAM poses, SLAM units)
    and, when the recording has it, camera_gt.tum (/gt/camera_pose, metres): TUM files for evo."""
    from hac_ros.tum import rotations_to_quats, write_tum

    directory.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}

    def export(kind: str, stamps: list[int], rotations: list[np.ndarray],
               positions: list[np.ndarray]) -> None:
        if not stamps:
            return
        path = directory / TUM_FILES[kind]
        write_tum(path, np.asarray(stamps, dtype=np.int64), np.asarray(positions, dtype=float),
                  rotations_to_quats(np.asarray(rotations, dtype=float)))
        written[kind] = path

    export('metric', [o.stamp_ns for o in odometry], [o.rotation_metric for o in odometry],
           [o.position_metric for o in odometry])
    export('slam', [p[0] for p in poses], [p[1] for p in poses], [p[2] for p in poses])
    gt = read_gt_camera(recording)
    if gt is not None:
        export('gt', list(gt[0]), list(gt[1]), list(gt[2]))
    return written


def read_gt_camera(recording: Recording) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """/gt/camera_pose: stamps (T,) ns, R (T, 3, 3) camera to world, centres (T, 3) metres; or None."""
    from msg_adapters import pose_msg_to_rt, stamp_to_ns

    if not recording.has(*GT_CAMERA):
        return None
    stamps, rotations, centres = [], [], []
    for _, msg in recording.read(GT_CAMERA[0]):
        R, c = pose_msg_to_rt(msg)
        stamps.append(stamp_to_ns(msg.header.stamp))
        rotations.append(R)
        centres.append(c)
    return np.asarray(stamps, dtype=np.int64), np.asarray(rotations), np.asarray(centres)


# ============================================================================ command line
def load_params(params_file: str | None, overrides: dict[str, Any]) -> HacParams:
    """The node's parameters file (``hac_node: ros__parameters:``), then the command-line flags."""
    params = HacParams.from_yaml(params_file) if params_file else HacParams()
    changes = {k: v for k, v in overrides.items() if v is not None}
    return params.replace(**changes) if changes else params


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('input', metavar='IN', help='input recording (rosbag2 directory, .mcap, '
                        '.db3, or ROS 1 .bag); only read')
    parser.add_argument('-o', '--output', metavar='OUT', required=True,
                        help='output recording to create (must not exist)')
    parser.add_argument('--mode', choices=('offline', 'online'), default='offline',
                        help='offline (default): the best estimate using the whole recording; '
                        'online: exactly what hac_node publishes, frame by frame')
    parser.add_argument('--params', metavar='FILE',
                        help='the node\'s parameters file (hac_node: ros__parameters:)')
    parser.add_argument('--storage', choices=STORAGES, default='mcap',
                        help='storage plugin of OUT (default mcap)')
    parser.add_argument('--pose-topic', help='overrides pose_topic')
    parser.add_argument('--cloud-topic', help='overrides cloud_topic')
    parser.add_argument('--joints-topic', help='overrides joints_topic')
    parser.add_argument('--camera-info-topic', help='overrides camera_info_topic ("" = off)')
    parser.add_argument('--pose-type', choices=tuple(POSE_MSGTYPES), help='overrides pose_type')
    parser.add_argument('--copy-inputs', action='store_true',
                        help='also copy every topic of IN into OUT (so OUT alone can be evaluated)')
    parser.add_argument('--export-tum', metavar='DIR',
                        help='write camera_metric.tum, camera_slam.tum and camera_gt.tum (when the '
                        'recording has ground truth) into DIR, for evo')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')


def run(args: argparse.Namespace) -> int:
    params = load_params(args.params, {
        'pose_topic': args.pose_topic, 'cloud_topic': args.cloud_topic,
        'joints_topic': args.joints_topic, 'camera_info_topic': args.camera_info_topic,
        'pose_type': args.pose_type})
    summary = replay(args.input, args.output, params, mode=args.mode, storage=args.storage,
                     copy_inputs=args.copy_inputs, export_tum=args.export_tum,
                     progress=False if args.no_progress else None)
    print(summary.text())
    return 0
