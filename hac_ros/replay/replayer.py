"""The replay: a recording's inputs through the node's core, its outputs into a new recording.

:func:`replay` reads a recording (:mod:`hac_ros.recording`), feeds every input message to a
:class:`~hac_ros.core.calibrator.Calibrator` as ``hac_node`` does (:mod:`hac_ros.replay.feeder`),
converts the outputs with the node's :class:`~hac_ros.bridge.messages.OutputMessages` and writes
them, each logged at its header stamp.

Modes (docs/replay.md):

- ``online``: what the node publishes, frame by frame (causal).
- ``offline`` (default): one run of the calibrator with its metric outputs deferred
  (:mod:`hac_ros.core.stream.metric_stage`) keeps its accepted samples and its resets;
  :mod:`hac_ros.core.offline` turns them into a stamp -> scale schedule per segment (the median,
  or the smoothed scale where the samples give evidence of drift); the deferred outputs are then
  resolved with
  that schedule and written (what a second run with that schedule would publish, without reading
  the recording or indexing its maps again).

OUT appears atomically (:class:`~hac_ros.recording.atomic.staged_output`) and IN is only ever read.
Besides the node's output topics the replay writes ``/hac/samples`` (per-frame scale samples, for
``hac plot``; see :data:`~hac_ros.bridge.messages.SAMPLES`).
"""
from __future__ import annotations

import logging
import math
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hac_ros.bridge.messages import Message, OutputMessages, samples_message
from hac_ros.bridge.topics import SAMPLES, TOPICS, in_root
from hac_ros.core.basics.errors import ArgumentError
from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import (
    DiagnosticsOut,
    NoticeOut,
    Output,
    PoseOut,
    ResetOut,
    SampleOut,
    ScaleOut,
    Status,
)
from hac_ros.core.basics.printable import printable
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.estimate.segment import SegmentScale, drift_text
from hac_ros.core.offline import OfflineScale, resolve_offline
from hac_ros.core.rules.params import HacParams
from hac_ros.core.rules.reasons import refusals_behind
from hac_ros.core.rules.reasons import text as reason_text
from hac_ros.core.rules.status_shares import StatusShares
from hac_ros.files.tum import write_tum_exports
from hac_ros.progress import Progress, ProgressBar, progress_pass
from hac_ros.recording.atomic import staged_output
from hac_ros.recording.reader import STORAGES, Recording, layout_data
from hac_ros.recording.writer import OutputWriter, check_output_path
from hac_ros.replay.feeder import CoreFeeder, InputTopics

MODES = ('offline', 'online')
NOTICE_LEVELS = {'info': logging.INFO, 'warn': logging.WARNING, 'error': logging.ERROR}

log = logging.getLogger(__name__)
PROGRESS_EVERY = 4096  # outputs written between two updates of the offline mode's 'write' bar


# ============================================================================ writing outputs
class OutputHandler:
    """Writes the messages of the calibrator's outputs and keeps what the summary needs."""

    def __init__(self, params: HacParams, writer: OutputWriter | None, notices: NoticeLog,
                 keep_poses: bool = False) -> None:
        self.messages = OutputMessages(params)
        self.writer = writer
        self.notices = notices
        self.resets: list[ResetOut] = []
        self.poses: list[PoseOut] | None = [] if keep_poses else None  # /hac/pose, for TUM
        self.last_scale: ScaleOut | None = None  # the last /hac/scale written
        self.statuses = StatusShares()  # what the /diagnostics written said
        self.max_samples = 0  # the most samples in the estimator's window, by its statuses

    def __call__(self, outputs: list[Output], progress: ProgressBar | None = None) -> None:
        """Write the messages of ``outputs``; ``progress``: a bar advanced as they are written."""
        frame_samples: list[SampleOut] = []
        for count, output in enumerate(outputs, 1):
            if progress is not None and count % PROGRESS_EVERY == 0:
                progress.update(PROGRESS_EVERY)
            if isinstance(output, NoticeOut):
                self.notices(output)
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
            if isinstance(output, PoseOut) and self.poses is not None:
                self.poses.append(output)
            if isinstance(output, ScaleOut):
                self.last_scale = output
            for message in self.messages.convert(output):
                self._write(message)
            if isinstance(output, DiagnosticsOut) and self.messages.last_health is not None:
                health = self.messages.last_health
                self.statuses.add(health.level, health.reasons)
                self.max_samples = max(self.max_samples, output.status.samples)
        if frame_samples:
            self._write_samples(frame_samples)
        if progress is not None:
            progress.update(len(outputs) % PROGRESS_EVERY)

    def _write(self, message: Message) -> None:
        if self.writer is not None:
            self.writer.write(in_root(message.topic), message.msgtype, message.stamp_ns,
                              message.msg)

    def _write_samples(self, samples: list[SampleOut]) -> None:
        self._write(Message(*SAMPLES.pair, samples_message(samples), samples[0].stamp_ns))


