"""The replay: a recording's inputs through the node's core, its outputs into a new recording.

:func:`replay` reads a recording (:mod:`hac_ros.recording`), feeds every input message to a
:class:`~hac_ros.core.calibrator.Calibrator` in log-time order with its header stamp (SPEC,
processing order), exactly as ``hac_node`` does (:mod:`hac_ros.inputs`: the same decoders and the
same map builder), converts the outputs with the node's :class:`~hac_ros.messages.OutputMessages`
and writes them, each logged at its header stamp.

Modes (docs/replay.md):

- ``online``: what the node publishes, frame by frame (causal).
- ``offline`` (default): one run of the calibrator with its metric outputs deferred
  (:mod:`hac_ros.core.metric`) keeps its accepted samples and its resets;
  :mod:`hac_ros.core.offline` turns them into a stamp -> scale schedule per segment (the median,
  or a centred rolling median where the scale drifts); the deferred outputs are then resolved with
  that schedule and written (what a second run with that schedule would publish, without reading
  the recording or indexing its maps again).

OUT appears atomically (:class:`~hac_ros.recording.staged_output`) and IN is only ever read. Besides
SPEC's output topics the replay writes ``/hac/samples`` (per-frame scale samples, for
``hac plot``; see :data:`~hac_ros.messages.SAMPLES`).
"""
from __future__ import annotations

import math
import sys
import time
from collections import Counter, deque
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

import numpy as np

from hac_ros.core.calibrator import Calibrator
from hac_ros.core.errors import HacError
from hac_ros.core.humans import smooth_outputs
from hac_ros.core.metric import finite_scale
from hac_ros.core.numeric import NS
from hac_ros.core.offline import OfflineScale, offline_scale
from hac_ros.core.outputs import NoticeOut, OdometryOut, Output, ResetOut, SampleOut, Status
from hac_ros.core.params import POSE_MSGTYPES, HacParams
from hac_ros.inputs import (MapBuilder, MapBuilt, add_camera_info_msg, add_joints_msg,
                            add_pose_msg)
from hac_ros.messages import OUTPUT_TOPICS, SAMPLES, Message, OutputMessages, samples_message
from hac_ros.recording import (STORAGES, OutputWriter, Recording, check_output_path,
                               staged_output)
from msg_adapters import MessageError, parse_cloud_cdr

INPUT_TYPES = {'joints': 'geometry_msgs/msg/PoseArray', 'cloud': 'sensor_msgs/msg/PointCloud2',
               'camera_info': 'sensor_msgs/msg/CameraInfo'}
MODES = ('offline', 'online')
# Messages of the same log time are fed in this order (then any other topic): the camera's
# intrinsics and the map before the frame they serve, the pose (the clock) before its joints.
TIE_ORDER = {'camera_info': 0, 'cloud': 1, 'pose': 2, 'joints': 3}
MAPS_AHEAD = 3  # map clouds decoded and indexed ahead of the calibrator
MAP_WORKERS = 2  # threads indexing maps (scipy's k-d tree build releases the GIL)
LOOKAHEAD_MESSAGES = 400  # at most this many messages read ahead of the calibrator (13 s at 30 Hz)


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
    def check(cls, recording: Recording, params: HacParams,
              pose_type: str | None = None) -> 'InputTopics':
        """The parameters' topics, checked against what the recording holds.

        The SLAM pose type is the recording's own (SPEC: PoseStamped or Odometry, so recordings of
        both kinds replay without flags) unless ``pose_type`` (``--pose-type``) overrides it; the
        parameters' ``pose_type`` (the node's subscription type) only names the type expected of a
        pose topic that is neither.
        """
        recorded = recording.topics.get(params.pose_topic)
        if pose_type is None:
            pose_type = next((k for k, v in POSE_MSGTYPES.items() if v == recorded),
                             params.pose_type)
        elif pose_type not in POSE_MSGTYPES:
            raise HacError(f'--pose-type must be one of {", ".join(POSE_MSGTYPES)}, '
                           f'not {pose_type!r}')
        other = next(k for k in POSE_MSGTYPES if k != pose_type)
        hint = ''
        if recorded == POSE_MSGTYPES[other]:
            hint = f' (use --pose-type {other}, or no --pose-type: it is read from the recording)'
        recording.check_topic(params.pose_topic, [POSE_MSGTYPES[pose_type]], 'SLAM pose', hint)
        recording.check_topic(params.joints_topic, [INPUT_TYPES['joints']], 'HMR joints',
                              ' (use --joints-topic)')
        recording.check_topic(params.cloud_topic, [INPUT_TYPES['cloud']], 'map cloud',
                              ' (use --cloud-topic)')
        camera_info = params.camera_info_topic
        if camera_info and camera_info in recording.topics:
            recording.check_topic(camera_info, [INPUT_TYPES['camera_info']], 'CameraInfo')
        elif camera_info:
            camera_info = ''
        return cls(params.pose_topic, POSE_MSGTYPES[pose_type], params.joints_topic,
                   params.cloud_topic, camera_info)

    def kinds(self) -> dict[str, str]:
        """topic -> 'pose' | 'joints' | 'cloud' | 'camera_info'."""
        out = {self.pose: 'pose', self.joints: 'joints', self.cloud: 'cloud'}
        if self.camera_info:
            out[self.camera_info] = 'camera_info'
        return out


