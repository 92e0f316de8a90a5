"""The offline scale: the best estimate of each moment once the whole recording is known.

The paper is offline: one median of every per-frame scale of the video (docs/method.md, step 5). Two
of its stated limitations change that picture, and the offline mode handles both:

- **SLAM re-initialisation.** A new map has a new scale, so the recording is cut into segments at
  the estimator's resets and each segment gets its own estimate from its own samples only.
- **Scale drift.** Within a segment the median is the right answer only if the scale is constant.
  The evidence of drift is the trend of all the segment's samples at once (:func:`segment_drift`:
  their least-squares slope against the online estimator's prior, with the noise measured about
  it); the segment drifts when its probability is above DRIFT_EVIDENCE. Then the samples go
  through the online estimator's filter forwards and a
  Rauch–Tung–Striebel smoother backwards (hac_ros.core.scale_filter.smooth), with the noise
  measured on the samples about their centred rolling median (so that the drift is not taken
  for noise), and the segment's scale at a stamp is the smoothed level there, lifted by the
  median of the samples' residuals about it (so that its level is a median's, as in the constant
  case). Otherwise the segment keeps its median (docs/replay.md's contract).

A segment with fewer than ``min_samples`` accepted samples has no estimate (NaN: nothing metric is
published there, as online before convergence).

Pure numpy: no ROS. Stamps are int nanoseconds; scales are metres per SLAM unit.
"""
from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from hac_ros.core.errors import InputError
from hac_ros.core.estimator import DRIFT_EVIDENCE
from hac_ros.core.human_filter import smooth_outputs
from hac_ros.core.metric_stage import MetricStage, ScaleAt, finite_scale
from hac_ros.core.numeric import MEDIAN_STD_ERROR, NS
from hac_ros.core.outputs import Output, ResetOut, SampleOut, Status
from hac_ros.core.pending import PendingFrame, PendingOdometry, Record
from hac_ros.core.scale_filter import drift_probability, noise_density, smooth

if TYPE_CHECKING:
    from hac_ros.core.calibrator import Calibrator
    from hac_ros.core.plane import Plane

KNOTS_PER_WINDOW = 10  # knots of the drifting schedule per window length (linear in between)
# Near a segment's ends the centred window shrinks symmetrically (so it stays centred and unbiased
# on a linear drift) but never below this fraction of the full half window (so it is not too noisy).
EDGE_MIN_HALF_FRACTION = 0.25


