"""The scale estimator: a rolling window in stamp time with a streaming median (SPEC, method step 5).

The paper takes one median over a whole video. Online we keep the per-frame scales of the last
``window_s`` stamp seconds (at most ``window_max_samples``) in a sorted container, so that adding or
evicting a sample costs O(log n) and the median is an index lookup: the window is never re-sorted.
The robust spread is the median absolute deviation (MAD), found in O(log² n) by selecting the k-th
smallest of the two sorted runs of deviations on either side of the median.

Once converged (``min_samples``), a sample further than ``gate_k`` robust sigmas from the median
(and than ``gate_min_rel`` of it) is gated out. If gated samples keep coming in a row for a third
of the window (and at least ``min_samples``), consistent among themselves, the window was wrong
(it locked on a bad start) and the estimator re-locks on them.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from sortedcontainers import SortedList

MAD_TO_SIGMA = 1.4826  # sigma of a normal distribution per unit of MAD


@dataclass
class Estimate:
    """scale: metres per SLAM unit (NaN when empty); spread: 1.4826 MAD of the window, same unit."""

    scale: float
    spread: float
    samples: int
    converged: bool


class RollingScale:
    """Per-frame scale samples in, a causal robust scale estimate out."""

    def __init__(self, window_s: float, window_max_samples: int, min_samples: int,
                 gate_k: float = 5.0, gate_min_rel: float = 0.15) -> None:
        self.window_ns = int(round(window_s * 1e9))
        self.max_samples = int(window_max_samples)
        self.min_samples = int(min_samples)
        self.gate_k = float(gate_k)
        self.gate_min_rel = float(gate_min_rel)
        self._fifo: deque[tuple[int, float]] = deque()  # (stamp_ns, scale) in arrival order
        self._sorted: SortedList = SortedList()
        self._gated_run: list[tuple[int, float]] = []
        self.relocks = 0
        self._mad_cache: float | None = None  # valid until the window changes

    # ------------------------------------------------------------------ updates
    def add(self, stamp_ns: int, scale: float) -> bool:
        """Add one sample (stamp in ns, scale in metres per SLAM unit); False if it was gated.

        Non-finite or non-positive samples are never added (the caller counts them).
        """
        if not (math.isfinite(scale) and scale > 0.0):
            return False
        self._evict(stamp_ns)
        if self.converged and not self._within_gate(scale):
            self._gated_run.append((stamp_ns, scale))
            if self._run_says_window_is_wrong():
                self._relock()
            return False
        self._gated_run.clear()
        self._fifo.append((stamp_ns, scale))
        self._sorted.add(scale)
        self._mad_cache = None
        if len(self._fifo) > self.max_samples:
            self._drop_oldest()
        return True

    def advance(self, stamp_ns: int) -> None:
        """Let stamp time pass without a sample (evicts what fell out of the window)."""
        self._evict(stamp_ns)

    def reset(self) -> None:
        """Forget everything (SLAM re-initialisation: the new map has a new scale)."""
        self._fifo.clear()
        self._sorted.clear()
        self._gated_run.clear()
        self._mad_cache = None

    # ------------------------------------------------------------------ queries
    @property
    def samples(self) -> int:
        return len(self._sorted)

    @property
    def converged(self) -> bool:
        return len(self._sorted) >= self.min_samples

    def median(self) -> float:
        n = len(self._sorted)
        if n == 0:
            return float('nan')
        if n % 2:
            return float(self._sorted[n // 2])
        return 0.5 * (self._sorted[n // 2 - 1] + self._sorted[n // 2])

    def mad(self) -> float:
        """Median absolute deviation from the median, O(log² n), without copying the window."""
        if self._mad_cache is None:
            self._mad_cache = self._mad()
        return self._mad_cache

    def _mad(self) -> float:
        n = len(self._sorted)
        if n == 0:
            return float('nan')
        med = self.median()
        split = self._sorted.bisect_left(med)
        if n % 2:
            return float(_kth_deviation(self._sorted, split, med, n // 2))
        lo = _kth_deviation(self._sorted, split, med, n // 2 - 1)
        hi = _kth_deviation(self._sorted, split, med, n // 2)
        return 0.5 * (lo + hi)

    def spread(self) -> float:
        """Robust sigma of the samples (1.4826 MAD), metres per SLAM unit."""
        return MAD_TO_SIGMA * self.mad()

    def estimate(self) -> Estimate:
        return Estimate(self.median(), self.spread(), self.samples, self.converged)

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
        _, value = self._fifo.popleft()
        self._sorted.remove(value)
        self._mad_cache = None

    def _relock(self) -> None:
        run = self._gated_run
        self.reset()
        self.relocks += 1
        for stamp_ns, value in run:
            self._fifo.append((stamp_ns, value))
            self._sorted.add(value)
        self._mad_cache = None


def _kth_deviation(values: SortedList, split: int, med: float, k: int) -> float:
    """The k-th smallest (0-based) of |v - med| over sorted ``values``.

    ``values[:split]`` are < med, so their deviations grow leftwards; ``values[split:]`` grow
    rightwards. Selecting the k-th of two sorted sequences takes O(log n) probes (binary search on
    how many come from the left run), each an O(log n) SortedList index.
    """
    n_left, n_right = split, len(values) - split

    def left(i: int) -> float:  # i-th smallest deviation on the left
        return med - values[split - 1 - i]

    def right(i: int) -> float:
        return values[split + i] - med

    # number taken from the left run: a in [max(0, k+1-n_right), min(k+1, n_left)]
    lo, hi = max(0, k + 1 - n_right), min(k + 1, n_left)
    while lo < hi:
        a = (lo + hi) // 2
        b = k + 1 - a  # taken from the right
        # too few from the left if the next left element is smaller than the last right one
        if b > 0 and a < n_left and left(a) < right(b - 1):
            lo = a + 1
        else:
            hi = a
    a = lo
    b = k + 1 - a
    candidates = []
    if a > 0:
        candidates.append(left(a - 1))
    if b > 0:
        candidates.append(right(b - 1))
    return max(candidates)


def sequence_scale(samples: np.ndarray) -> float:
    """The paper's offline estimate: the median of every per-frame scale of the sequence."""
    samples = np.asarray(samples, dtype=float)
    samples = samples[np.isfinite(samples) & (samples > 0)]
    return float(np.median(samples)) if samples.size else float('nan')