class CoreFeeder:
    """Feeds a recording's input messages to one calibrator, the way ``hac_node`` feeds it.

    ``poses`` keeps the raw SLAM trajectory when asked (for the TUM export):
    [(stamp ns, R_wc (3, 3) camera to map, c (3,) SLAM units, map frame)].
    """

    def __init__(self, recording: Recording, topics: InputTopics, calibrator: Calibrator,
                 keep_poses: bool = False) -> None:
        self.recording = recording
        self.topics = topics
        self.kinds = topics.kinds()
        self.calibrator = calibrator
        self.poses: list[tuple[int, np.ndarray, np.ndarray]] | None = [] if keep_poses else None

    def run(self, on_outputs: Callable[[list[Output]], None],
            on_message: Callable[[str, int, Any], None] | None = None,
            progress: Any = None) -> None:
        """Feed every input message in log-time order, then flush. Map clouds are decoded and
        indexed ahead on the map builder's threads and handed over in order, at their place."""
        builder = MapBuilder(self.calibrator.build_index, workers=MAP_WORKERS)
        try:
            for topic, log_ns, item in self._lookahead(builder, on_message):
                if progress is not None:
                    progress.update(1)
                if topic is not None:
                    on_outputs(self.feed(self.kinds[topic], item, log_ns))
        finally:
            builder.close()
        on_outputs(self.calibrator.flush())

    def _lookahead(self, builder: MapBuilder, on_message: Callable[[str, int, Any], None] | None
                   ) -> Iterator[tuple[str | None, int, Any]]:
        """(topic, log time, item) in order: raw bytes, or the Future of a cloud's MapBuilt
        (submitted to the builder up to MAPS_AHEAD clouds ahead); topic None for a message that
        is only copied (``on_message``)."""
        wanted = list(self.recording.topics) if on_message is not None else list(self.kinds)
        queue: deque[tuple[str | None, int, Any]] = deque()
        maps_waiting = 0
        for topic, log_ns, raw in tie_ordered(self.recording.messages(wanted), self.kinds):
            if on_message is not None:
                on_message(topic, log_ns, raw)
            kind = self.kinds.get(topic)
            if kind == 'cloud':
                queue.append((topic, log_ns, self._submit(builder, topic, log_ns, raw)))
                maps_waiting += 1
            else:
                queue.append((topic if kind else None, log_ns, raw))
            while queue and (maps_waiting >= MAPS_AHEAD or len(queue) > LOOKAHEAD_MESSAGES):
                item = queue.popleft()
                maps_waiting -= isinstance(item[2], Future)
                yield item
        yield from queue

    def _submit(self, builder: MapBuilder, topic: str, log_ns: int, raw: Any) -> Future:
        """The header read here, the points decoded and indexed on the builder (as hac_node); a
        cloud whose header does not decode is rejected at its place in the order (stamp −1)."""
        try:
            cloud = parse_cloud_cdr(self.recording.to_cdr(raw, topic, log_ns))
        except MessageError as exc:
            failed: Future = Future()
            failed.set_result(MapBuilt(-1, None, str(exc)))
            return failed
        return builder.submit(cloud)

    def feed(self, kind: str, item: Any, log_ns: int) -> list[Output]:
        """One input message (raw bytes, or the Future of a built map) -> calibrator outputs."""
        cal = self.calibrator
        if kind == 'cloud':
            return item.result().hand_to(cal)
        topic = {'pose': self.topics.pose, 'joints': self.topics.joints,
                 'camera_info': self.topics.camera_info}[kind]
        # malformed bytes (msg None) are a counted rejection of their kind, as in the node
        msg = self.recording.deserialize_or_none(self.recording.to_cdr(item, topic, log_ns), topic)
        if kind == 'pose':
            outputs, pose = add_pose_msg(cal, msg)
            if pose is not None and self.poses is not None:
                self.poses.append(pose)
            return outputs
        if kind == 'joints':
            return add_joints_msg(cal, msg)
        if msg is None:
            return cal.reject('camera_info_invalid', -1)
        return add_camera_info_msg(cal, msg)[0]


