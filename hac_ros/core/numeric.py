"""Constants the core shares: robust statistics of normal samples, and nanoseconds per second
(stamps are integer nanoseconds everywhere)."""
from __future__ import annotations

# normal samples: sigma per unit of median absolute deviation, and the standard error of a median
# of n samples, MEDIAN_STD_ERROR * sigma / sqrt(n)
MAD_TO_SIGMA = 1.4826
MEDIAN_STD_ERROR = 1.2533
NS = 1_000_000_000  # nanoseconds per second
