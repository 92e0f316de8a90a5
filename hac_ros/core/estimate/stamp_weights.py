"""What a sample weighs: the stamp time it covers (docs/method.md, "The estimator").

A per-frame sample stands for the stamp time since the previous sampled frame (the samples of one
frame share it), at most WEIGHT_CAP_S (a gap in the samples tells nothing), at least
WEIGHT_MIN_S, in steps of WEIGHT_QUANTUM_S so that a stream's nanosecond jitter weighs alike. A
frame resent a hundred times within a tenth of a second then counts for that tenth of a second,
not for a hundred frames: the window's median (hac_ros.core.estimate.sorted_window), the noise
(hac_ros.core.estimate.scale_filter) and the offline level (hac_ros.core.estimate.segment) all
weigh samples so.

Pure numpy; stamps int nanoseconds, weights seconds.
"""
from __future__ import annotations

import numpy as np

from hac_ros.core.basics.numeric import NS

WEIGHT_CAP_S = 1.0  # a sample weighs the stamp time it covers, at most this, ...
WEIGHT_MIN_S = 1e-3  # ... at least this (a stream's first sample online), ...
WEIGHT_QUANTUM_S = 1e-4  # ... in steps of this
TIE_REL = 1e-9  # half the weight within this share of the total of a boundary: on it


def gap_weights(gaps_s: np.ndarray) -> np.ndarray:
    """The weights of samples whose frames cover ``gaps_s`` seconds of stamp time (any shape):
    clipped to [WEIGHT_MIN_S, WEIGHT_CAP_S], rounded to WEIGHT_QUANTUM_S."""
    clipped = np.clip(gaps_s, WEIGHT_MIN_S, WEIGHT_CAP_S)
    return np.round(clipped / WEIGHT_QUANTUM_S) * WEIGHT_QUANTUM_S


def sample_weight(gap_s: float) -> float:
    """The weight of one sample whose frame covers ``gap_s`` seconds (:func:`gap_weights`)."""
    return float(gap_weights(np.float64(gap_s)))


def stamp_weights(stamps_ns: np.ndarray) -> np.ndarray:
    """Each sample's weight, seconds (:func:`gap_weights` of the time since the previous sampled
    frame; the first frame weighs as much as the second). stamps_ns (n,) sorted int."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    frames, inverse = np.unique(stamps, return_inverse=True)
    gaps = np.diff(frames) / NS
    gaps = np.r_[gaps[:1] if len(gaps) else [WEIGHT_CAP_S], gaps]
    return gap_weights(gaps)[inverse]


def weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    """The value at which the cumulative weight of the sorted values reaches half the total
    (within TIE_REL of it; the mean of two neighbours when half falls on their boundary: equal
    weights give the median). values, weights (n,), n >= 1."""
    order = np.argsort(values, kind='stable')
    v, cumulative = values[order], np.cumsum(weights[order])
    half = 0.5 * cumulative[-1]
    tie = TIE_REL * cumulative[-1]
    k = min(int(np.searchsorted(cumulative, half - tie)), len(v) - 1)
    if k + 1 < len(v) and abs(cumulative[k] - half) <= tie:
        return float((v[k] + v[k + 1]) / 2.0)
    return float(v[k])
