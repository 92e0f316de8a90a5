"""Constants the core shares: robust statistics of normal samples, and nanoseconds per second
(stamps are integer nanoseconds everywhere); the median of a few values."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

# normal samples: sigma per unit of median absolute deviation, and the standard error of a median
# of n samples, MEDIAN_STD_ERROR * sigma / sqrt(n)
MAD_TO_SIGMA = 1.4826
MEDIAN_STD_ERROR = 1.2533
NS = 1_000_000_000  # nanoseconds per second


def median_of(values: Any) -> float:
    """The median of every value (flattened), equal to ``float(np.median(values))``: NaN when any
    value is NaN or there is none.

    A sort and an index: np.median's generality costs about ten times more on the few dozen
    values the core takes the median of several times per frame (docs/benchmarks.md, replay).
    """
    ordered = np.sort(np.asarray(values, dtype=np.float64), axis=None)
    n = ordered.size
    if n == 0 or math.isnan(ordered[-1]):  # NaN sorts last
        return math.nan
    half = n // 2
    if n % 2:
        return float(ordered[half])
    return 0.5 * (float(ordered[half - 1]) + float(ordered[half]))
