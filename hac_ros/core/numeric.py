"""Small numeric helpers for the per-frame path (numpy's generic versions cost tens of µs here)."""
from __future__ import annotations

import numpy as np


def median_1d(values: np.ndarray) -> float:
    """The median of a non-empty 1-D float array, as ``np.median`` gives it (finite values).

    One ``np.partition`` and no axis or NaN bookkeeping: ~4x faster than ``np.median`` on the
    few hundred values of a ray's cone. NaN for an empty array.
    """
    n = values.size
    if n == 0:
        return float('nan')
    if n == 1:
        return float(values[0])
    half = n // 2
    if n % 2:
        return float(np.partition(values, half)[half])
    part = np.partition(values, (half - 1, half))
    return 0.5 * (float(part[half - 1]) + float(part[half]))
