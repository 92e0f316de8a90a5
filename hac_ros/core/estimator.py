"""The scale estimator: a rolling window of per-frame samples with a streaming median, and a
robust state-space filter on the log scale that says whether, and how fast, the scale drifts
(docs/method.md, "The estimator").

**The window.** The per-frame scales of the last ``window_s`` stamp seconds (at most
``window_max_samples``) in arrival order, and the same kept sorted
(:class:`hac_ros.core.sorted_window.SortedWindow`): their median and median absolute deviation
(MAD) are read from it when the window has changed, and kept until it changes again. The median
is the robust level while the scale holds still, and the gate's reference: once the window holds
``min_samples``, a sample further than ``gate_k`` robust sigmas from the median (and than
``gate_min_rel`` of it) is gated out.

**The filter** (:class:`hac_ros.core.scale_filter.LogScaleFilter`) is fed every accepted sample
itself, never a window statistic: its level and rate, its noise measured on the samples, the
probability ``p`` that the scale drifts. The estimate now is the two models weighed by that
probability, in log scale: ``m = (1 - p) m0 + p m1`` with ``m0`` the window's median and ``m1``
the filter's level; its variance ``(1 - p) V0 + p V1 + p (1 - p) (m1 - m0)²``, ``V0`` that of the
median (1.2533² × the mean's variance under the measured noise), ``V1`` the filter's. The ``±``
(:meth:`RollingScale.spread`) is that standard deviation times the scale: the estimator's own
uncertainty, not the unobservable HMR or contact-height bias (docs/method.md, identifiability).
**Converged** = at least ``min_samples`` samples and a relative uncertainty under
``converged_max_rel_sigma``. **Drifting** = ``p`` above DRIFT_EVIDENCE.

**Re-lock.** Gated samples in a row say the window may be wrong: from RELOCK_WARN_SAMPLES of
them, or one RELOCK_WARN_S after the last accepted sample (one sample at 1 Hz), or from the moment
a new map says its scale changed (:meth:`RollingScale.map_changed`),
:attr:`RollingScale.relocking` holds and the status WARNs until a sample is accepted. The window
re-locks on the run (it is dropped and refilled with the run's samples, the filter restarted on
them) when the run holds ``min_samples`` samples consistent among themselves (robust spread within
half the gate's relative floor) and either began after a new map whose floor says it has
another scale came into use (:meth:`RollingScale.map_changed`: a SLAM that re-initialised
quietly, same frame, no pose jump) or has lasted a third of the window (a window that locked on
a bad start; a passing disturbance, a walker on a flight of stairs, does not last that long).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from hac_ros.core.numeric import MAD_TO_SIGMA, MEDIAN_STD_ERROR, NS
from hac_ros.core.scale_filter import LogScaleFilter
from hac_ros.core.sorted_window import SortedWindow

DRIFT_EVIDENCE = 0.999  # the drift probability above which the scale is said to drift
RELOCK_WARN_SAMPLES = 2  # gated samples in a row that WARN (one could be an outlier) ...
RELOCK_WARN_S = 0.5  # ... or one whose stamp is this long after the last accepted sample
RELOCK_FALLBACK_WINDOW_SHARE = 1.0 / 3.0  # a run this long re-locks without a new map


@dataclass(frozen=True)
class Estimate:
    """The estimate at one stamp: ``scale`` metres per SLAM unit, ``rel_sigma`` its relative
    uncertainty (standard deviation of the log scale; inf before the filter starts),
    ``drift`` the probability that the scale drifts."""

    scale: float
    rel_sigma: float
    drift: float


class RollingScale:
    """Per-frame scale samples in, a causal estimate and its uncertainty out (module
    docstring)."""

    def __init__(self, window_s: float, window_max_samples: int, min_samples: int,
                 gate_k: float = 5.0, gate_min_rel: float = 0.15,
                 converged_max_rel_sigma: float = 0.01) -> None:
        self.window_ns = int(round(window_s * NS))
        self.max_samples = int(window_max_samples)
        self.min_samples = int(min_samples)
        self.gate_k = float(gate_k)
        self.gate_min_rel = float(gate_min_rel)
        self.max_rel_sigma = float(converged_max_rel_sigma)
        self._fifo: deque[tuple[int, float]] = deque()  # (stamp_ns, scale) in arrival order
        self._sorted = SortedWindow()  # the same scales, sorted: the streaming median
        self._gated_run: list[tuple[int, float]] = []
        self._accepted_ns = -1  # the stamp of the last accepted sample
        self._map_rescaled = False  # a new map says it has another scale (map_changed)
        self.relocks = 0
        self._stats: tuple[float, float] | None = None  # (median, MAD), until the window changes
        self._now_ns = -1  # the newest stamp seen (a sample or advance)
        self.filter = LogScaleFilter(self.window_ns, self.max_samples)
        self._estimate: tuple[tuple[int, int], Estimate] | None = None
        self._version = 0  # counts changes of the window and the filter

    # ------------------------------------------------------------------ updates
    def add(self, stamp_ns: int, scale: float) -> bool:
        """Add one sample (stamp in ns, scale in metres per SLAM unit); False if it was gated.

        Non-finite or non-positive samples are never added (the caller counts them).
        """
        if not (math.isfinite(scale) and scale > 0.0):
            return False
        self._now_ns = max(self._now_ns, int(stamp_ns))
        self._evict(stamp_ns)
        if len(self._fifo) >= self.min_samples and not self._within_gate(scale):
            self._gated_run.append((int(stamp_ns), scale))
            if self._run_says_window_is_wrong():
                self._relock()
            return False
        self._gated_run.clear()
        self._map_rescaled = False
        self._accepted_ns = int(stamp_ns)
        self._fifo.append((int(stamp_ns), scale))
        self._sorted.add(scale)
        self._stats = None
        self._version += 1
        if len(self._fifo) > self.max_samples:
            self._drop_oldest()
        if self.filter.started:
            self.filter.update(int(stamp_ns), math.log(scale), math.log(self.median()))
        elif len(self._fifo) >= self.min_samples:
            self.filter.start([s for s, _ in self._fifo], [math.log(v) for _, v in self._fifo])
        return True

    def advance(self, stamp_ns: int) -> None:
        """Let stamp time pass without a sample (evicts what fell out of the window)."""
        self._now_ns = max(self._now_ns, int(stamp_ns))
        self._evict(stamp_ns)

    def map_changed(self, rescaled: bool = False) -> None:
        """A new map came into use (same segment, the calibrator's stamp time). ``rescaled``: the
        map itself says its scale changed (the camera's height above its floor): a run of gated
        samples in progress belongs to the old map and is dropped, :attr:`relocking` holds from
        now until a sample is accepted, and the window re-locks on the samples that follow once
        they hold ``min_samples`` (module docstring, re-lock)."""
        if rescaled and not self._map_rescaled:
            self._gated_run.clear()
            self._map_rescaled = True

    def reset(self) -> None:
        """Forget everything (SLAM re-initialisation: the new map has a new scale)."""
        self._fifo.clear()
        self._sorted.clear()
        self._gated_run.clear()
        self._map_rescaled = False
        self._stats = None
        self.filter = LogScaleFilter(self.window_ns, self.max_samples)
        self._version += 1

    # ------------------------------------------------------------------ queries
    @property
    def samples(self) -> int:
        return len(self._fifo)

    @property
    def converged(self) -> bool:
        """At least ``min_samples`` samples and a relative uncertainty under
        ``converged_max_rel_sigma``."""
        return (len(self._fifo) >= self.min_samples
                and self.estimate().rel_sigma < self.max_rel_sigma)

    @property
    def relocking(self) -> bool:
        """Gated samples in a row say the window may be wrong (module docstring)."""
        run = self._gated_run
        if len(self._fifo) < self.min_samples:
            return False
        return self._map_rescaled or (bool(run) and (
            len(run) >= RELOCK_WARN_SAMPLES
            or run[-1][0] - self._accepted_ns >= RELOCK_WARN_S * NS))

    @property
    def drifting(self) -> bool:
        """The evidence says the scale drifts (its probability above DRIFT_EVIDENCE)."""
        return self.estimate().drift > DRIFT_EVIDENCE

    def median(self) -> float:
        """The window's median, metres per SLAM unit (NaN when empty)."""
        return self._median_and_mad()[0]

    def current(self) -> float:
        """The scale now, metres per SLAM unit (NaN when empty; module docstring)."""
        return self.estimate().scale

    def spread(self) -> float:
        """The estimate's standard deviation, metres per SLAM unit (inf before the filter has
        started, NaN when empty): its own uncertainty, without the unobservable biases."""
        estimate = self.estimate()
        return estimate.scale * estimate.rel_sigma

    def estimate(self) -> Estimate:
        """The estimate at the newest stamp (module docstring), kept until a sample or stamp time
        changes it."""
        key = (self._now_ns, self._version)
        if self._estimate is None or self._estimate[0] != key:
            self._estimate = (key, self._compute())
        return self._estimate[1]

    def mad(self) -> float:
        """Median absolute deviation from the median, metres per SLAM unit (NaN when empty)."""
        return self._median_and_mad()[1]

    def sample_spread(self) -> float:
        """Robust sigma of the window's samples (1.4826 MAD), metres per SLAM unit."""
        return MAD_TO_SIGMA * self.mad()

    def values(self) -> np.ndarray:
        """The window's samples in arrival order (for tests and plots)."""
        return np.array([v for _, v in self._fifo], dtype=float)

    # ------------------------------------------------------------------ internals
    def _compute(self) -> Estimate:
        median = self.median()
        if not self.filter.started or not math.isfinite(median):
            return Estimate(median, math.inf, 0.0)
        n = len(self._fifo)
        span_s = (self._fifo[-1][0] - self._fifo[0][0]) / NS
        now_ns = max(self._now_ns, self.filter.stamp_ns or 0)
        m0 = math.log(median)
        v0 = MEDIAN_STD_ERROR ** 2 * self.filter.mean_variance(n, span_s)
        m1, v1 = self.filter.level_at(now_ns)
        p = self.filter.drift()
        mean = (1.0 - p) * m0 + p * m1
        variance = (1.0 - p) * v0 + p * v1 + p * (1.0 - p) * (m1 - m0) ** 2
        return Estimate(math.exp(mean), math.sqrt(max(variance, 0.0)), p)

    def _median_and_mad(self) -> tuple[float, float]:
        if self._stats is None:
            if not self._fifo:
                return math.nan, math.nan
            self._stats = self._sorted.median(), self._sorted.mad()
        return self._stats

    def _within_gate(self, scale: float) -> bool:
        med = self.median()
        band = max(self.gate_k * self.sample_spread(), self.gate_min_rel * med)
        return abs(scale - med) <= band

    def _run_says_window_is_wrong(self) -> bool:
        """A run of gated samples long enough (``min_samples``, and begun after a new map came
        into use or a third of the window long in stamp time) and consistent enough (robust
        spread within half the gate's relative floor) to say the window is wrong, not that a
        passing disturbance (an occluder, a step) is gated as it should be."""
        run = self._gated_run
        if len(run) < self.min_samples:
            return False
        if not self._map_rescaled and (run[-1][0] - run[0][0]
                                       < RELOCK_FALLBACK_WINDOW_SHARE * self.window_ns):
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
        self._sorted.remove(self._fifo.popleft()[1])
        self._stats = None
        self._version += 1

    def _relock(self) -> None:
        run = list(self._gated_run)
        self.reset()
        self.relocks += 1
        self._fifo.extend(run)
        for _, scale in run:
            self._sorted.add(scale)
        if len(run) >= self.min_samples:
            self.filter.start([s for s, _ in run], [math.log(v) for _, v in run])


def sequence_scale(samples: np.ndarray) -> float:
    """The paper's offline estimate: the median of every per-frame scale of the sequence."""
    samples = np.asarray(samples, dtype=float)
    samples = samples[np.isfinite(samples) & (samples > 0)]
    return float(np.median(samples)) if samples.size else float('nan')
