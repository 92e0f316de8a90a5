"""The scale estimator: a rolling window of per-frame samples with a streaming median, a robust
state-space filter on the log scale that says whether, and how fast, the scale drifts, and the
checks that say whether the evidence still backs the estimate (docs/method.md, "The estimator").

**The window.** The per-frame scales of the latest ``window_s`` stamp seconds of samples (at most
``window_max_samples``), each weighing the stamp time it covers
(hac_ros.core.estimate.stamp_weights: a burst of repeated frames counts for the time it spans), kept
sorted (:class:`hac_ros.core.estimate.sorted_window.SortedWindow`): their weighted median is the
robust level while the scale holds still, and the gate's reference: once the window holds
``min_samples``, a sample further than ``gate_k`` robust sigmas from it (and than ``gate_min_rel``
of it) is gated out. The window keeps its newest samples however old they grow: their age is a doubt
of its own (below).

**The filter** (:class:`hac_ros.core.estimate.scale_filter.LogScaleFilter`) is fed every accepted
sample itself: its level and rate, its noise measured on the samples, the probability ``p`` that the
scale drifts. The estimate is the two models weighed by that probability, in log scale:
``m = (1 - p) m0 + p m1``, ``m0`` the window's median, ``m1`` the filter's level now; the variance
of its core ``V = (1 - p) V0 + p V1 + p (1 - p) (m1 - m0)²``, ``V0`` that of the median
(1.2533² × the mean's variance under the noise measured about a constant level, with the window's
effective count of samples and the stamp time they cover), ``V1`` the filter's.

**The map's word** (:meth:`RollingScale.map_changed`): a new map measured against the one before
(hac_ros.core.geometry.reference.MapIndex.rescale_against) that says the scale changed beyond
MAP_RESCALE_MIN and MAP_RESCALE_Z of its standard error rescales every sample kept, so the
estimate follows the map at once; beyond ``converged_max_rel_sigma`` :attr:`map_rescaled` holds
until a later map says the scale holds still.

**The doubts.** The estimator's own relative uncertainty σ_stat (:attr:`Estimate.rel_sigma`) is the
core's √V with three doubts added in quadrature, each also a reason the status names:

- *age* (``unverified``): the drift the filter's prior allows since the newest accepted sample,
  STALE_RATE × its age: nobody in view, empty joints frames or a joints gap leave an estimate
  that nothing checks; ``unverified`` once that exceeds ``converged_max_rel_sigma``;
- *gap* (``relocking``, ``map_rescaled``): while gated samples say the scale changed (below), the
  distance between the estimate and their median; while a map said so, the size of its step;
- *lag* (``lagging``): the recent samples (LAG_S of stamp time, covering at least
  LAG_MIN_COVER_S) disagree with the estimate beyond LAG_Z of their standard error (under the
  noise measured before them) and half of ``converged_max_rel_sigma``: the scale changes faster
  than the window and the filter follow.

**Converged** (with hysteresis, on the core alone): at least ``min_samples`` samples and √V under
``converged_max_rel_sigma``; it is lost above LOSE_FACTOR times that. **Publishing**: from a
segment's first convergence until :meth:`RollingScale.reset` (a SLAM re-initialisation), whatever
the later doubts, which the uncertainty carries, or :meth:`RollingScale.restart` (its samples
judged wrong). **Drifting** = ``p`` above DRIFT_EVIDENCE.

**Re-lock.** Gated samples in a row (an accepted sample ends the run) say the scale changed only
with evidence: a run that began after a map said the scale changed (:meth:`map_changed`), or
while the estimate was ``unverified`` (nobody checked it meanwhile) or
``lagging`` the same way (the samples were already moving), or a run that lasts RELOCK_WARN_S and
RELOCK_WARN_SAMPLES samples: then :attr:`RollingScale.relocking` holds and the status WARNs. A
passing disturbance (a walker on a flight of stairs, an occluder, one person of a crowd) is gated
and counted, never more. The window re-locks on the run (it is dropped and refilled with the run's
samples, the filter restarted on them) once the run holds ``min_samples`` samples consistent among
themselves (robust spread within half the gate's relative floor) and has that evidence, or has
lasted a third of the window (a window that locked on a bad start).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hac_ros.core.basics.numeric import MAD_TO_SIGMA, MEDIAN_STD_ERROR, NS, median_of
from hac_ros.core.estimate.scale_filter import DRIFT_RATE_PRIOR, LogScaleFilter, Noise
from hac_ros.core.estimate.sorted_window import SortedWindow
from hac_ros.core.estimate.stamp_weights import WEIGHT_MIN_S, sample_weight

if TYPE_CHECKING:
    from hac_ros.core.rules.params import HacParams

DRIFT_EVIDENCE = 0.999  # the drift probability above which the scale is said to drift
LOSE_FACTOR = 2.0  # converged below converged_max_rel_sigma, no longer above this many times it
STALE_RATE = DRIFT_RATE_PRIOR  # the drift (log, per second) allowed while no sample checks it
RELOCK_WARN_SAMPLES = 3  # a gated run this long ...
RELOCK_WARN_S = 3.0  # ... and this long in stamp time says the scale changed (a stair is shorter)
RELOCK_FALLBACK_WINDOW_SHARE = 1.0 / 3.0  # a run this long re-locks without other evidence
LAG_S = 2.0  # the recent samples the estimate is checked against: this much stamp time, ...
LAG_MIN_COVER_S = 3.0  # ... and at least samples covering this much (3 keyframes, not a burst)
LAG_Z = 3.0  # standard errors of their median beyond which they disagree with the estimate
NOISES_KEPT = 64  # the line's noise as measured at its last refreshes (32 s of stamp time)
MAP_RESCALE_MIN = 0.005  # a new map this much larger or smaller (log) than the one before ...
MAP_RESCALE_Z = 4.0  # ... and by this many of its standard errors says the scale changed


@dataclass(frozen=True)
class Estimate:
    """The estimate at one stamp: ``scale`` metres per SLAM unit; ``rel_sigma`` its relative
    uncertainty σ_stat (standard deviation of the log scale, the doubts included; inf before the
    filter starts); ``core`` the window's and the filter's part alone (what converges); ``drift``
    the probability that the scale drifts; ``age``, ``gap``, ``lag`` the doubts (relative)."""

    scale: float
    rel_sigma: float
    drift: float
    core: float = math.inf
    age: float = 0.0
    gap: float = 0.0
    lag: float = 0.0


class RollingScale:
    """Per-frame scale samples in, a causal estimate and its uncertainty out (module
    docstring)."""

    # the state restart() sets afresh
    _fifo: deque[tuple[int, float, float]]  # (stamp, scale, weight) in arrival order
    _sorted: SortedWindow  # the same scales, sorted: the streaming median
    _recent: deque[tuple[int, float, float]]  # accepted (stamp, log scale, weight)
    _recent_sorted: SortedWindow  # the same logs, sorted: their weighted median
    # (stamp, the line's noise measured until then): the lag is judged against the noise before
    # the recent samples, which a fast change would otherwise count as noise
    _noises: deque[tuple[int, Noise | None]]
    _gated_run: list[tuple[int, float, float]]
    _frame_ns: int | None  # the last frame sampled (its samples share its weight)
    _stats: tuple[float, float] | None  # (median, MAD) until the window changes
    _estimate: tuple[tuple[int, int], Estimate] | None
    _now_ns: int  # the newest stamp seen (a sample or advance)
    _lag_sign: float  # the sign of the lag last found (0: none)
    filter: LogScaleFilter

    def __init__(self, *, window_s: float, window_max_samples: int, min_samples: int,
                 gate_k: float = 5.0, gate_min_rel: float = 0.15,
                 converged_max_rel_sigma: float = 0.02) -> None:
        self.window_ns = int(round(window_s * NS))
        self.max_samples = int(window_max_samples)
        self.min_samples = int(min_samples)
        self.gate_k = float(gate_k)
        self.gate_min_rel = float(gate_min_rel)
        self.max_rel_sigma = float(converged_max_rel_sigma)
        self.relocks = self.map_rescales = 0
        # False while the calibrator doubts what the samples measure (a plane map the bodies have
        # not judged yet): the estimate does not converge, so nothing is published on it
        self.may_converge = True
        self.reset()

    @classmethod
    def from_params(cls, p: HacParams) -> RollingScale:
        return cls(window_s=p.window_s, window_max_samples=p.window_max_samples,
                   min_samples=p.min_samples, gate_k=p.gate_k, gate_min_rel=p.gate_min_rel,
                   converged_max_rel_sigma=p.converged_max_rel_sigma)

    # ------------------------------------------------------------------ updates
    def add(self, stamp_ns: int, scale: float) -> bool:
        """Add one sample (stamp in ns, scale in metres per SLAM unit); False if it was gated.

        Non-finite or non-positive samples are never added (the caller counts them).
        """
        if not (math.isfinite(scale) and scale > 0.0):
            return False
        stamp_ns = int(stamp_ns)
        self._now_ns = max(self._now_ns, stamp_ns)
        if stamp_ns != self._frame_ns:  # a new frame: the stamp time its samples cover
            gap = (stamp_ns - self._frame_ns) / NS if self._frame_ns is not None else 0.0
            self._weight = sample_weight(gap)
            self._frame_ns = stamp_ns
        weight = self._weight
        if len(self._fifo) >= self.min_samples and not self._within_gate(scale):
            if not self._gated_run:
                estimate = self.estimate()
                self._run_began = ('unverified' if estimate.age > self.max_rel_sigma else
                                   'lagging' if self._lag_sign * (scale - estimate.scale) > 0.0
                                   else '')
            self._gated_run.append((stamp_ns, scale, weight))
            self._changed()
            if self._run_says_window_is_wrong():
                self._relock()
            return False
        self._gated_run.clear()
        self._map_rescaled = False
        self._accepted_ns = stamp_ns
        self._take(stamp_ns, scale, weight)
        self._evict(stamp_ns - self.window_ns)
        while len(self._fifo) > self.max_samples:
            self._drop_oldest()
        if self.filter.started:
            if self.filter.noise_due(stamp_ns):
                self._noises.append((stamp_ns, self.filter.noise))  # the noise before: the lag's
                self.filter.measure_noise(stamp_ns, math.log(self.median()))
            self.filter.update(stamp_ns, math.log(scale))
        elif len(self._fifo) >= self.min_samples:
            self.filter.start([s for s, _, _ in self._fifo],
                              [math.log(v) for _, v, _ in self._fifo])
        self._changed()
        return True

    def advance(self, stamp_ns: int) -> None:
        """Let stamp time pass without a sample (a frame or a pose at ``stamp_ns``): the
        evidence ages."""
        self._now_ns = max(self._now_ns, int(stamp_ns))

    def map_changed(self, stamp_ns: int, ratio: float | None = None, error: float = 0.0
                    ) -> float | None:
        """A new map came into use at ``stamp_ns`` (same segment, the calibrator's stamp time).
        ``ratio``: how many times larger it is than the map before about the camera, with its
        standard error ``error`` (relative;
        :meth:`hac_ros.core.geometry.reference.MapIndex.rescale_against`; None: the maps do not
        say). Beyond MAP_RESCALE_MIN and MAP_RESCALE_Z errors the map says
        the scale changed by 1 / ratio: every sample kept is rescaled with it (they were measured
        against the old map), a gated run in progress is dropped, :attr:`map_rescaled` holds until
        a map says the scale holds still, and a run of gated samples that begins meanwhile has
        the evidence to re-lock (module docstring). Returns the factor applied to the scale (new
        over old), or None."""
        self._now_ns = max(self._now_ns, int(stamp_ns))
        if ratio is None:
            return None
        step = math.log(ratio)
        if not abs(step) > max(MAP_RESCALE_MIN, MAP_RESCALE_Z * error):
            self._map_step = 0.0
            self._changed()
            return None
        self._rescale(-step)
        self._gated_run.clear()
        self._map_rescaled = True
        self._map_step = abs(step)
        self.map_rescales += 1
        self._changed()
        return 1.0 / ratio

    def reset(self) -> None:
        """Forget everything (SLAM re-initialisation: the new map has a new scale); nothing is
        published until the new window converges."""
        self.restart()
        self._now_ns = -1

    def restart(self) -> None:
        """Drop the window and the filter: their samples were judged wrong (the floor refused
        them, down turned out to be the other way, their plane map was refused), so what they
        gave is not published any more; the segment goes on, and is published again once the new
        window converges."""
        self._publishing = False
        self._fifo, self._sorted = deque(), SortedWindow()
        self._recent, self._recent_sorted = deque(), SortedWindow()
        self._noises = deque(maxlen=NOISES_KEPT)
        self._gated_run = []
        self._run_began = ''  # what held when the run began: unverified, lagging or nothing
        self._accepted_ns = -1  # the stamp of the last accepted sample
        self._frame_ns, self._weight = None, WEIGHT_MIN_S
        self._map_rescaled = False  # a new map said it has another scale: evidence for a run
        self._map_step = 0.0  # the last map's change of scale (log) while it holds (map_changed)
        self._converged = False
        self._lag_sign = 0.0
        self._stats = None
        self.filter = LogScaleFilter(self.window_ns, self.max_samples)
        self._estimate = None
        self._version = getattr(self, '_version', 0) + 1  # counts changes of the state

    # ------------------------------------------------------------------ queries
    @property
    def samples(self) -> int:
        return len(self._fifo)

    @property
    def converged(self) -> bool:
        """At least ``min_samples`` samples and the core's relative uncertainty under
        ``converged_max_rel_sigma``, until it exceeds LOSE_FACTOR times that (hysteresis)."""
        self.estimate()
        return self._converged

    @property
    def relocking(self) -> bool:
        """Gated samples in a row say the scale changed (module docstring, re-lock)."""
        if len(self._fifo) < self.min_samples:
            return False
        return self._run_has_evidence() or self._run_lasts(RELOCK_WARN_S * NS,
                                                            RELOCK_WARN_SAMPLES)

    @property
    def map_rescaled(self) -> bool:
        """The last new map said the scale changed (:meth:`map_changed`) by more than
        ``converged_max_rel_sigma``: the SLAM's poses may move on at another scale until the next
        map says."""
        return self._map_step > self.max_rel_sigma

    @property
    def unverified(self) -> bool:
        """No sample has checked the estimate for longer than the drift allowed meanwhile
        exceeds ``converged_max_rel_sigma``."""
        return self.publishing and self.estimate().age > self.max_rel_sigma

    @property
    def publishing(self) -> bool:
        """From the segment's first convergence until :meth:`reset` (module docstring)."""
        self.estimate()
        return self._publishing

    @property
    def lagging(self) -> bool:
        """The recent samples disagree with the estimate (module docstring)."""
        return self.estimate().lag > 0.0

    @property
    def drifting(self) -> bool:
        """The evidence says the scale drifts (its probability above DRIFT_EVIDENCE)."""
        return self.estimate().drift > DRIFT_EVIDENCE

    def median(self) -> float:
        """The window's weighted median, metres per SLAM unit (NaN when empty)."""
        return self._median_and_mad()[0]

    def current(self) -> float:
        """The scale now, metres per SLAM unit (NaN when empty; module docstring)."""
        return self.estimate().scale

    def spread(self) -> float:
        """The estimate's standard deviation σ_stat, metres per SLAM unit (inf before the filter
        has started, NaN when empty): its own uncertainty, doubts included, without the
        unobservable biases."""
        estimate = self.estimate()
        return estimate.scale * estimate.rel_sigma

    def estimate(self) -> Estimate:
        """The estimate at the newest stamp (module docstring), kept until a sample or stamp time
        changes it; the hysteresis of ``converged`` and the publishing latch follow it."""
        key = (self._now_ns, self._version)
        if self._estimate is None or self._estimate[0] != key:
            estimate = self._compute()
            self._estimate = (key, estimate)
            if len(self._fifo) < self.min_samples or not estimate.core <= (
                    LOSE_FACTOR if self._converged else 1.0) * self.max_rel_sigma:
                self._converged = False
            elif estimate.core < self.max_rel_sigma and self.may_converge:
                self._converged = True
            if self._converged:
                self._publishing = True
        return self._estimate[1]

    def mad(self) -> float:
        """Median absolute deviation from the median, metres per SLAM unit (NaN when empty)."""
        return self._median_and_mad()[1]

    def sample_spread(self) -> float:
        """Robust sigma of the window's samples (1.4826 MAD), metres per SLAM unit."""
        return MAD_TO_SIGMA * self.mad()

    def values(self) -> np.ndarray:
        """The window's samples in arrival order (for tests and plots)."""
        return np.array([v for _, v, _ in self._fifo], dtype=float)

    # ------------------------------------------------------------------ internals
    def _compute(self) -> Estimate:
        median = self.median()
        if not self.filter.started or not math.isfinite(median):
            return Estimate(median, math.inf, 0.0)
        now_ns = max(self._now_ns, self.filter.stamp_ns or 0)
        m0 = math.log(median)
        v0 = MEDIAN_STD_ERROR ** 2 * self.filter.mean_variance(self._sorted.effective_count(),
                                                                self._sorted.total_weight)
        m1, v1 = self.filter.level_at(now_ns)
        p = self.filter.drift()
        mean = (1.0 - p) * m0 + p * m1
        core = math.sqrt(max((1.0 - p) * v0 + p * v1 + p * (1.0 - p) * (m1 - m0) ** 2, 0.0))
        age = STALE_RATE * max(now_ns - self._accepted_ns, 0) / NS
        gap = self._map_step  # the map moved by this much: the next one may move as much
        if self._gated_run and (self._run_has_evidence()
                                or self._run_lasts(RELOCK_WARN_S * NS, RELOCK_WARN_SAMPLES)):
            gap = max(gap, abs(math.log(median_of([v for _, v, _ in self._gated_run]))
                               - mean))
        lag = self._lag(mean, now_ns)
        rel_sigma = math.sqrt(core * core + age * age + gap * gap + lag * lag)
        return Estimate(math.exp(mean), rel_sigma, p, core, age, gap, lag)

    def _lag(self, mean: float, now_ns: int) -> float:
        """The recent samples' disagreement with the estimate ``mean`` (log): their weighted
        median minus it, when that exceeds LAG_Z standard errors and half of
        ``converged_max_rel_sigma``, else 0 (module docstring)."""
        recent, kept = self._recent, self._recent_sorted
        while (recent and recent[0][0] < now_ns - LAG_S * NS
               and kept.total_weight - recent[0][2] >= LAG_MIN_COVER_S):
            _, value, weight = recent.popleft()
            kept.remove(value, weight)
        noise = next((n for stamp, n in reversed(self._noises) if stamp <= recent[0][0]),
                     self._noises[0][1] if self._noises else self.filter.noise) if recent else None
        covered = kept.total_weight  # the stamp time they cover, seconds
        if covered < LAG_MIN_COVER_S or noise is None:
            self._lag_sign = 0.0
            return 0.0
        lag = kept.weighted_median() - mean
        error = MEDIAN_STD_ERROR * math.sqrt(max(noise.sigma2 / kept.effective_count(),
                                                 noise.density / covered))
        if abs(lag) <= max(LAG_Z * error, 0.5 * self.max_rel_sigma):
            self._lag_sign = 0.0
            return 0.0
        self._lag_sign = math.copysign(1.0, lag)
        return abs(lag)

    def _median_and_mad(self) -> tuple[float, float]:
        if self._stats is None:
            if not self._fifo:
                return math.nan, math.nan
            self._stats = self._sorted.weighted_median(), self._sorted.mad()
        return self._stats

    def _within_gate(self, scale: float) -> bool:
        med = self.median()
        band = max(self.gate_k * self.sample_spread(), self.gate_min_rel * med)
        return abs(scale - med) <= band

    def _run_has_evidence(self) -> bool:
        """The run began after a map said the scale changed, or while the estimate was
        unverified or lagging its way (module docstring)."""
        return bool(self._gated_run) and (self._map_rescaled or bool(self._run_began))

    def _run_lasts(self, span_ns: float, count: int) -> bool:
        run = self._gated_run
        return len(run) >= count and run[-1][0] - run[0][0] >= span_ns

    def _run_says_window_is_wrong(self) -> bool:
        """A run of gated samples long enough (``min_samples``, with evidence that the scale
        changed or a third of the window long in stamp time) and consistent enough (robust
        spread within half the gate's relative floor) to say the window is wrong, not that a
        passing disturbance (an occluder, a step) is gated as it should be."""
        run = self._gated_run
        if len(run) < self.min_samples:
            return False
        if not (self._run_has_evidence() or self._run_lasts(
                RELOCK_FALLBACK_WINDOW_SHARE * self.window_ns, self.min_samples)):
            return False
        values = np.array([v for _, v, _ in run])
        med = median_of(values)
        spread = MAD_TO_SIGMA * median_of(np.abs(values - med))
        return spread <= 0.5 * max(self.gate_min_rel, 1e-3) * med

    def _take(self, stamp_ns: int, scale: float, weight: float) -> None:
        self._fifo.append((stamp_ns, scale, weight))
        self._sorted.add(scale, weight)
        self._recent.append((stamp_ns, math.log(scale), weight))
        self._recent_sorted.add(math.log(scale), weight)
        self._stats = None

    def _evict(self, horizon_ns: int) -> None:
        while self._fifo and self._fifo[0][0] < horizon_ns:
            self._drop_oldest()

    def _drop_oldest(self) -> None:
        _, scale, weight = self._fifo.popleft()
        self._sorted.remove(scale, weight)
        self._stats = None

    def _changed(self) -> None:
        self._version += 1

    def _rescale(self, shift: float) -> None:
        """Every sample kept and the filter's level times exp(``shift``) (a new map's scale:
        :meth:`map_changed`)."""
        factor = math.exp(shift)
        self._fifo = deque((s, v * factor, w) for s, v, w in self._fifo)
        self._sorted.scale_values(factor)
        self._recent = deque((s, y + shift, w) for s, y, w in self._recent)
        self._recent_sorted.shift_values(shift)
        self.filter.shift(shift)
        self._stats = None

    def _relock(self) -> None:
        run = list(self._gated_run)
        publishing, now = self._publishing, self._now_ns
        self.restart()
        self._publishing, self._now_ns = publishing, now
        self.relocks += 1
        for stamp, scale, weight in run:
            self._take(stamp, scale, weight)
        self._accepted_ns = run[-1][0]
        self._frame_ns = run[-1][0]
        self.filter.start([s for s, _, _ in run], [math.log(v) for _, v, _ in run])
        self._changed()


def sequence_scale(samples: np.ndarray) -> float:
    """The paper's offline estimate: the median of every per-frame scale of the sequence."""
    samples = np.asarray(samples, dtype=float)
    samples = samples[np.isfinite(samples) & (samples > 0)]
    return median_of(samples) if samples.size else float('nan')