def centred_rolling_median(stamps_ns: np.ndarray, samples: np.ndarray, query_ns: np.ndarray,
                           window_s: float) -> np.ndarray:
    """Offline: at each query stamp, the median of the samples within ±window_s/2 (non-causal).

    stamps_ns: (N,) int sample stamps; samples: (N,) metres per SLAM unit; query_ns: (M,) int.
    Returns (M,) float; where a window holds no sample, the nearest sample's window is used.
    """
    order = np.argsort(stamps_ns, kind='stable')
    stamps_ns = np.asarray(stamps_ns)[order]
    samples = np.asarray(samples, dtype=float)[order]
    half = int(window_s * 0.5e9)
    lo = np.searchsorted(stamps_ns, np.asarray(query_ns) - half, side='left')
    hi = np.searchsorted(stamps_ns, np.asarray(query_ns) + half, side='right')
    out = np.full(len(query_ns), np.nan)
    for i, (a, b) in enumerate(zip(lo, hi)):
        if b > a:
            out[i] = np.median(samples[a:b])
        elif len(samples):
            j = min(max(a, 0), len(samples) - 1)
            k0, k1 = np.searchsorted(stamps_ns, [stamps_ns[j] - half, stamps_ns[j] + half])
            out[i] = np.median(samples[k0:max(k1, k0 + 1)])
    return out
