"""The scale's level and drift: a robust Kalman filter on the log scale, and its smoother.

The per-frame samples ``y_i = ln s_i`` (s: metres per SLAM unit) at stamps ``t_i`` are fed one by
one to a filter whose state is the log scale's level and rate, ``x = (l, r)`` (r per second):

- **Process** (between two stamps Δt apart): ``l += r Δt``; ``r`` is a random walk of spectral
  density ``q = DRIFT_RATE_PRIOR² / DRIFT_RATE_TIME_S``: a SLAM scale may drift at about
  DRIFT_RATE_PRIOR (per second, in log) and its rate changes over minutes, not seconds.
  ``Q(Δt) = q [[Δt³/3, Δt²/2], [Δt²/2, Δt]]`` (an integrated random walk), so the filter's
  behaviour depends on stamp time, never on the number of samples.
- **Measurement** ``y_i = l + v_i``: the samples' noise is measured on the samples themselves
  (:func:`noise_density`): their robust variance ``σ²`` and their noise density ``N²`` (variance
  times seconds: what one second of samples tells about the level), so that a sample covering
  ``δ_i`` seconds of stamp time (the time since the previous frame) counts with variance
  ``R_i = max(σ², N² / δ_i)``: at 30 Hz a sample weighs a thirtieth of a second's worth, at 1 Hz a
  second's worth; consecutive samples that are correlated (the same stride, a slowly wandering
  HMR bias) raise ``N²`` and weigh less.
- **Heavy tails**: an update whose normalised innovation exceeds HUBER_K has its variance
  inflated by ``|ν| / HUBER_K`` (Huber's weights), so that outliers that pass the gate do not pull.

Whether the scale drifts is the **evidence** for a non-zero rate: the Savage–Dickey ratio of the
rate's posterior density at zero to its prior density there, ``B01 = N(0; r, P_rr) /
N(0; 0, DRIFT_RATE_PRIOR²)``, with prior odds DRIFT_PRIOR_ODDS, gives the probability that the
scale drifts, :func:`drift_probability`; no threshold on a slope.

Offline, :func:`smooth` runs the same filter forwards over a segment and the Rauch–Tung–Striebel
smoother backwards: every stamp's estimate uses the samples before and after it.

Pure numpy; stamps int nanoseconds; the filter works in seconds of stamp time and natural log.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from hac_ros.core.basics.numeric import MAD_TO_SIGMA, NS, median_of
from hac_ros.core.estimate.stamp_weights import stamp_weights, weighted_median

# The prior on drift. A monocular SLAM's scale drifts as it maps new ground; 40 % in 90 s
# (bench/accuracy.py's `drift`) is about the fastest worth following, ln(1.4) / 90 s per second.
DRIFT_RATE_PRIOR = math.log(1.4) / 90.0  # prior sigma of the log scale's rate, per second
DRIFT_RATE_TIME_S = 1000.0  # the time over which the rate itself may change by that much
DRIFT_PRIOR_ODDS = 0.1 / 0.9  # prior odds of a drifting scale over a constant one (window)
# Samples closer than this in stamp time are not taken as independent whatever their spread says:
# the same stride, the same geometry, a slowly wandering HMR bias (measured on the bench's
# composites of real CMU walks: correlated over 1-5 s). It bounds N² from below, N² >= σ² × this.
NOISE_CORRELATION_S = 1.0
# No sample is taken as more precise than this (natural log, ~1 %): HMR's per-frame depth noise
# alone is a few centimetres at a few metres. It keeps a run of near-identical first samples (a
# slowly wandering error seen for a fraction of a second) from claiming a precise level.
SAMPLE_SIGMA_FLOOR = 0.01
NOISE_HISTORY_WINDOWS = 4.0  # the noise is measured over this many windows of samples
NOISE_BLOCK_MIN_S = 0.125  # the shortest block of the noise density (then doubled)
NOISE_BLOCKS_MIN = 4  # a block length needs the history to span this many blocks
NOISE_REFRESH_NS = 500_000_000  # the noise is re-measured this often (stamp time)
# The block means are taken of residuals clipped to this many σ about their centre: a few samples
# far out (a walker on a stair before the gate is armed) say little of how the level wanders,
# and without the clip they alone kept a keyframe-rate window of a person behind furniture from
# converging.
NOISE_CLIP_SIGMAS = 3.0
HUBER_K = 2.0  # normalised innovations beyond this are down-weighted (Huber)


@dataclass
class Noise:
    """The samples' noise, in natural log of the scale: ``sigma2`` the variance of one sample,
    ``density`` N², variance × seconds (what a second of samples tells about the level)."""

    sigma2: float
    density: float


def noise_density(stamps_ns: np.ndarray, residuals: np.ndarray) -> Noise | None:
    """The noise of samples whose residuals about the level (natural log) are ``residuals`` at
    ``stamps_ns`` (sorted int ns): σ² = (1.4826 MAD)², the median absolute deviation weighing each
    sample by the stamp time it covers up to the samples' typical spacing (hac_ros.core.
    stamp_weights: a burst of repeated frames is not taken for the noise, nor one sample after a
    gap for many), at least SAMPLE_SIGMA_FLOOR²; N² the
    largest of σ² over the sample rate (independent samples), σ² × NOISE_CORRELATION_S, and
    B × the variance of the means of blocks of B seconds, for B = 1/8, 1/4, 1/2, 1, 2, ... s
    while the samples span NOISE_BLOCKS_MIN blocks (two grids half a block apart, whole blocks
    only; the residuals clipped to NOISE_CLIP_SIGMAS σ about their centre): a correlation over B
    shows as block means that scatter more than independent samples would. None with fewer than
    3 samples."""
    n = len(residuals)
    if n < 3:
        return None
    t = (stamps_ns - stamps_ns[0]) / NS
    span = float(t[-1])
    weights = stamp_weights(stamps_ns)
    weights = np.minimum(weights, median_of(weights))
    centre = weighted_median(residuals, weights)
    sigma2 = max(MAD_TO_SIGMA * weighted_median(np.abs(residuals - centre), weights),
                 SAMPLE_SIGMA_FLOOR) ** 2
    density = max(sigma2 * span / max(n - 1, 1), sigma2 * NOISE_CORRELATION_S)
    clip = NOISE_CLIP_SIGMAS * math.sqrt(sigma2)
    residuals = np.clip(residuals, centre - clip, centre + clip)
    block = NOISE_BLOCK_MIN_S
    while span >= NOISE_BLOCKS_MIN * block:
        variances = []
        for offset in (0.0, 0.5 * block):
            index = np.floor((t + offset) / block).astype(np.int64)
            counts = np.bincount(index)
            sums = np.bincount(index, residuals)
            means = (sums[counts > 0] / counts[counts > 0])[1:-1]  # whole blocks only
            if len(means) >= 2:
                variances.append(float(np.var(means, ddof=1)))
        if variances:
            density = max(density, block * float(np.mean(variances)))
        block *= 2.0
    return Noise(sigma2, density)


def process_noise(dt_s: float) -> tuple[float, float, float]:
    """Q(Δt) of the integrated random walk (module docstring): (q_ll, q_lr, q_rr)."""
    q = DRIFT_RATE_PRIOR ** 2 / DRIFT_RATE_TIME_S
    return q * dt_s ** 3 / 3.0, q * dt_s ** 2 / 2.0, q * dt_s


def drift_probability(rate: float, rate_variance: float) -> float:
    """The probability that the scale drifts given the rate's posterior N(rate, rate_variance)
    (per second, natural log): Savage–Dickey against the prior N(0, DRIFT_RATE_PRIOR²), with the
    prior odds DRIFT_PRIOR_ODDS."""
    if not (rate_variance > 0.0 and math.isfinite(rate)):
        return 0.0
    z2 = rate * rate / rate_variance
    # B01 = N(0; r, P) / N(0; 0, prior²) = sqrt(prior² / P) exp(-z²/2), computed in logs
    log_b01 = 0.5 * math.log(DRIFT_RATE_PRIOR ** 2 / rate_variance) - 0.5 * z2
    log_odds = math.log(DRIFT_PRIOR_ODDS) - log_b01
    return 1.0 / (1.0 + math.exp(-log_odds)) if log_odds > -700 else 0.0


class LogScaleFilter:
    """The online filter (module docstring): ``start`` it on a first batch of samples, then
    ``update`` it with each sample; ``level_at`` and ``drift`` read it.

    Plain floats (a 2 × 2 state: numpy per sample would cost more than the arithmetic)."""

    def __init__(self, window_ns: int, max_samples: int) -> None:
        self.history_ns = int(NOISE_HISTORY_WINDOWS * window_ns)
        kept = int(NOISE_HISTORY_WINDOWS * max_samples)  # the samples the noise is measured on:
        self._stamps: deque[int] = deque(maxlen=kept)  # their stamps, ns
        self._values: deque[float] = deque(maxlen=kept)  # their natural log of the scale
        self.noise: Noise | None = None  # about the filter's line: its measurements' noise
        self.level_noise: Noise | None = None  # about a constant level (the window's median)
        self._noise_ns: int | None = None
        self.stamp_ns: int | None = None  # the state's stamp
        self.level = self.rate = 0.0  # natural log, and per second
        self.p_ll = self.p_lr = self.p_rr = 0.0
        self._frame_ns: int | None = None  # the stamp of the last frame sampled ...
        self._frame_gap_s = 0.0  # ... and the stamp time it covers (since the one before)

    @property
    def started(self) -> bool:
        return self.stamp_ns is not None

    def start(self, stamps_ns: list[int], log_scales: list[float]) -> None:
        """Start on a batch of samples (sorted stamps, natural log of the scale): the level their
        median, its variance that of a median of samples of this noise; the rate 0, its variance
        the prior's."""
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        values = np.asarray(log_scales, dtype=float)
        self._stamps.extend(stamps.tolist())
        self._values.extend(values.tolist())
        self.level = median_of(values)
        self.noise = self.level_noise = noise_density(stamps, values - self.level)
        self.stamp_ns, self._noise_ns = int(stamps[-1]), int(stamps[-1])
        self.p_ll = self.mean_variance(len(values), float(stamps[-1] - stamps[0]) / NS)
        self.p_lr, self.rate, self.p_rr = 0.0, 0.0, DRIFT_RATE_PRIOR ** 2
        self._frame_ns = int(stamps[-1])

    def mean_variance(self, count: float, span_s: float) -> float:
        """The variance of the mean of ``count`` samples covering ``span_s`` seconds of stamp
        time about a constant level, under the noise measured about one (``level_noise``):
        max(σ² / n, N² / span) (log²; σ² for samples of one stamp, ∞ without a noise). A drift
        the constant level ignores shows in that noise, so a window that drifts is not said to be
        precise."""
        noise = self.level_noise
        if noise is None or count <= 0:
            return math.inf
        if span_s <= 0.0:
            return noise.sigma2
        return max(noise.sigma2 / count, noise.density / span_s)

    def shift(self, log_factor: float) -> None:
        """The level and every sample of the history moved by ``log_factor`` (natural log: the
        map the samples were measured against changed its scale)."""
        self.level += log_factor
        self._values = deque((y + log_factor for y in self._values), maxlen=self._values.maxlen)

    def predict(self, stamp_ns: int) -> None:
        """Carry the state to ``stamp_ns`` (no-op for an older stamp)."""
        if self.stamp_ns is None or stamp_ns <= self.stamp_ns:
            return
        dt = (stamp_ns - self.stamp_ns) / NS
        q_ll, q_lr, q_rr = process_noise(dt)
        self.level += self.rate * dt
        p_ll = self.p_ll + 2.0 * dt * self.p_lr + dt * dt * self.p_rr + q_ll
        self.p_lr += dt * self.p_rr + q_lr
        self.p_ll = p_ll
        self.p_rr += q_rr
        self.stamp_ns = int(stamp_ns)

    def noise_due(self, stamp_ns: int) -> bool:
        """Whether the noise is due to be measured again at ``stamp_ns`` (NOISE_REFRESH_NS of
        stamp time after the last time): the caller then calls :meth:`measure_noise`."""
        return self._noise_ns is not None and stamp_ns - self._noise_ns >= NOISE_REFRESH_NS

    def update(self, stamp_ns: int, log_scale: float) -> None:
        """One sample (stamp ns, natural log of the scale) after :meth:`start`."""
        if self.stamp_ns is None or self.noise is None:
            raise RuntimeError('LogScaleFilter.update before start')
        if stamp_ns != self._frame_ns:  # a new frame: the stamp time since the previous one
            self._frame_gap_s = (stamp_ns - (self._frame_ns or stamp_ns)) / NS
            self._frame_ns = int(stamp_ns)
        self._stamps.append(int(stamp_ns))
        self._values.append(float(log_scale))
        self.predict(stamp_ns)
        noise = self.noise
        r = noise.sigma2 if self._frame_gap_s <= 0.0 else max(
            noise.sigma2, noise.density / self._frame_gap_s)
        innovation = log_scale - self.level
        s = self.p_ll + r
        nu = abs(innovation) / math.sqrt(s) if s > 0.0 else 0.0
        if nu > HUBER_K:  # heavy tails: Huber's weight
            r *= nu / HUBER_K
            s = self.p_ll + r
        k_l, k_r = self.p_ll / s, self.p_lr / s
        self.level += k_l * innovation
        self.rate += k_r * innovation
        p_ll, p_lr, p_rr = self.p_ll, self.p_lr, self.p_rr
        self.p_ll = p_ll - k_l * p_ll
        self.p_lr = p_lr - k_l * p_lr
        self.p_rr = p_rr - k_r * p_lr

    def measure_noise(self, stamp_ns: int, centre: float) -> None:
        """The noise of the history's samples about the filter's line (level and rate now), and
        about the constant level ``centre`` (log: the window's median)."""
        self._noise_ns = int(stamp_ns)
        while self._stamps and self._stamps[0] < stamp_ns - self.history_ns:
            self._stamps.popleft()
            self._values.popleft()
        stamps = np.fromiter(self._stamps, np.int64, len(self._stamps))
        values = np.fromiter(self._values, float, len(self._values))
        line = self.level + self.rate * (stamps - stamp_ns) / NS
        self.noise = noise_density(stamps, values - line) or self.noise
        self.level_noise = noise_density(stamps, values - centre) or self.level_noise

    def level_at(self, stamp_ns: int) -> tuple[float, float]:
        """The level (natural log) at ``stamp_ns`` (at or after the state's) and its variance."""
        if self.stamp_ns is None:
            return math.nan, math.inf
        dt = max(0, stamp_ns - self.stamp_ns) / NS
        q_ll, _, _ = process_noise(dt)
        return (self.level + self.rate * dt,
                self.p_ll + 2.0 * dt * self.p_lr + dt * dt * self.p_rr + q_ll)

    def drift(self) -> float:
        """The probability that the scale drifts (:func:`drift_probability`)."""
        return drift_probability(self.rate, self.p_rr) if self.started else 0.0


