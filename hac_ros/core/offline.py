"""The offline scale: the best estimate of each moment once the whole recording is known.

The paper is offline: one median of every per-frame scale of the video (docs/method.md, step 5). Two
of its stated limitations change that picture, and the offline mode handles both:

- **SLAM re-initialisation.** A new map has a new scale, so the recording is cut into segments at
  the estimator's resets and each segment gets its own estimate from its own samples only.
- **Scale drift.** Within a segment the median is the right answer only if the scale is constant.
  The drift test below asks whether the samples say otherwise; if they do, the segment's scale at a
  stamp is the **centred** rolling median around it (it uses the samples after the stamp too, which
  an online estimator cannot), interpolated linearly between knots.

The drift test (documented in docs/replay.md). Inside a segment of samples ``s_i`` at stamps
``t_i``, with ``m`` the segment median:

1. Lay centred windows of ``window_s`` stamp seconds (the online window's length) every half
   window, each entirely inside the segment, and take each window's median ``m_w`` over its
   ``n_w`` samples (windows with fewer than ``min_samples`` samples are skipped).
2. The noise of the samples is their robust sigma **about the local trend** (1.4826 × the median
   absolute residual from the centred rolling median), so that a drift does not pass for noise.
3. Under a constant scale ``m_w`` differs from ``m`` only by the error of a median of ``n_w``
   samples, ``1.2533 σ / √n_w``. The segment drifts when some window's ``z_w = |m_w − m| /
   (1.2533 σ / √n_w)`` exceeds :data:`DRIFT_Z` **and** its relative departure ``|m_w / m − 1|``
   exceeds :data:`DRIFT_MIN_REL` (per-frame samples are correlated in real data, so the z-score
   alone would fire on slow HMR bias changes that are not a scale change worth following).

A segment shorter than one window cannot show drift and keeps its median. A segment with fewer
than ``min_samples`` accepted samples has no estimate (NaN: nothing metric is published there, as
online before convergence).

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
from hac_ros.core.human_filter import smooth_outputs
from hac_ros.core.metric_stage import MetricStage, ScaleAt, finite_scale
from hac_ros.core.numeric import MAD_TO_SIGMA, MEDIAN_STD_ERROR, NS
from hac_ros.core.outputs import Output, ResetOut, SampleOut, Status
from hac_ros.core.pending import PendingFrame, PendingOdometry, Record

if TYPE_CHECKING:
    from hac_ros.core.calibrator import Calibrator
    from hac_ros.core.plane import Plane

# A window median this many standard errors from the segment median is not noise. With one window
# per half window over a long recording (hundreds of windows), 5 sigma keeps false alarms rare.
DRIFT_Z = 5.0
# ... and it must also depart from the segment median by this fraction: smaller drifts are below
# what per-frame HMR noise and its slow biases let us follow, and the median is then the better bet.
DRIFT_MIN_REL = 0.02
KNOTS_PER_WINDOW = 10  # knots of the drifting schedule per window length (linear in between)
# Near a segment's ends the centred window shrinks symmetrically (so it stays centred and unbiased
# on a linear drift) but never below this fraction of the full half window (so it is not too noisy).
EDGE_MIN_HALF_FRACTION = 0.25


@dataclass
class SegmentScale:
    """The offline scale of one segment (between two SLAM re-initialisations).

    start_ns: first stamp of the segment (the reset's stamp; the first segment starts at the
    recording's beginning); samples: accepted samples in it; median: their median, metres per SLAM
    unit (NaN if fewer than min_samples); sigma: robust sigma of the samples about the local trend;
    drift: whether the drift test fired; drift_z / drift_rel: the largest window z-score and
    relative departure seen; knots_ns / knots_scale: the schedule (one knot = constant median);
    error: the standard error of the published scale (of the median, or of one window's median when
    drifting), metres per SLAM unit (the odometry's covariance uses it).
    """

    start_ns: int
    samples: int
    median: float
    sigma: float
    drift: bool
    drift_z: float
    drift_rel: float
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
        kind = 'drifting: centred rolling median' if self.drift else 'constant: median'
        if self.drift:
            lo, hi = float(np.min(self.knots_scale)), float(np.max(self.knots_scale))
            kind += f' {lo:.6g} .. {hi:.6g}'
        return (f'{self.samples} samples, median {self.median:.6g} +- {self.sigma:.2g}, {kind} '
                f'(drift test: max z {self.drift_z:.1f}, max departure '
                f'{100 * self.drift_rel:.1f} %)')


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
                  reset_stamps_ns: np.ndarray | list[int], window_s: float, min_samples: int,
                  drift_z: float = DRIFT_Z, drift_min_rel: float = DRIFT_MIN_REL) -> OfflineScale:
    """The offline schedule from the accepted per-frame samples of a whole recording.

    sample_stamps_ns: (N,) int frame stamps; sample_scales: (N,) metres per SLAM unit (non-finite
    and non-positive values are ignored); reset_stamps_ns: stamps of the estimator's resets (each
    starts a new segment); window_s: the centred window, stamp seconds; min_samples: samples a
    segment needs for an estimate.
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
    segments = [
        segment_scale(stamps[a:b], scales[a:b], start, window_s, min_samples, drift_z,
                      drift_min_rel)
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
                  min_samples: int, drift_z: float = DRIFT_Z,
                  drift_min_rel: float = DRIFT_MIN_REL) -> SegmentScale:
    """One segment's estimate: median, or the centred rolling median when the drift test fires.

    stamps_ns: (n,) int, sorted; scales: (n,) metres per SLAM unit, finite and positive.
    """
    n = len(scales)
    if n < max(int(min_samples), 1):
        return SegmentScale(int(start_ns), n, math.nan, math.nan, False, 0.0, 0.0,
                            np.array([start_ns], dtype=np.int64), np.array([math.nan]),
                            int(stamps_ns[0]) if n else 0, int(stamps_ns[-1]) if n else 0)
    median = float(np.median(scales))
    half_ns = int(round(window_s * 0.5 * NS))
    trend = centred_medians(stamps_ns, scales, stamps_ns, half_ns, min_samples)
    sigma = MAD_TO_SIGMA * float(np.median(np.abs(scales - trend)))
    z_max, rel_max = drift_statistic(stamps_ns, scales, median, sigma, half_ns, min_samples)
    drift = z_max > drift_z and rel_max > drift_min_rel
    if drift:
        step = max(1, int(2 * half_ns / KNOTS_PER_WINDOW))
        knots = np.arange(int(stamps_ns[0]), int(stamps_ns[-1]) + step, step, dtype=np.int64)
        knots[-1] = min(knots[-1], int(stamps_ns[-1]))
        knots = np.unique(knots)
        values = centred_medians(stamps_ns, scales, knots, half_ns, min_samples)
        span = max(int(stamps_ns[-1]) - int(stamps_ns[0]), 1)
        n_used = max(1.0, n * min(1.0, 2 * half_ns / span))  # the samples of one window
    else:
        knots, values = np.array([stamps_ns[0]], dtype=np.int64), np.array([median])
        n_used = float(n)
    return SegmentScale(int(start_ns), n, median, sigma, bool(drift), z_max, rel_max, knots, values,
                        int(stamps_ns[0]), int(stamps_ns[-1]),
                        MEDIAN_STD_ERROR * sigma / math.sqrt(n_used))


def drift_statistic(stamps_ns: np.ndarray, scales: np.ndarray, median: float, sigma: float,
                    half_ns: int, min_samples: int) -> tuple[float, float]:
    """The largest window z-score and relative departure from ``median`` (see the module docstring).

    Windows of ±half_ns centred every half_ns, entirely within the samples' span.
    """
    t0, t1 = int(stamps_ns[0]), int(stamps_ns[-1])
    if t1 - t0 < 2 * half_ns or half_ns <= 0:
        return 0.0, 0.0
    centres = np.arange(t0 + half_ns, t1 - half_ns + 1, half_ns, dtype=np.int64)
    lo = np.searchsorted(stamps_ns, centres - half_ns, side='left')
    hi = np.searchsorted(stamps_ns, centres + half_ns, side='right')
    z_max = rel_max = 0.0
    noise = max(sigma, 1e-12 * abs(median))  # identical samples: any departure is significant
    for a, b in zip(lo, hi):
        count = int(b - a)
        if count < max(min_samples, 1):
            continue
        window_median = float(np.median(scales[a:b]))
        z = abs(window_median - median) / (MEDIAN_STD_ERROR * noise / math.sqrt(count))
        z_max = max(z_max, z)
        rel_max = max(rel_max, abs(window_median / median - 1.0))
    return float(z_max), float(rel_max)


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
