"""The streaming median of the estimator's window: its values kept sorted as they come and go.

A value comes in by binary insertion and goes by binary search (``bisect``: a memmove of at most
``window_max_samples`` floats), so the median is read in O(1) and the median absolute deviation
(MAD) in O(log² n): the deviations from the median are two sorted runs (the values below it read
downwards, those above it read upwards), and the k-th smallest of two sorted runs is found by
bisection. Both equal numpy's ``np.median(values)`` and ``np.median(np.abs(values - median))``
exactly (the same subtractions and the same mean of the two middle values), which the tests
check.

Each value also carries a weight (the stamp time its sample covers: docs/method.md, "The
estimator"), kept beside it in the same order, so that a burst of repeated frames counts for the
stamp time it spans, not for its number. :meth:`SortedWindow.weighted_median` is the first value
at which the cumulative weight reaches half the total (the mean of it and the next one when half
falls on their boundary, so that equal weights give the median). It is kept up to date as values
come and go: its index and the weight below it move by the few places a change shifts them, and
the running sums are summed afresh (``math.fsum``) every REFRESH_CHANGES changes so that rounding
never accumulates.

Pure Python floats; the values are scales, metres per SLAM unit (any finite floats work); the
weights positive floats (seconds).
"""
from __future__ import annotations

import bisect
import math

from hac_ros.core.estimate.stamp_weights import TIE_REL

REFRESH_CHANGES = 1024  # the running weight sums are summed afresh this often


class SortedWindow:
    """A multiset of weighted floats with its median, MAD and weighted median (module
    docstring)."""

    def __init__(self) -> None:
        self._values: list[float] = []
        self._weights: list[float] = []  # the weight of each value, in the same (sorted) order
        self.clear()

    def __len__(self) -> int:
        return len(self._values)

    def add(self, value: float, weight: float = 1.0) -> None:
        """Add ``value`` with ``weight`` (> 0)."""
        i = bisect.bisect_right(self._values, value)
        self._values.insert(i, value)
        self._weights.insert(i, weight)
        if i <= self._k and len(self._values) > 1:  # before the weighted median: below it
            self._k += 1
            self._below += weight
        self._changed(weight, 1.0)

    def remove(self, value: float, weight: float = 1.0) -> None:
        """Remove one occurrence of ``value`` with ``weight`` (ValueError when there is none)."""
        i = bisect.bisect_left(self._values, value)
        end = bisect.bisect_right(self._values, value, lo=i)
        for k in range(i, end):
            if self._weights[k] == weight:
                del self._values[k]
                del self._weights[k]
                if k < self._k:
                    self._k -= 1
                    self._below -= weight
                self._changed(weight, -1.0)
                return
        raise ValueError(f'{value!r} (weight {weight!r}) is not in the window')

    def clear(self) -> None:
        self._values.clear()
        self._weights.clear()
        self._k = 0  # the index of the weighted median ...
        self._below = 0.0  # ... and the weight of the values before it
        self._total = self._squares = 0.0  # the sum of the weights, and of their squares
        self._changes = 0

    def scale_values(self, factor: float) -> None:
        """Every value times ``factor`` (> 0: the order and the weights stay)."""
        self._values = [v * factor for v in self._values]

    def shift_values(self, offset: float) -> None:
        """Every value plus ``offset`` (the order and the weights stay)."""
        self._values = [v + offset for v in self._values]

    @property
    def total_weight(self) -> float:
        return self._total

    def effective_count(self) -> float:
        """(Σw)² / Σw²: the number of equal-weight values the window is worth (0 when empty)."""
        return self._total ** 2 / self._squares if self._squares > 0.0 else 0.0

    def weighted_median(self) -> float:
        """The first value at which the cumulative weight reaches half the total (within
        TIE_REL of it); the mean of it and the next one when half falls on their boundary (equal
        weights: :meth:`median`); NaN when empty."""
        v, w, n = self._values, self._weights, len(self._values)
        if not n:
            return math.nan
        half, tie = 0.5 * self._total, TIE_REL * self._total
        self._k = min(self._k, n - 1)
        while self._k > 0 and self._below >= half - tie:  # the smallest k whose cumulative
            self._k -= 1  # weight reaches half
            self._below -= w[self._k]
        while self._k < n - 1 and self._below + w[self._k] < half - tie:
            self._below += w[self._k]
            self._k += 1
        k = self._k
        if k + 1 < n and abs(self._below + w[k] - half) <= tie:
            return (v[k] + v[k + 1]) / 2.0
        return v[k]

    def _changed(self, weight: float, sign: float) -> None:
        self._total += sign * weight
        self._squares += sign * weight * weight
        self._changes += 1
        if self._changes >= REFRESH_CHANGES or not self._values:
            self._changes = 0
            self._k = min(self._k, max(len(self._values) - 1, 0))
            self._below = math.fsum(self._weights[:self._k])
            self._total = math.fsum(self._weights)
            self._squares = math.fsum(x * x for x in self._weights)

    def median(self) -> float:
        """The median (the mean of the two middle values for an even count; NaN when empty)."""
        v, n = self._values, len(self._values)
        if not n:
            return math.nan
        return v[n // 2] if n % 2 else (v[n // 2 - 1] + v[n // 2]) / 2.0

    def mad(self) -> float:
        """The median of the absolute deviations from :meth:`median` (NaN when empty)."""
        v, n = self._values, len(self._values)
        if not n:
            return math.nan
        m = self.median()
        split = bisect.bisect_left(v, m)  # v[:split] < m <= v[split:]

        def below(i: int) -> float:  # the i-th smallest deviation of the values below m
            return m - v[split - 1 - i]

        def above(j: int) -> float:  # the j-th smallest deviation of the values at or above m
            return v[split + j] - m

        def kth(k: int) -> float:  # the k-th smallest deviation (0-based) of both runs
            a, b = split, n - split
            lo, hi = max(0, k + 1 - b), min(k + 1, a)  # how many of the k + 1 come from below
            while lo < hi:
                i = (lo + hi) // 2
                if below(i) < above(k - i):  # the (i + 1)-th from below is among the k + 1
                    lo = i + 1
                else:
                    hi = i
            last_below = below(lo - 1) if lo > 0 else -math.inf
            last_above = above(k - lo) if k + 1 - lo > 0 else -math.inf
            return max(last_below, last_above)

        return kth(n // 2) if n % 2 else (kth(n // 2 - 1) + kth(n // 2)) / 2.0
