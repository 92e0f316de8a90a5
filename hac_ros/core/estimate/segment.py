"""One segment's offline scale: the best estimate of each moment from all its samples at once.

A segment is one SLAM map between re-initialisations (hac_ros.core.offline cuts the recording at the
resets). Its samples are first brought to one unit: a map that changed its scale within the segment
(the calibrator's :class:`~hac_ros.core.basics.outputs.MapRescaleOut`, docs/method.md) measured the
samples before it in the old unit, so each sample is multiplied by the rescales after it, and the
schedule found is divided by them again where it is read (:meth:`SegmentScale.at`): there as a ramp
from the map before to the map that said so, since the SLAM's scale changed in between while its
poses went on (the samples, measured against the old map, could not see it). Then, in that unit:

- **the level** is the median of the samples weighed by the stamp time each covers
  (hac_ros.core.estimate.stamp_weights): a burst of repeated frames counts for the time it spans,
  not for its number;
- **a straight drift** is decided by the evidence of the trend of all samples at once
  (:func:`segment_drift`: their least-squares slope against the online estimator's prior, with the
  noise measured about it); drifting when its probability is above DRIFT_EVIDENCE: then the
  samples go through the online filter forwards and the Rauch–Tung–Striebel smoother backwards
  (hac_ros.core.estimate.scale_filter.smooth), with the noise measured about their centred rolling
  median, lifted by the median of the samples' residuals about it;
- **any other shape** (a scale that breathes, steps, slips out of sight) is what is left about
  that schedule: the residuals' centred weighted median over SHAPE_HALF_S either side, tested
  block by block against its standard error (a chi-square over blocks of 2 SHAPE_HALF_S, beyond
  SHAPE_Z standard deviations of its degrees of freedom) and larger than SHAPE_NOISES times a
  sample's own noise; where it is both the schedule follows it, never one median with a small
  ``±``.

A segment with fewer than ``min_samples`` but at least FEW_SAMPLES_MIN samples gets its estimate,
flagged ``few``; with fewer, none (NaN: nothing metric is published there, as online before
convergence).

Pure numpy: no ROS. Stamps are int nanoseconds; scales are metres per SLAM unit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hac_ros.core.basics.numeric import MEDIAN_STD_ERROR, NS, median_of
from hac_ros.core.estimate.estimator import DRIFT_EVIDENCE
from hac_ros.core.estimate.scale_filter import drift_probability, noise_density, smooth
from hac_ros.core.estimate.stamp_weights import stamp_weights, weighted_median

FEW_SAMPLES_MIN = 3  # a segment with fewer samples has no estimate
KNOTS_PER_WINDOW = 10  # knots of the drifting schedule per window length (linear in between)
# Near a segment's ends the centred window shrinks symmetrically (so it stays centred and unbiased
# on a linear drift) but never below this fraction of the full half window (so it is not too noisy).
EDGE_MIN_HALF_FRACTION = 0.25
SHAPE_HALF_S = 4.0  # the shape follower's centred window: this much stamp time either side
SHAPE_Z = 4.0  # its chi-square over blocks must exceed its dof by this many of its std devs
SHAPE_KNOT_S = 1.0  # the followed shape's knots, this far apart in stamp time
SHAPE_NOISES = 2.0  # a shape is followed only when its RMS exceeds this many samples' own noise


@dataclass
class SegmentScale:
    """The offline scale of one segment (between two SLAM re-initialisations).

    start_ns: first stamp of the segment (the reset's stamp; the first segment starts at the
    recording's beginning); samples: accepted samples in it; median: their weighted median, metres
    per SLAM unit, in the unit of the segment's last map (NaN if fewer than FEW_SAMPLES_MIN);
    sigma: robust sigma of the samples about the local trend, metres per SLAM unit; drift: whether
    the schedule is not one median (a drift or a shape); drift_probability: the straight drift's
    probability; shape: whether it follows a shape beyond a straight drift; few: fewer samples
    than ``min_samples``; knots_ns / knots_scale: the schedule in that unit (one knot = constant
    median); rescales_ns / rescales_log / rescales_since_ns: the maps' changes of scale in the
    segment (stamp, natural log of new over old scale, the stamp of the map before), which
    :meth:`at` applies; error: the standard error of the
    published scale, metres per SLAM unit (the odometry's covariance uses it).
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
    shape: bool = False
    few: bool = False
    rescales_ns: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64),
                                    repr=False)
    rescales_log: np.ndarray = field(default_factory=lambda: np.empty(0), repr=False)
    rescales_since_ns: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64),
                                          repr=False)

    def at(self, stamps_ns: np.ndarray) -> np.ndarray:
        """Scale at each stamp (M,) int ns -> (M,) float: interpolated knots, constant beyond,
        each rescale ramped in from the map before it (module docstring)."""
        stamps = np.asarray(stamps_ns)
        if len(self.knots_ns) == 1:
            out = np.full(np.shape(stamps), float(self.knots_scale[0]))
        else:
            out = np.interp(stamps.astype(np.float64), self.knots_ns.astype(np.float64),
                            self.knots_scale)
        if len(self.rescales_ns):
            t = np.asarray(stamps, dtype=np.float64)[..., None]
            since, until = self.rescales_since_ns.astype(np.float64), self.rescales_ns.astype(
                np.float64)
            still = np.clip((until - t) / np.maximum(until - since, 1.0), 0.0, 1.0)
            out = out * np.exp(-(still * self.rescales_log).sum(axis=-1))
        return out