@dataclass
class SegmentScale:
    """The offline scale of one segment (between two SLAM re-initialisations).

    start_ns: first stamp of the segment (the reset's stamp; the first segment starts at the
    recording's beginning); samples: accepted samples in it; median: their median, metres per SLAM
    unit (NaN if fewer than min_samples); sigma: robust sigma of the samples about the local trend,
    metres per SLAM unit; drift: whether the smoother found evidence of drift; drift_probability:
    the largest probability of drift over the segment; knots_ns / knots_scale: the schedule (one
    knot = constant median); error: the standard error of the published scale (the median's, or
    the smoothed level's median one when drifting), metres per SLAM unit (the odometry's
    covariance uses it).
    """

    start_ns: int
    samples: int
    median: float
    sigma: float
    drift: bool
    drift_probability: float
    knots_ns: np.ndarray = field(repr=False)
    knots_scale: np.ndarray = field(repr=False)
    first_sample_ns: int = 0
    last_sample_ns: int = 0
    error: float = math.nan

    def at(self, stamps_ns: np.ndarray) -> np.ndarray:
        """Scale at each stamp (M,) int ns -> (M,) float: interpolated knots, constant beyond."""
        if len(self.knots_ns) == 1:
            return np.full(np.shape(stamps_ns), float(self.knots_scale[0]))
        return np.interp(np.asarray(stamps_ns, dtype=np.float64), self.knots_ns.astype(np.float64),
                         self.knots_scale)

    def describe(self) -> str:
        if not math.isfinite(self.median):
            return f'{self.samples} samples: too few, no estimate'
        kind = 'drifting: smoothed' if self.drift else 'constant: median'
        if self.drift:
            lo, hi = float(np.min(self.knots_scale)), float(np.max(self.knots_scale))
            kind += f' {lo:.6g} .. {hi:.6g}'
        return (f'{self.samples} samples, median {self.median:.6g} +- {self.error:.2g}, {kind} '
                f'(drift probability {self.drift_probability:.2f})')


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
        self._constant = [float(s.knots_scale[0]) if len(s.knots_ns) == 1 else None
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
                  min_samples: int) -> OfflineScale:
    """The offline schedule from the accepted per-frame samples of a whole recording.

    sample_stamps_ns: (N,) int frame stamps; sample_scales: (N,) metres per SLAM unit (non-finite
    and non-positive values are ignored); reset_stamps_ns: stamps of the estimator's resets (each
    starts a new segment); window_s: the online window, stamp seconds (the rolling median that
    measures the noise is centred and as long); min_samples: samples a segment needs for an
    estimate.
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
    segments = [segment_scale(stamps[a:b], scales[a:b], start, window_s, min_samples)
                for start, a, b in zip(starts, edges[:-1], edges[1:])]
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
        schedule = offline_scale(np.array([s.stamp_ns for s in samples], dtype=np.int64),
                                 np.array([s.scale for s in samples]), resets, params.window_s,
                                 params.min_samples)
        scale_at, error_at = schedule, schedule.error
    # a stage of its own, without the online filter of the humans (smoothed below instead)
    stage = MetricStage(calibrator.metric.config)
    outputs = stage.resolve(records, scale_at, error_at, final_planes(records))
    if params.human_filter == 'smooth' if smooth_humans is None else smooth_humans:
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


def segment_scale(stamps_ns: np.ndarray, scales: np.ndarray, start_ns: int, window_s: float,
                  min_samples: int) -> SegmentScale:
    """One segment's estimate: its median, or its smoothed level where the smoother finds
    evidence of drift (module docstring).

    stamps_ns: (n,) int, sorted; scales: (n,) metres per SLAM unit, finite and positive.
    """
    n = len(scales)
    if n < max(int(min_samples), 1):
        return SegmentScale(int(start_ns), n, math.nan, math.nan, False, 0.0,
                            np.array([start_ns], dtype=np.int64), np.array([math.nan]),
                            int(stamps_ns[0]) if n else 0, int(stamps_ns[-1]) if n else 0)
    median = float(np.median(scales))
    half_ns = int(round(window_s * 0.5 * NS))
    trend = centred_medians(stamps_ns, scales, stamps_ns, half_ns, min_samples)
    log_scales = np.log(scales)
    noise = noise_density(stamps_ns, log_scales - np.log(trend))
    sigma = median * math.sqrt(noise.sigma2) if noise is not None else 0.0
    span_s = float(stamps_ns[-1] - stamps_ns[0]) / NS
    drift_p = segment_drift(stamps_ns, log_scales)
    smoothed = None
    if noise is not None and drift_p > DRIFT_EVIDENCE:
        smoothed = smooth(stamps_ns, log_scales, noise)
    if smoothed is not None:
        step = max(1, int(2 * half_ns / KNOTS_PER_WINDOW))
        knots = np.unique(np.r_[np.arange(int(stamps_ns[0]), int(stamps_ns[-1]), step,
                                          dtype=np.int64), int(stamps_ns[-1])])
        offset = float(np.median(log_scales - smoothed.level))
        t = stamps_ns.astype(np.float64)
        values = np.exp(np.interp(knots.astype(np.float64), t, smoothed.level) + offset)
        error = median * math.sqrt(float(np.median(smoothed.level_var)))
    else:
        knots, values = np.array([stamps_ns[0]], dtype=np.int64), np.array([median])
        variance = 0.0
        if noise is not None:
            variance = noise.sigma2 / n
            if span_s > 0.0:
                variance = max(variance, noise.density / span_s)
        error = MEDIAN_STD_ERROR * median * math.sqrt(variance)
    return SegmentScale(int(start_ns), n, median, sigma, bool(drift_p > DRIFT_EVIDENCE), drift_p,
                        knots, values, int(stamps_ns[0]), int(stamps_ns[-1]), error)


def segment_drift(stamps_ns: np.ndarray, log_scales: np.ndarray) -> float:
    """The probability that a segment's scale drifts, from all its samples at once: the
    least-squares slope of the log scale over the segment, its variance 12 N² / T³ (T the span,
    N² the noise density of the residuals about the line: hac_ros.core.scale_filter), weighed by
    the online estimator's prior (scale_filter.drift_probability). stamps_ns (n,) sorted int;
    log_scales (n,) natural log of metres per SLAM unit."""
    t = (stamps_ns - stamps_ns[0]) / NS
    span = float(t[-1]) if len(t) else 0.0
    if span <= 0.0:
        return 0.0
    slope, intercept = np.polyfit(t, log_scales, 1)
    noise = noise_density(stamps_ns, log_scales - (slope * t + intercept))
    if noise is None:
        return 0.0
    return drift_probability(float(slope), 12.0 * noise.density / span ** 3)


def centred_medians(stamps_ns: np.ndarray, scales: np.ndarray, query_ns: np.ndarray, half_ns: int,
                    min_samples: int) -> np.ndarray:
    """Median of the samples in a window centred on each query stamp.

    The window is ±half_ns, shrunk symmetrically near the samples' ends so that it stays centred
    (never below :data:`EDGE_MIN_HALF_FRACTION` of half_ns), and widened to ±half_ns if it then
    holds fewer than ``min_samples`` samples. stamps_ns: (n,) sorted int; scales: (n,); query_ns:
    (M,) int. Returns (M,) float, metres per SLAM unit.
    """
    query = np.asarray(query_ns, dtype=np.int64)
    if len(stamps_ns) == 0:
        return np.full(len(query), np.nan)
    t0, t1 = int(stamps_ns[0]), int(stamps_ns[-1])
    room = np.minimum(query - t0, t1 - query)
    half = np.clip(room, int(EDGE_MIN_HALF_FRACTION * half_ns), half_ns)
    lo = np.searchsorted(stamps_ns, query - half, side='left')
    hi = np.searchsorted(stamps_ns, query + half, side='right')
    short = (hi - lo) < min_samples
    if short.any():
        lo[short] = np.searchsorted(stamps_ns, query[short] - half_ns, side='left')
        hi[short] = np.searchsorted(stamps_ns, query[short] + half_ns, side='right')
    out = np.empty(len(query))
    for i, (a, b) in enumerate(zip(lo, hi)):
        if b <= a:  # no sample within the window: the nearest sample's value
            j = min(int(a), len(scales) - 1)
            out[i] = scales[j]
        else:
            out[i] = np.median(scales[a:b])
    return out
