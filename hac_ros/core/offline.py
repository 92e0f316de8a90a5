"""The offline scale: the best estimate of each moment once the whole recording is known.

The paper is offline: one median of every per-frame scale of the video (docs/method.md, step 5). Two
of its stated limitations change that picture, and the offline mode handles both:

- **SLAM re-initialisation.** A new map has a new scale, so the recording is cut into segments at
  the estimator's resets and each segment gets its own estimate from its own samples only.
- **A scale that changes within a segment**: a map that changed its scale, a drift, any other
  shape: hac_ros.core.estimate.segment estimates each segment (its weighted median, a straight drift
  smoothed, a shape followed), in the unit of the map in use at each moment.

A segment with fewer than ``min_samples`` accepted samples but at least
:data:`~hac_ros.core.estimate.segment.FEW_SAMPLES_MIN` gets its estimate, flagged ``few``; with
fewer it has none (NaN: nothing metric is published there, as online before convergence).

Pure numpy: no ROS. Stamps are int nanoseconds; scales are metres per SLAM unit.
"""
from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hac_ros.core.basics.errors import InputError
from hac_ros.core.basics.outputs import MapRescaleOut, Output, ResetOut, SampleOut, Status
from hac_ros.core.bodies.human_filter import smooth_outputs
from hac_ros.core.estimate.segment import SegmentScale, segment_scale
from hac_ros.core.rules.params import HumanFilter
from hac_ros.core.stream.metric_stage import MetricStage, ScaleAt, finite_scale
from hac_ros.core.stream.pending import PendingFrame, PendingOdometry, Record

if TYPE_CHECKING:
    from hac_ros.core.calibrator import Calibrator
    from hac_ros.core.geometry.plane import Plane

class OfflineScale:
    """stamp_ns -> scale for a whole recording: the segment of the stamp, then its schedule.

    Callable, as the ``schedule`` of a :class:`~hac_ros.core.calibrator.Calibrator`. A stamp at or
    after a reset stamp belongs to the new segment (the calibrator resets before it accepts the pose
    of that stamp).
    """

    def __init__(self, segments: list[SegmentScale]) -> None:
        if not segments:
            raise ValueError('OfflineScale needs at least one segment')
        self.segments = segments
        self._starts = [s.start_ns for s in segments[1:]]
        # constant segments answer without numpy (called once per pose and per frame)
        self._constant = [float(s.knots_scale[0])
                          if len(s.knots_ns) == 1 and not len(s.rescales_ns) else None
                          for s in segments]

    def segment_index(self, stamp_ns: int) -> int:
        return bisect.bisect_right(self._starts, int(stamp_ns))

    def error(self, stamp_ns: int) -> float:
        """Standard error of the scale at ``stamp_ns`` (its segment's), metres per SLAM unit."""
        return self.segments[self.segment_index(stamp_ns)].error

    def __call__(self, stamp_ns: int) -> float:
        k = self.segment_index(stamp_ns)
        constant = self._constant[k]
        if constant is not None:
            return constant
        return float(self.segments[k].at(np.array([stamp_ns]))[0])

    def at(self, stamps_ns: np.ndarray) -> np.ndarray:
        """Vectorised: (M,) int ns -> (M,) float, metres per SLAM unit (NaN: no estimate)."""
        stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
        which = np.searchsorted(np.asarray(self._starts, dtype=np.int64), stamps_ns, side='right')
        out = np.full(len(stamps_ns), np.nan)
        for k, segment in enumerate(self.segments):
            mask = which == k
            if mask.any():
                out[mask] = segment.at(stamps_ns[mask])
        return out

    @property
    def drifting(self) -> bool:
        return any(s.drift for s in self.segments)