class NoticeLog:
    """Logs each NoticeOut once, at its level (a notice repeated with the same stamp and text, as
    the offline mode's second pass repeats them, is not)."""

    def __init__(self, start_ns: int = 0) -> None:
        self.start_ns = start_ns  # stamps are logged relative to the recording's start
        self.seen: set[tuple[int, str, str]] = set()
        self.counts: Counter[str] = Counter()

    def __call__(self, notice: NoticeOut) -> None:
        key = (notice.stamp_ns, notice.cause, notice.text)
        if key in self.seen:
            return
        self.seen.add(key)
        self.counts[notice.cause] += 1
        when = f'{_seconds(notice.stamp_ns, self.start_ns)} ' if notice.stamp_ns >= 0 else ''
        log.log(NOTICE_LEVELS.get(notice.level, logging.WARNING), '%s%s', when, notice.text)


def segment_text(segment: SegmentScale, min_samples: int) -> str:
    """An offline segment for the summary: its samples (few: fewer than ``min_samples``), its
    scale and that scale's standard error, its shape, and the drift test's probability (never
    rounded up to 1: docs/replay.md, "The two modes")."""
    if not math.isfinite(segment.median):
        return f'{segment.samples} samples: too few (at least 3), no estimate'
    few = f' (few samples: fewer than min_samples {min_samples})' if segment.few else ''
    kind = 'constant: median'
    if segment.drift:
        lo, hi = float(np.min(segment.knots_scale)), float(np.max(segment.knots_scale))
        kind = (f'{"following its shape" if segment.shape else "drifting: smoothed"} '
                f'{lo:.6g} .. {hi:.6g}')
    return (f'{segment.samples} samples{few}, median {segment.median:.6g} +- '
            f'{segment.error:.2g}, {kind} (drift test: drift probability '
            f'{drift_text(segment.drift_probability)})')


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
    last_scale: ScaleOut | None = None  # the last /hac/scale written (None: none was)
    statuses: StatusShares = field(default_factory=StatusShares)  # the /diagnostics written
    params: HacParams = field(default_factory=HacParams)  # the replay's parameters
    max_samples: int = 0  # the most samples the estimator's window held (its statuses)
    stamps_apart_s: float | None = None  # joints minus poses, s, when they never met (core)

    @property
    def final_scale(self) -> float | None:
        """The last scale written to /hac/scale, metres per SLAM unit (None: nothing was
        calibrated). The summary, ``hac batch`` and ``hac eval`` all report this one."""
        return None if self.last_scale is None else self.last_scale.scale

    @property
    def calibrated(self) -> bool:
        return self.last_scale is not None

    def why_not_calibrated(self) -> str:
        """One line: why no scale was written, naming what kept the estimate from converging
        (:meth:`what_kept_it`)."""
        return (f'nothing calibrated: no /hac/scale written ({self.status.frames} frames, at most '
                f'{self.max_samples} samples in the window): {self.what_kept_it()}')

    def what_kept_it(self) -> str:
        """What kept the estimate from converging, the first that applies: no frame found its
        SLAM pose (the joints and poses stamped apart, when they were), no frame gave a sample
        (the reason most of them were refused), ``min_samples`` out of reach (beyond
        ``window_max_samples``, or more than the window ever held), else the estimator's test."""
        s, p = self.status, self.params
        if s.frames == 0:
            apart = self.stamps_apart_s
            if apart is not None:
                return (f'joints and SLAM poses never came within reach of each other: the joints '
                        f'are stamped {abs(apart):.6g} s {"after" if apart > 0 else "before"} the '
                        'poses (different clocks?)')
            return 'no joints frame found its SLAM pose' + self._rejected_most()
        if self.max_samples == 0:
            return 'no frame gave a scale sample' + self._rejected_most()
        if self.max_samples < p.min_samples:
            if p.min_samples > p.window_max_samples:
                return (f'min_samples {p.min_samples} can never be reached: the window holds at '
                        f'most window_max_samples {p.window_max_samples} samples')
            return (f'min_samples {p.min_samples} was never reached: the window of window_s '
                    f'{p.window_s:g} s held at most {self.max_samples} samples')
        return (f'the estimate never passed its convergence test although the window held '
                f'{self.max_samples} samples (min_samples {p.min_samples})')

    def _rejected_most(self) -> str:
        """``; rejected most: no_map 901 (its text)``, and the refusals of the input it waited
        for (``; the maps were refused: cloud_wrong_frame 15 (...)``), or '' when nothing was
        rejected."""
        if not self.status.rejected:
            return ''
        reason, count = max(self.status.rejected.items(), key=lambda item: item[1])
        behind = refusals_behind(reason, self.status.rejected)
        return (f'; rejected most: {reason} {count} ({reason_text(reason)})'
                + (f'; {behind}' if behind else ''))

    @property
    def frames_per_s(self) -> float:
        return self.status.frames / self.wall_s if self.wall_s > 0 else math.inf

    def text(self) -> str:
        s = self.status
        lines = [f'hac replay ({self.mode}): {self.input_path} -> {self.output_path}',
                 f'  frames {s.frames}, people {s.people}, input messages {self.input_messages}']
        if self.offline is not None:
            for k, segment in enumerate(self.offline.segments):
                start = ('the start' if segment.start_ns < self.start_ns
                         else _seconds(segment.start_ns, self.start_ns))
                lines.append(f'  segment {k} (from {start}): '
                             f'{segment_text(segment, self.params.min_samples)}')
        if self.last_scale is None:
            lines.append(f'  final scale: none ({self.why_not_calibrated()})')
        else:
            lines.append(f'  final scale {self.last_scale.scale:.6g} m/SLAM unit, spread '
                         f'{self.last_scale.spread:.3g} (the last /hac/scale written)')
        lines.append(f'  statuses ({self.statuses.total} /diagnostics, one per second): '
                     f'{self.statuses.text()}')
        lines.append(f'  estimator at the end: {s.samples} samples in the window, '
                     f'{"converged" if s.converged else "not converged"}, status '
                     f'{self.statuses.last_text()}')
        lines.append(f'  fallback rate {100 * s.fallback_rate:.1f} % (map hits {s.map_hits}, '
                     f'ground plane {s.ground_fallbacks})')
        if s.pose_matches:
            lines.append('  frames matched to a SLAM pose: ' + ', '.join(
                f'{case} {n}' for case, n in sorted(s.pose_matches.items())))
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
           export_tum: str | Path | None = None, progress: Progress | None = None,
           pose_type: str | None = None) -> ReplaySummary:
    """Calibrate the recording at ``input_path`` into a new recording at ``output_path``.

    mode: ``offline`` or ``online`` (module docstring); storage: of OUT, ``mcap`` or ``sqlite3``;
    copy_inputs: every topic of IN is copied into OUT too; export_tum: a directory for TUM files
    (:func:`hac_ros.files.tum.write_tum_exports`); progress: a progress display to advance per
    message (:data:`~hac_ros.progress.Progress`; default none: the library draws nothing);
    pose_type: ``PoseStamped`` or ``Odometry`` overrides the SLAM pose type read from
    IN. The calibrator's notices are logged (this module's logger), each once.
    Raises :class:`HacError` (OUT exists, IN missing or unreadable, ...; :class:`ArgumentError`
    naming the argument or parameter: an invalid mode, missing topics, ...). On any error or
    KeyboardInterrupt nothing is left at ``output_path``.
    """
    params = params or HacParams()
    if mode not in MODES:
        raise ArgumentError(f'{{mode}} must be offline or online, not {mode!r}', 'mode')
    if storage not in STORAGES:
        raise ArgumentError(f'{{storage}} must be one of {", ".join(STORAGES)}, not {storage!r}',
                            'storage')
    input_path, output_path = Path(input_path), Path(output_path)
    check_output_path(input_path, output_path)
    start = time.perf_counter()
    with Recording(input_path) as recording:
        topics = InputTopics.check(recording, params, pose_type)
        start_ns = recording.start_ns
        notices = NoticeLog(start_ns)
        for topic in (topics.pose, topics.joints, topics.cloud):
            publishers = recording.publishers(topic) if topic else 0
            if publishers > 1:
                log.warning('the recording says %d publishers offered %s: their messages '
                            'interleave as if one source jumped back and forth (two SLAMs, or '
                            'two robots in one domain without namespaces?)',
                            publishers, printable(topic))
        if params.camera_info_topic and not topics.camera_info:
            log.info('no %s in the recording: joints are judged in view by the map cone alone',
                     params.camera_info_topic)
        n_inputs = sum(recording.counts.get(t, 0) for t in topics.kinds())
        n_pass = sum(recording.counts.values()) if copy_inputs else n_inputs
        schedule = None
        calibrator = Calibrator(params, offline=mode == 'offline')
        with staged_output(output_path) as staged:
            writer = OutputWriter(staged, storage, layout_data(calibrator.layout))
            try:
                handler = OutputHandler(params, writer, notices, keep_poses=export_tum is not None)
                for output in TOPICS:  # hac_ros.bridge.topics: those its switches allow
                    if output.replay and output.enabled(params):
                        writer.connection(output.rooted, output.msgtype, latched=output.latched)
                feeder = CoreFeeder(recording, topics, calibrator,
                                    keep_poses=export_tum is not None)
                on_message = _input_copier(recording, writer) if copy_inputs else None
                if mode == 'online':
                    with progress_pass(progress, n_pass, 'replay') as bar:
                        feeder.run(handler, on_message=on_message, progress=bar)
                    status = feeder.calibrator.status()
                else:
                    status, schedule = _offline(feeder, handler, on_message, progress, n_pass)
            finally:
                writer.close()
            tum: dict[str, Path] = {}
            if export_tum is not None:
                tum = write_tum_exports(Path(export_tum), handler.poses or [], feeder.poses or [],
                                        recording)
    return ReplaySummary(mode, input_path, output_path, status, time.perf_counter() - start,
                         n_inputs, dict(writer.counts), list(handler.resets), schedule, tum,
                         start_ns, handler.last_scale, handler.statuses, params,
                         max(handler.max_samples, status.samples), feeder.calibrator.reach.apart_s)


