"""The streaming median of the estimator's window: its values kept sorted as they come and go.

A value comes in by binary insertion and goes by binary search (``bisect``: a memmove of at most
``window_max_samples`` floats), so the median is read in O(1) and the median absolute deviation
(MAD) in O(log² n): the deviations from the median are two sorted runs (the values below it read
downwards, those above it read upwards), and the k-th smallest of two sorted runs is found by
bisection. Both equal numpy's ``np.median(values)`` and ``np.median(np.abs(values - median))``
exactly (the same subtractions and the same mean of the two middle values), which the tests
check.

Pure Python floats; the values are scales, metres per SLAM unit (any finite floats work).
"""
from __future__ import annotations

import bisect
import math


class SortedWindow:
    """A multiset of floats with its median and MAD (module docstring)."""

    def __init__(self) -> None:
        self._values: list[float] = []

    def __len__(self) -> int:
        return len(self._values)

    def add(self, value: float) -> None:
        bisect.insort(self._values, value)

    def remove(self, value: float) -> None:
        """Remove one occurrence of ``value`` (ValueError when there is none)."""
        i = bisect.bisect_left(self._values, value)
        if i == len(self._values) or self._values[i] != value:
            raise ValueError(f'{value!r} is not in the window')
        del self._values[i]

    def clear(self) -> None:
        self._values.clear()

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