def offline_scale(sample_stamps_ns: np.ndarray, sample_scales: np.ndarray,
                  reset_stamps_ns: np.ndarray | list[int], window_s: float,
                  min_samples: int, rescales: list[tuple[int, float, int]] | None = None
                  ) -> OfflineScale:
    """The offline schedule from the accepted per-frame samples of a whole recording.

    sample_stamps_ns: (N,) int frame stamps; sample_scales: (N,) metres per SLAM unit (non-finite
    and non-positive values are ignored); reset_stamps_ns: stamps of the estimator's resets (each
    starts a new segment); window_s: the online window, stamp seconds (the rolling median that
    measures the noise is centred and as long); min_samples: samples a segment needs to be
    more than ``few``; rescales: (stamp ns, new over old scale, stamp of the map before) of the
    maps that changed their scale (:class:`~hac_ros.core.basics.outputs.MapRescaleOut`).
    """
    stamps = np.asarray(sample_stamps_ns, dtype=np.int64).reshape(-1)
    scales = np.asarray(sample_scales, dtype=np.float64).reshape(-1)
    if stamps.shape != scales.shape:
        raise ValueError(f'stamps {stamps.shape} and scales {scales.shape} differ in length')
    keep = np.isfinite(scales) & (scales > 0.0)
    stamps, scales = stamps[keep], scales[keep]
    order = np.argsort(stamps, kind='stable')
    stamps, scales = stamps[order], scales[order]
    resets = sorted(int(r) for r in reset_stamps_ns)
    bounds = np.searchsorted(stamps, np.asarray(resets, dtype=np.int64), side='left')
    edges = [0, *bounds.tolist(), len(stamps)]
    starts = [int(stamps[0]) if len(stamps) else 0, *resets]
    ends = [*resets, 2 ** 62]
    segments = [segment_scale(stamps[a:b], scales[a:b], start, window_s, min_samples,
                              [r for r in rescales or [] if start <= r[0] < end])
                for start, end, a, b in zip(starts, ends, edges[:-1], edges[1:])]
    return OfflineScale(segments)


@dataclass
class OfflineRun:
    """An offline run, resolved: ``outputs`` every output in order (metric ones with the schedule),
    ``schedule`` the offline schedule (None when a ``scale_at`` was given), ``status`` the final
    /diagnostics status."""

    outputs: list[Output]
    schedule: OfflineScale | None
    status: Status


def resolve_offline(calibrator: Calibrator, scale_at: ScaleAt | None = None,
                    smooth_humans: bool | None = None) -> OfflineRun:
    """The run of an offline calibrator (``Calibrator(offline=True)``, fed a whole recording)
    resolved as the offline replay resolves it: the metric records of its journal turned into
    outputs with the offline schedule of the run's own accepted samples and resets, or with
    ``scale_at`` (stamp -> metres per SLAM unit) when given; each segment aligned with its final
    ground plane; the world humans smoothed over the whole recording when ``human_filter`` is
    ``smooth`` (``smooth_humans`` overrides it). The journal is only read: a run can be resolved
    with several schedules.
    """
    records = calibrator.journal
    if records is None:
        raise InputError('resolve_offline needs a calibrator made with offline=True')
    params = calibrator.params
    schedule = None
    error_at = None
    if scale_at is None:
        samples = [r for r in records if isinstance(r, SampleOut) and r.accepted]
        resets = [r.stamp_ns for r in records if isinstance(r, ResetOut)]
        rescales = [(r.stamp_ns, r.factor, r.since_ns) for r in records
                    if isinstance(r, MapRescaleOut)]
        schedule = offline_scale(np.array([s.stamp_ns for s in samples], dtype=np.int64),
                                 np.array([s.scale for s in samples]), resets, params.window_s,
                                 params.min_samples, rescales)
        sys_rel = calibrator.layout.sys_rel_sigma  # the published ±: the biases' prior too

        def published_error(stamp_ns: int) -> float:
            return math.hypot(schedule.error(stamp_ns), sys_rel * schedule(stamp_ns))
        scale_at, error_at = schedule, published_error
    # a stage of its own, without the online filter of the humans (smoothed below instead)
    stage = MetricStage(calibrator.metric.config)
    outputs = stage.resolve(records, scale_at, error_at, final_planes(records))
    if params.human_filter == HumanFilter.SMOOTH if smooth_humans is None else smooth_humans:
        smooth_outputs(outputs, calibrator.layout)
    pending = calibrator.pending_status()
    status = stage.status(pending, finite_scale(scale_at(pending.status.stamp_ns)))
    return OfflineRun(outputs, schedule, status)


def final_planes(records: Sequence[Record]) -> dict[int, Plane | None]:
    """Segment -> its last ground plane (SLAM map frame) among an offline run's records: offline,
    each segment has one final alignment (docs/interface.md, "The metric frame")."""
    planes: dict[int, Plane | None] = {}
    for record in records:
        if isinstance(record, (PendingOdometry, PendingFrame)) and record.plane is not None:
            planes[record.segment] = record.plane
    return planes
