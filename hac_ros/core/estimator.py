"""The scale estimator: a rolling window in stamp time with a streaming median (docs/method.md,
step 5).

The paper takes one median over a whole video. Online we keep the per-frame scales of the last
``window_s`` stamp seconds (at most ``window_max_samples``) in arrival order; the estimate is their
median and the robust spread their median absolute deviation (MAD), both computed when the window
has changed and kept until it changes again.

Once converged (``min_samples``), a sample further than ``gate_k`` robust sigmas from the median
(and than ``gate_min_rel`` of it) is gated out. If gated samples keep coming in a row for a third
of the window (and at least ``min_samples``), consistent among themselves, the window was wrong
(it locked on a bad start) and the estimator re-locks on them.

**Drift.** The window's median lags a drifting scale by half the window (6 % for a SLAM scale
drifting 40 % in 90 s under a 30 s window). :meth:`RollingScale.current` is therefore the median
only while the scale looks constant; when the window's samples drift it is their robust linear
trend in log-scale evaluated at the newest stamp (:func:`log_trend`: Theil–Sen over the medians
of TREND_BINS time bins; only once the samples span a third of the window, so not right after a
reset). The window drifts when the trend's slope is DRIFT_Z standard errors
from zero (the error from the bin medians' scatter about the trend) and moves the scale by more
than DRIFT_MIN_REL over the window: a trend is twice as noisy as a median at the window's end, so it
is used only when the drift is real. The trend is re-fitted every TREND_REFRESH_NS of stamp time.
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from hac_ros.core.numeric import MAD_TO_SIGMA, NS

TREND_BINS = 8  # time bins of the window whose medians the trend is fitted to
# samples a bin needs to count: the median of fewer is too noisy to fit a slope to (at keyframe
# rate, 1-2 Hz, bins of 3 samples made a spurious 'drift' that read a constant scale 9 % off)
TREND_MIN_PER_BIN = 10
TREND_REFRESH_NS = 500_000_000  # the trend is re-fitted this often (stamp time)
DRIFT_Z = 4.0  # the slope's distance from zero, in standard errors, that says "drifting"
DRIFT_MIN_REL = 0.04  # ... and the smallest relative change over the window worth following
TREND_MIN_SPAN_REL = 1.0 / 3.0  # a trend needs samples over this fraction of the window


class RollingScale:
    """Per-frame scale samples in, a causal robust scale estimate out."""

    def __init__(self, window_s: float, window_max_samples: int, min_samples: int,
                 gate_k: float = 5.0, gate_min_rel: float = 0.15) -> None:
        self.window_ns = int(round(window_s * NS))
        self.max_samples = int(window_max_samples)
        self.min_samples = int(min_samples)
        self.gate_k = float(gate_k)
        self.gate_min_rel = float(gate_min_rel)
        self._fifo: deque[tuple[int, float]] = deque()  # (stamp_ns, scale) in arrival order
        self._gated_run: list[tuple[int, float]] = []
        self.relocks = 0
        self._stats: tuple[float, float] | None = None  # (median, MAD), until the window changes
        self._now_ns = -1  # the newest stamp seen (a sample or advance)
        # the drift trend: (log scale at the reference stamp, slope per ns, reference stamp) or
        # None while the window looks constant; and the stamp it was fitted at
        self._trend: tuple[float, float, int] | None = None
        self._trend_ns: int | None = None

    # ------------------------------------------------------------------ updates
    def add(self, stamp_ns: int, scale: float) -> bool:
        """Add one sample (stamp in ns, scale in metres per SLAM unit); False if it was gated.

        Non-finite or non-positive samples are never added (the caller counts them).
        """
        if not (math.isfinite(scale) and scale > 0.0):
            return False
        self._now_ns = max(self._now_ns, int(stamp_ns))
        self._evict(stamp_ns)
        if self.converged and not self._within_gate(scale):
            self._gated_run.append((stamp_ns, scale))
            if self._run_says_window_is_wrong():
                self._relock()
            return False
        self._gated_run.clear()
        self._fifo.append((stamp_ns, scale))
        self._stats = None
        if len(self._fifo) > self.max_samples:
            self._drop_oldest()
        return True

    def advance(self, stamp_ns: int) -> None:
        """Let stamp time pass without a sample (evicts what fell out of the window)."""
        self._now_ns = max(self._now_ns, int(stamp_ns))
        self._evict(stamp_ns)

    def reset(self) -> None:
        """Forget everything (SLAM re-initialisation: the new map has a new scale)."""
        self._fifo.clear()
        self._gated_run.clear()
        self._stats = None
        self._trend, self._trend_ns = None, None

    # ------------------------------------------------------------------ queries
    @property
    def samples(self) -> int:
        return len(self._fifo)

    @property
    def converged(self) -> bool:
        return len(self._fifo) >= self.min_samples

    def median(self) -> float:
        """The window's median, metres per SLAM unit (NaN when empty)."""
        return self._median_and_mad()[0]

    def current(self) -> float:
        """The scale now (metres per SLAM unit, NaN when empty): the window's median, or its drift
        trend at the newest stamp while the window drifts (module docstring)."""
        if not self.converged:
            return self.median()
        if self._trend_ns is None or self._now_ns - self._trend_ns >= TREND_REFRESH_NS:
            self._trend_ns = self._now_ns
            stamps = np.fromiter((s for s, _ in self._fifo), np.int64, len(self._fifo))
            values = np.fromiter((v for _, v in self._fifo), float, len(self._fifo))
            long_enough = (len(stamps)
                           and stamps[-1] - stamps[0] >= TREND_MIN_SPAN_REL * self.window_ns)
            self._trend = log_trend(stamps, values) if long_enough else None
        if self._trend is None:
            return self.median()
        level, slope, ref_ns = self._trend
        return math.exp(level + slope * (self._now_ns - ref_ns))

    @property
    def drifting(self) -> bool:
        """Whether :meth:`current` follows a drift trend (as of its last fit)."""
        return self._trend is not None

    def mad(self) -> float:
        """Median absolute deviation from the median, metres per SLAM unit (NaN when empty)."""
        return self._median_and_mad()[1]

    def _median_and_mad(self) -> tuple[float, float]:
        if self._stats is None:
            if not self._fifo:
                return math.nan, math.nan
            values = self.values()
            median = float(np.median(values))
            self._stats = median, float(np.median(np.abs(values - median)))
        return self._stats

    def spread(self) -> float:
        """Robust sigma of the samples (1.4826 MAD), metres per SLAM unit."""
        return MAD_TO_SIGMA * self.mad()

    def values(self) -> np.ndarray:
        """The window's samples in arrival order (for tests and plots)."""
        return np.array([v for _, v in self._fifo], dtype=float)

    # ------------------------------------------------------------------ internals
    def _within_gate(self, scale: float) -> bool:
        med = self.median()
        band = max(self.gate_k * self.spread(), self.gate_min_rel * med)
        return abs(scale - med) <= band

    def _run_says_window_is_wrong(self) -> bool:
        """A run of gated samples long enough (``min_samples`` and a third of the window in stamp
        time) and consistent enough (robust spread within half the gate's relative floor) to say
        the window locked on a bad start, not that a passing disturbance (an occluder, a step) is
        gated as it should be."""
        run = self._gated_run
        if len(run) < self.min_samples or run[-1][0] - run[0][0] < self.window_ns // 3:
            return False
        values = np.array([v for _, v in run])
        med = float(np.median(values))
        spread = MAD_TO_SIGMA * float(np.median(np.abs(values - med)))
        return spread <= 0.5 * max(self.gate_min_rel, 1e-3) * med

    def _evict(self, stamp_ns: int) -> None:
        horizon = stamp_ns - self.window_ns
        while self._fifo and self._fifo[0][0] < horizon:
            self._drop_oldest()
        while self._gated_run and self._gated_run[0][0] < horizon:
            self._gated_run.pop(0)

    def _drop_oldest(self) -> None:
        self._fifo.popleft()
        self._stats = None

    def _relock(self) -> None:
        run = list(self._gated_run)
        self.reset()
        self.relocks += 1
        self._fifo.extend(run)