@dataclass
class Smoothed:
    """The smoother's estimate at each sample of a segment: ``level`` (n,) natural log,
    ``level_var`` (n,) its variance, ``rate`` (n,) per second, ``rate_var`` (n,)."""

    level: np.ndarray
    level_var: np.ndarray
    rate: np.ndarray
    rate_var: np.ndarray


def smooth(stamps_ns: np.ndarray, log_scales: np.ndarray, noise: Noise) -> Smoothed:
    """Rauch–Tung–Striebel: the filter forwards over every sample (sorted stamps, natural log),
    then backwards, with the segment's ``noise``; the filter starts on the first sample with an
    uninformative level."""
    n = len(stamps_ns)
    t = (np.asarray(stamps_ns, dtype=np.int64) - int(stamps_ns[0])) / NS
    x_pred = np.zeros((n, 2))
    p_pred = np.zeros((n, 2, 2))
    x_post = np.zeros((n, 2))
    p_post = np.zeros((n, 2, 2))
    x = np.array([float(log_scales[0]), 0.0])
    p = np.diag([1e6, DRIFT_RATE_PRIOR ** 2])
    frame_gap, last_frame = 0.0, t[0]
    for i in range(n):
        dt = t[i] - t[i - 1] if i else 0.0
        if t[i] != last_frame:
            frame_gap, last_frame = t[i] - last_frame, t[i]
        F = np.array([[1.0, dt], [0.0, 1.0]])
        q_ll, q_lr, q_rr = process_noise(dt)
        x = F @ x
        p = F @ p @ F.T + np.array([[q_ll, q_lr], [q_lr, q_rr]])
        x_pred[i], p_pred[i] = x, p
        r = noise.sigma2 if frame_gap <= 0.0 else max(noise.sigma2, noise.density / frame_gap)
        innovation = float(log_scales[i]) - x[0]
        s = p[0, 0] + r
        nu = abs(innovation) / math.sqrt(s)
        if nu > HUBER_K and i:
            s = p[0, 0] + r * nu / HUBER_K
        gain = p[:, 0] / s
        x = x + gain * innovation
        p = p - np.outer(gain, p[0, :])
        x_post[i], p_post[i] = x, p
    xs, ps = x_post.copy(), p_post.copy()
    for i in range(n - 2, -1, -1):
        dt = t[i + 1] - t[i]
        F = np.array([[1.0, dt], [0.0, 1.0]])
        c = p_post[i] @ F.T @ np.linalg.pinv(p_pred[i + 1])
        xs[i] = x_post[i] + c @ (xs[i + 1] - x_pred[i + 1])
        ps[i] = p_post[i] + c @ (ps[i + 1] - p_pred[i + 1]) @ c.T
    return Smoothed(xs[:, 0], ps[:, 0, 0], xs[:, 1], ps[:, 1, 1])