def drift_text(probability: float) -> str:
    """A probability as the summary prints it: never rounded up to 1 (0.9993 is '1 - 7e-04')."""
    if probability >= 0.995 and probability < 1.0:
        return f'1 - {1.0 - probability:.1e}'
    return f'{probability:.2f}'


def unit_shift(stamps_ns: np.ndarray, rescales_ns: np.ndarray, rescales_log: np.ndarray
               ) -> np.ndarray:
    """Per stamp, the natural log of the rescales after it: a sample of that stamp times
    exp(this) is in the unit of the segment's last map (a map is in use from its stamp on)."""
    after = np.r_[np.cumsum(rescales_log[::-1])[::-1], 0.0]
    return after[np.searchsorted(rescales_ns, np.asarray(stamps_ns, dtype=np.int64),
                                 side='right')]


def segment_scale(stamps_ns: np.ndarray, scales: np.ndarray, start_ns: int, window_s: float,
                  min_samples: int, rescales: list[tuple[int, float, int]] | None = None
                  ) -> SegmentScale:
    """One segment's estimate (module docstring).

    stamps_ns: (n,) int, sorted; scales: (n,) metres per SLAM unit, finite and positive;
    rescales: (stamp ns, new over old scale, stamp of the map before) of the maps that changed
    scale in the segment.
    """
    n = len(scales)
    moves = sorted(rescales or [])
    moves_ns = np.array([m[0] for m in moves], dtype=np.int64)
    moves_log = np.log(np.array([m[1] for m in moves], dtype=np.float64))
    moves_since = np.array([min(m[2], m[0]) for m in moves], dtype=np.int64)

    if n < FEW_SAMPLES_MIN:
        return SegmentScale(int(start_ns), n, math.nan, math.nan, False, 0.0,
                            np.array([start_ns], dtype=np.int64), np.array([math.nan]),
                            int(stamps_ns[0]) if n else 0, int(stamps_ns[-1]) if n else 0,
                            few=True, rescales_ns=moves_ns, rescales_log=moves_log,
                            rescales_since_ns=moves_since)
    log_scales = np.log(scales) + unit_shift(stamps_ns, moves_ns, moves_log)
    weights = stamp_weights(stamps_ns)
    median = weighted_median(np.exp(log_scales), weights)
    half_ns = int(round(window_s * 0.5 * NS))
    trend = np.log(centred_medians(stamps_ns, np.exp(log_scales), stamps_ns, half_ns,
                                   min_samples))
    noise = noise_density(stamps_ns, log_scales - trend)
    sigma = median * math.sqrt(noise.sigma2) if noise is not None else 0.0
    covered = float(weights.sum())
    drift_p = segment_drift(stamps_ns, log_scales)
    smoothed = None
    if noise is not None and drift_p > DRIFT_EVIDENCE:
        smoothed = smooth(stamps_ns, log_scales, noise)
    if smoothed is not None:
        step = max(1, int(2 * half_ns / KNOTS_PER_WINDOW))
        knots = np.unique(np.r_[np.arange(int(stamps_ns[0]), int(stamps_ns[-1]), step,
                                          dtype=np.int64), int(stamps_ns[-1])])
        offset = median_of(log_scales - smoothed.level)
        t = stamps_ns.astype(np.float64)
        values = np.interp(knots.astype(np.float64), t, smoothed.level) + offset
        error = median * math.sqrt(median_of(smoothed.level_var))
    else:
        knots, values = np.array([stamps_ns[0]], dtype=np.int64), np.array([math.log(median)])
        variance = 0.0
        if noise is not None:
            variance = noise.sigma2 * float(weights @ weights) / covered ** 2
            if covered > 0.0:
                variance = max(variance, noise.density / covered)
        error = MEDIAN_STD_ERROR * median * math.sqrt(variance)
    shaped = follow_shape(stamps_ns, log_scales, weights, knots, values, bool(moves))
    if shaped is not None:
        knots, values, shape_error = shaped
        error = math.hypot(error, median * shape_error)
    return SegmentScale(int(start_ns), n, median, sigma,
                        bool(drift_p > DRIFT_EVIDENCE) or shaped is not None, drift_p,
                        knots, np.exp(values), int(stamps_ns[0]), int(stamps_ns[-1]), error,
                        shape=shaped is not None, few=n < min_samples, rescales_ns=moves_ns,
                        rescales_log=moves_log, rescales_since_ns=moves_since)