def tie_ordered(messages: Iterable[tuple[str, int, Any]], kinds: dict[str, str]
                ) -> Iterator[tuple[str, int, Any]]:
    """(topic, log time, raw) in log-time order, messages of equal log time in :data:`TIE_ORDER`.

    Storage formats differ in how they order messages of equal log time (a ROS 1 bag's index groups
    them by connection): a fixed order keeps the result independent of the storage. Otherwise the
    storage's order (the recorder's arrival order) is kept.
    """
    last = len(TIE_ORDER)
    group: list[tuple[str, int, Any]] = []
    for item in messages:
        if group and item[1] != group[0][1]:
            yield from sorted(group, key=lambda m: TIE_ORDER.get(kinds.get(m[0], ''), last))
            group = []
        group.append(item)
    yield from sorted(group, key=lambda m: TIE_ORDER.get(kinds.get(m[0], ''), last))


def deferred_run(recording: Recording, params: HacParams) -> tuple[Calibrator, list[Output]]:
    """One run of the calibrator over ``recording`` with its metric outputs deferred: the
    calibrator and every output in order, to be resolved with any scale schedule
    (``calibrator.metric.fresh().resolve(outputs, scale_at)``; :mod:`hac_ros.core.metric`)."""
    calibrator = Calibrator(params, defer_metric=True)
    outputs: list[Output] = []
    CoreFeeder(recording, InputTopics.check(recording, params), calibrator).run(outputs.extend)
    return calibrator, outputs


# ============================================================================ writing outputs
class OutputHandler:
    """Writes the messages of the calibrator's outputs and keeps what the summary needs."""

    def __init__(self, params: HacParams, writer: OutputWriter | None, printer: 'NoticePrinter',
                 keep_odometry: bool = False) -> None:
        self.messages = OutputMessages(params)
        self.writer = writer
        self.printer = printer
        self.resets: list[ResetOut] = []
        self.odometry: list[OdometryOut] | None = [] if keep_odometry else None

    def __call__(self, outputs: list[Output]) -> None:
        frame_samples: list[SampleOut] = []
        for output in outputs:
            if isinstance(output, NoticeOut):
                self.printer(output)
                continue
            if isinstance(output, SampleOut):
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
            for message in self.messages.convert(output):
                self._write(message)
        if frame_samples:
            self._write_samples(frame_samples)

    def _write(self, message: Message) -> None:
        if self.writer is not None:
            self.writer.write(message.topic, message.msgtype, message.stamp_ns, message.msg)

    def _write_samples(self, samples: list[SampleOut]) -> None:
        self._write(Message(*SAMPLES, samples_message(samples), samples[0].stamp_ns))


class NoticePrinter:
    """Prints each NoticeOut once to stderr (a notice repeated with the same stamp and text is not)."""

    def __init__(self, stream: Any = None, start_ns: int = 0) -> None:
        self.stream = stream
        self.start_ns = start_ns  # stamps are printed relative to the recording's start
        self.seen: set[tuple[int, str, str]] = set()
        self.counts: Counter[str] = Counter()

    def __call__(self, notice: NoticeOut) -> None:
        key = (notice.stamp_ns, notice.cause, notice.text)
        if key in self.seen:
            return
        self.seen.add(key)
        self.counts[notice.cause] += 1
        when = f'{_seconds(notice.stamp_ns, self.start_ns)} ' if notice.stamp_ns >= 0 else ''
        self.line(f'hac replay: {notice.level}: {when}{notice.text}')

    def line(self, text: str) -> None:
        """A line on the stream that does not break an active progress bar."""
        from tqdm import tqdm

        tqdm.write(text, file=self.stream or sys.stderr)