def log_trend(stamps_ns: np.ndarray, scales: np.ndarray) -> tuple[float, float, int] | None:
    """The drift of a window's samples, or None when it looks constant (module docstring).

    stamps_ns: (n,) int, increasing; scales: (n,) metres per SLAM unit, positive. Returns (log scale
    at the newest stamp, slope in log scale per ns, the newest stamp).
    """
    n = len(stamps_ns)
    if n < TREND_BINS * TREND_MIN_PER_BIN:
        return None
    ref = int(stamps_ns[-1])
    t = (stamps_ns - ref).astype(np.float64)  # <= 0, ns
    y = np.log(scales)
    span = -t[0]
    if span <= 0.0:
        return None
    edges = np.searchsorted(t, np.linspace(t[0], 0.0, TREND_BINS + 1)[1:-1])
    centres, levels = [], []
    for a, b in zip([0, *edges.tolist()], [*edges.tolist(), n]):
        if b - a >= TREND_MIN_PER_BIN:
            centres.append(float(np.median(t[a:b])))
            levels.append(float(np.median(y[a:b])))
    if len(centres) < 3:
        return None
    tc, yc = np.array(centres), np.array(levels)
    i, j = np.triu_indices(len(tc), 1)
    slope = float(np.median((yc[j] - yc[i]) / (tc[j] - tc[i])))  # Theil-Sen over the bin medians
    level = float(np.median(yc - slope * tc))
    # the slope's standard error from the bin medians' scatter about the line: consecutive
    # samples are correlated (the same geometry, a slowly wandering HMR bias), bins much less so
    residual = yc - (level + slope * tc)
    sigma = MAD_TO_SIGMA * float(np.median(np.abs(residual - np.median(residual))))
    error = sigma / max(math.sqrt(float(np.sum((tc - tc.mean()) ** 2))), 1e-300)
    if abs(slope) <= DRIFT_Z * error or abs(slope) * span <= DRIFT_MIN_REL:
        return None
    return level, slope, ref


def sequence_scale(samples: np.ndarray) -> float:
    """The paper's offline estimate: the median of every per-frame scale of the sequence."""
    samples = np.asarray(samples, dtype=float)
    samples = samples[np.isfinite(samples) & (samples > 0)]
    return float(np.median(samples)) if samples.size else float('nan')