def follow_shape(stamps_ns: np.ndarray, log_scales: np.ndarray, weights: np.ndarray,
                 knots_ns: np.ndarray, knots_log: np.ndarray, maps_moved: bool = False
                 ) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The schedule (knots (K,) int ns, natural log (K,)) with the shape the samples show about
    it (module docstring), or None when they show none: new knots every SHAPE_KNOT_S, their values
    (log) and the shape's own standard error (relative, median over the knots).

    The shape is the residuals' centred weighted median within SHAPE_HALF_S; the noise
    (hac_ros.core.estimate.scale_filter.noise_density) is measured about it, so that the shape is
    not taken for noise; each block of 2 SHAPE_HALF_S gives one independent value of it, judged
    against its standard error; unless the maps said the scale moved (``maps_moved``: the
    segment's samples were brought to one unit through their ratios, whose errors add up), its
    size (RMS over the blocks) must also exceed SHAPE_NOISES times a sample's own noise: a slower
    wander of that size is the correlated noise an HMR model has (a 3 % wander over 10 s among
    2.5 % samples: test_replay_offline), not the SLAM's scale."""
    if len(stamps_ns) < 2 * FEW_SAMPLES_MIN:
        return None
    t = stamps_ns.astype(np.float64)
    base = (np.full(len(t), knots_log[0]) if len(knots_ns) == 1
            else np.interp(t, knots_ns.astype(np.float64), knots_log))
    residuals = log_scales - base
    half = SHAPE_HALF_S * NS
    span = float(stamps_ns[-1] - stamps_ns[0])
    blocks = int(span // (2 * half))
    if blocks < 2:
        return None
    lo = np.searchsorted(t, t - half, side='left')
    hi = np.searchsorted(t, t + half, side='right')
    shape_at = np.array([weighted_median(residuals[a:b], weights[a:b]) for a, b in zip(lo, hi)])
    noise = noise_density(stamps_ns, residuals - shape_at)
    if noise is None:
        return None

    def local(centre: float) -> tuple[float, float] | None:
        a, b = np.searchsorted(t, [centre - half, centre + half], side='left')
        if b - a < FEW_SAMPLES_MIN:
            return None
        w = weights[a:b]
        covered = float(w.sum())
        variance = MEDIAN_STD_ERROR ** 2 * max(noise.sigma2 * float(w @ w) / covered ** 2,
                                               noise.density / covered)
        return weighted_median(residuals[a:b], w), variance
    centres = t[0] + (np.arange(blocks) + 0.5) * 2 * half
    blocks_found = [f for f in map(local, centres) if f is not None]
    z2 = [m * m / v for m, v in blocks_found]
    dof = len(z2)
    if dof < 2 or sum(z2) <= dof + SHAPE_Z * math.sqrt(2.0 * dof):
        return None
    if not maps_moved and math.sqrt(float(np.mean([m * m for m, _ in blocks_found]))) <= (
            SHAPE_NOISES * math.sqrt(noise.sigma2)):
        return None  # a wander within a sample's own noise: the correlated noise HMR has
    knots = np.unique(np.r_[np.arange(int(stamps_ns[0]), int(stamps_ns[-1]),
                                      int(SHAPE_KNOT_S * NS), dtype=np.int64),
                            int(stamps_ns[-1])])
    found = [local(float(k)) for k in knots]
    ok = np.array([f is not None for f in found])
    values = np.array([f[0] if f is not None else math.nan for f in found])
    values = np.interp(knots.astype(np.float64), knots[ok].astype(np.float64), values[ok])
    base_at = (np.full(len(knots), knots_log[0]) if len(knots_ns) == 1
               else np.interp(knots.astype(np.float64), knots_ns.astype(np.float64), knots_log))
    error = median_of([math.sqrt(f[1]) for f in found if f is not None])
    return knots, base_at + values, error


def segment_drift(stamps_ns: np.ndarray, log_scales: np.ndarray) -> float:
    """The probability that a segment's scale drifts, from all its samples at once: the
    least-squares slope of the log scale over the segment, its variance 12 N² / T³ (T the span, N²
    the noise density of the residuals about the line: hac_ros.core.estimate.scale_filter), weighed
    by the online estimator's prior (scale_filter.drift_probability). stamps_ns (n,) sorted int;
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
            out[i] = median_of(scales[a:b])
    return out