def _seconds(stamp_ns: int, start_ns: int) -> str:
    """A stamp as seconds into the recording (its absolute value would be unreadable)."""
    return f't+{(stamp_ns - start_ns) / NS:.3f} s'


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
           notices: Any = None, pose_type: str | None = None) -> ReplaySummary:
    """Calibrate the recording at ``input_path`` into a new recording at ``output_path``.

    mode: ``offline`` or ``online`` (module docstring); storage: of OUT, ``mcap`` or ``sqlite3``;
    copy_inputs: every topic of IN is copied into OUT too; export_tum: a directory for TUM files
    (:func:`hac_ros.tum.write_tum_exports`); progress: a bar on stderr (default: when it is a
    terminal); notices: the stream notices are printed on (default stderr); pose_type:
    ``PoseStamped`` or ``Odometry`` overrides the SLAM pose type read from IN (``--pose-type``).
    Raises :class:`HacError` (OUT exists, IN missing or unreadable, missing topics, ...). On any
    error or KeyboardInterrupt nothing is left at ``output_path``.
    """
    from hac_ros.tum import write_tum_exports

    params = params or HacParams()
    if mode not in MODES:
        raise HacError(f'--mode must be offline or online, not {mode!r}')
    if storage not in STORAGES:
        raise HacError(f'--storage must be one of {", ".join(STORAGES)}, not {storage!r}')
    input_path, output_path = Path(input_path), Path(output_path)
    check_output_path(input_path, output_path)
    if progress is None:
        progress = sys.stderr.isatty()
    start = time.perf_counter()
    with Recording(input_path) as recording:
        topics = InputTopics.check(recording, params, pose_type)
        start_ns = recording.start_ns
        printer = NoticePrinter(notices, start_ns)
        if params.camera_info_topic and not topics.camera_info:
            printer.line(f'hac replay: note: no {params.camera_info_topic} in the recording: '
                         'joints are judged in view by the map cone alone')
        n_inputs = sum(recording.counts.get(t, 0) for t in topics.kinds())
        n_pass = sum(recording.counts.values()) if copy_inputs else n_inputs
        schedule = None
        with staged_output(output_path) as staged:
            writer = OutputWriter(staged, storage)
            try:
                handler = OutputHandler(params, writer, printer, keep_odometry=export_tum is not None)
                for topic, msgtype in (*OUTPUT_TOPICS, SAMPLES):
                    if topic != '/hac/markers' or params.publish_markers:
                        writer.connection(topic, msgtype)
                feeder = CoreFeeder(recording, topics,
                                    Calibrator(params, defer_metric=mode == 'offline'),
                                    keep_poses=export_tum is not None)
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


def _offline(feeder: CoreFeeder, handler: OutputHandler,
             on_message: Callable[[str, int, Any], None] | None, progress: bool,
             n_pass: int) -> tuple[Status, OfflineScale]:
    """The offline mode: one run of the calibrator with its metric outputs deferred, the schedule
    from its accepted samples and resets, then the deferred outputs resolved with the schedule and
    written (hac_ros.core.metric: the same outputs as a second run with that schedule would give).

    Memory: the run's outputs are kept until the schedule is known (about 1.9 kB per frame of one
    person, docs/replay.md).
    """
    calibrator = feeder.calibrator
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
    resolved = [stage.resolve(outputs, schedule, schedule.error) for outputs in recorded]
    recorded.clear()
    if p.human_filter == 'smooth':
        smooth_outputs([o for outputs in resolved for o in outputs])
    with _progress(progress, len(resolved), 'write') as bar:
        for outputs in resolved:
            handler(outputs)
            if bar is not None:
                bar.update(1)
    pending = calibrator.pending_status()
    return stage.status(pending, finite_scale(schedule(pending.status.stamp_ns))), schedule


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