def _offline(feeder: CoreFeeder, handler: OutputHandler,
             on_message: Callable[[str, int, Any], None] | None, progress: Progress | None,
             n_pass: int) -> tuple[Status, OfflineScale]:
    """The offline mode: one run of an offline calibrator (its metric outputs held back in its
    journal), then the run resolved with the schedule of its accepted samples and resets and
    written (:func:`hac_ros.core.offline.resolve_offline`: the same outputs as a second run with
    that schedule would give).

    Memory: the run's records are kept until the schedule is known (about 1.9 kB per frame of one
    person, docs/replay.md).
    """
    with progress_pass(progress, n_pass, 'estimate') as bar:
        feeder.run(lambda _: None, on_message=on_message, progress=bar)
    run = resolve_offline(feeder.calibrator)
    assert run.schedule is not None
    with progress_pass(progress, len(run.outputs), 'write') as bar:
        handler(run.outputs, bar)
    return run.status, run.schedule


def _input_copier(recording: Recording, writer: OutputWriter) -> Callable[[str, int, Any], None]:
    """copy_inputs: every input topic passes into OUT unchanged, at its log time.

    A topic of IN with an output topic's name (IN is itself a replay) is not copied, nor a ROS 1
    topic whose type ROS 2 Jazzy does not have.
    """
    ours = {output.rooted for output in TOPICS}
    typestore = recording.typestore
    if not recording.is_ros2:
        ours |= {t for t, msgtype in recording.topics.items() if msgtype not in typestore.fielddefs}

    def copy(topic: str, log_ns: int, raw: Any) -> None:
        if topic in ours:
            return
        conn = writer.connection(topic, recording.topics[topic], typestore=typestore)
        writer.write_raw(conn, log_ns, recording.to_cdr(raw, topic, log_ns))
    return copy
