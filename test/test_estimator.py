"""The scale estimator on built scenes at keyframe rate (1 Hz) and at 30 Hz (issue 37's targets):
a 1.6x step (a quiet SLAM re-initialisation), a ramp, a constant scale under slowly wandering
(AR(1)) noise; what 'converged' and the ``±`` mean; the window, its gate and its re-lock.

The samples are drawn per seed: the truth times exp(noise), the noise white with
WHITE_SIGMA (a sample's own spread on the bench's scenes: 2-2.5 %) plus, on the AR(1) scene, a
wander of AR_SIGMA and AR_TAU_S. Each stream is read as /diagnostics reads it: once per second of
stamp time, after the samples of that second.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from hac_ros.core.estimator import RollingScale
from hac_ros.core.numeric import NS

WHITE_SIGMA = 0.025
AR_SIGMA, AR_TAU_S = 0.03, 10.0  # the AR(1) scene's wander
RAMP_RATE = math.log(1.4) / 90.0  # 40 % in 90 s, per second (log)
STEP = 1.6  # the quiet re-initialisation's factor
STEP_AT_S = 60.0
DURATION_S = 120.0
RATES = (1.0, 30.0)  # keyframe rate and video rate, Hz
SEEDS = range(5)
OFF = 0.05  # 'OK while more than 5 % off' is the failure a user cannot defend against


@dataclass
class Status:
    """What /diagnostics would say at ``t_s``: the estimate against the truth."""

    t_s: float
    error: float  # relative error of the estimate
    rel_sigma: float
    converged: bool
    relocking: bool
    drifting: bool

    @property
    def ok(self) -> bool:
        return self.converged and not self.relocking


def stream(kind: str, rate: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_s, truth, samples) of a built scene: 'constant', 'step', 'ramp' or 'ar1'."""
    rng = np.random.default_rng([seed, int(rate), len(kind)])
    t = np.arange(0.0, DURATION_S, 1.0 / rate)
    truth = np.full(len(t), 2.0)
    if kind.startswith('step'):
        truth = np.where(t >= STEP_AT_S, 2.0 * STEP, 2.0)
    elif kind == 'ramp':
        truth = 2.0 * np.exp(RAMP_RATE * t)
    noise = rng.normal(0.0, WHITE_SIGMA, len(t))
    if kind == 'ar1':  # an exact AR(1) (Ornstein-Uhlenbeck) step over each dt
        wander = np.zeros(len(t))
        wander[0] = rng.normal(0.0, AR_SIGMA)
        a = math.exp(-1.0 / (rate * AR_TAU_S))
        for i in range(1, len(t)):
            wander[i] = a * wander[i - 1] + math.sqrt(1.0 - a * a) * rng.normal(0.0, AR_SIGMA)
        noise += wander
    return t, truth, truth * np.exp(noise)


def statuses(kind: str, rate: float, seed: int, estimator: RollingScale | None = None,
             warned: list[float] | None = None) -> list[Status]:
    """Feed a built scene; a status once per second of stamp time. On the step scene the new
    map comes into use at the step, its floor saying it has another scale, as the calibrator
    says when it activates it ('step_unannounced': no word from the map). ``warned`` gets the
    time of every sample after which the estimator says it is re-locking."""
    est = estimator or RollingScale(window_s=30.0, window_max_samples=2000, min_samples=10)
    t, truth, samples = stream(kind, rate, seed)
    out: list[Status] = []
    for i, (t_s, sample) in enumerate(zip(t, samples)):
        stamp = int(round(t_s * NS))
        if kind == 'step' and i and t[i - 1] < STEP_AT_S <= t_s:
            est.map_changed(rescaled=True)
        est.add(stamp, float(sample))
        if warned is not None and est.relocking:
            warned.append(t_s)
        last_of_second = i + 1 == len(t) or math.floor(t[i + 1]) > math.floor(t_s)
        if last_of_second and est.samples >= est.min_samples:
            estimate = est.estimate()
            out.append(Status(t_s, estimate.scale / truth[i] - 1.0, estimate.rel_sigma,
                              est.converged, est.relocking, est.drifting))
    return out


def ok_while_off(found: list[Status]) -> list[Status]:
    return [s for s in found if s.ok and abs(s.error) > OFF]


@pytest.mark.parametrize('rate', RATES)
def test_a_quiet_reinitialisation_warns_at_once_and_relocks(rate):
    """1.6x step (a new map, same frame, no pose jump): WARN (relocking) within 10 samples, the
    estimate re-locked within 20 s at 1 Hz and 5 s at 30 Hz, and never OK while 5 % off."""
    limit_s = {1.0: 20.0, 30.0: 5.0}[rate]
    for seed in SEEDS:
        est = RollingScale(window_s=30.0, window_max_samples=2000, min_samples=10)
        warned: list[float] = []
        found = statuses('step', rate, seed, est, warned)
        assert warned and warned[0] - STEP_AT_S <= 10.0 / rate, seed  # within 10 samples
        after = [s for s in found if s.t_s >= STEP_AT_S]
        relocked = next(s.t_s for s in after if abs(s.error) <= OFF)
        assert relocked - STEP_AT_S <= limit_s, seed
        assert all(abs(s.error) <= OFF for s in after if s.t_s >= relocked), seed
        assert ok_while_off(found) == [], seed


@pytest.mark.parametrize('rate', RATES)
def test_a_step_without_a_new_maps_word_relocks_after_a_third_of_the_window(rate):
    """The same step with no map saying it has another scale: a run of gated samples could be a
    passing disturbance (a walker on a flight of stairs), so the window re-locks once the run has
    lasted a third of the window (10 s); WARN meanwhile, never OK while 5 % off."""
    for seed in SEEDS:
        found = statuses('step_unannounced', rate, seed)
        after = [s for s in found if s.t_s >= STEP_AT_S]
        relocked = next(s.t_s for s in after if abs(s.error) <= OFF)
        assert 10.0 <= relocked - STEP_AT_S <= 12.0, seed
        assert all(not s.ok for s in after if s.t_s < relocked), seed
        assert ok_while_off(found) == [], seed


@pytest.mark.parametrize('rate', RATES)
def test_a_ramp_is_followed_without_lag(rate):
    """40 % in 90 s: after the first window the estimate lags the truth of the moment by at most
    1 % (median signed error; a window's median would lag 6 %), is said to drift, and is never OK
    while 5 % off."""
    for seed in SEEDS:
        found = statuses('ramp', rate, seed)
        assert abs(np.median([s.error for s in found if s.t_s >= 30.0])) <= 0.01, seed
        assert found[-1].drifting, seed
        assert ok_while_off(found) == [], seed


@pytest.mark.parametrize('rate', RATES)
def test_a_slowly_wandering_constant_scale_is_not_taken_for_drift(rate):
    """A constant scale whose samples wander (AR(1), 3 %, 10 s) as well as scatter: 'drifting'
    is never said, and no status is OK while 5 % off."""
    for seed in SEEDS:
        found = statuses('ar1', rate, seed)
        assert not any(s.drifting for s in found), seed
        assert ok_while_off(found) == [], seed


@pytest.mark.parametrize('rate', RATES)
def test_the_spread_is_the_estimates_uncertainty(rate):
    """The ± is not overconfident: 2σ covers the truth in at least 90 % of the statuses (its
    calibration on the bench's scenes: bench/accuracy.py, coverage). 'converged' waits for it to
    be small, not for a number of samples: at 30 Hz, min_samples samples are a third of a
    second."""
    errors, sigmas = [], []
    for seed in SEEDS:
        found = statuses('constant', rate, seed)
        errors += [abs(math.log1p(s.error)) for s in found]
        sigmas += [s.rel_sigma for s in found]
        assert not (rate == 30.0 and found[0].converged), seed
    assert np.mean(np.array(errors) <= 2 * np.array(sigmas)) >= 0.9


def test_the_same_evidence_converges_alike_at_any_rate():
    """The filter weighs a sample by the stamp time it covers: thirty samples of one second at
    30 Hz tell (about) what one does at 1 Hz, so the uncertainty after a minute is alike."""
    final = {rate: statuses('constant', rate, 0)[-1].rel_sigma for rate in RATES}
    assert final[30.0] <= final[1.0] <= 4.0 * final[30.0]


def test_window_evicts_by_stamp_time_and_gates_outliers_then_relocks():
    est = RollingScale(window_s=1.0, window_max_samples=1000, min_samples=5)
    for i in range(20):
        assert est.add(i * NS // 10, 2.0 + 0.01 * (i % 3))
    assert est.samples == 11  # stamps within the last second (inclusive)
    assert not est.add(2 * NS, 10.0)  # far outside the gate once min_samples are in
    assert est.median() == pytest.approx(2.01) and not est.relocking  # one: an outlier
    for i in range(5):  # a short run of "outliers" is gated: a passing disturbance, but WARN
        est.add(2 * NS + i, 4.0)
    assert est.relocks == 0 and est.median() == pytest.approx(2.01) and est.relocking
    for i in range(5):  # consistent for a third of the window: the window was wrong, relock
        est.add(2 * NS + NS // 2 + i, 4.0 + 0.01 * i)
    assert est.relocks == 1 and est.median() == pytest.approx(4.0, abs=0.05)
    assert not est.relocking
    # the window re-locked on the run itself: every gated sample of the run is in it
    assert est.samples >= 5 and sorted(est.values().tolist())[:5] == [4.0] * 5
    assert not est.add(3 * NS, float('nan')) and not est.add(3 * NS, -1.0)


def test_a_new_map_relocks_on_min_samples_and_a_rescaled_one_warns_at_once():
    est = RollingScale(window_s=30.0, window_max_samples=1000, min_samples=5)
    for i in range(30):
        est.add(i * NS, 2.0)
    est.map_changed(rescaled=True)  # its floor says it has another scale
    assert est.relocking  # before any sample of it
    for i in range(5):
        est.add((30 + i) * NS, 3.2)
    assert est.relocks == 1 and est.median() == pytest.approx(3.2)
    est.map_changed(rescaled=True)
    est.add(36 * NS, 3.2)  # the samples agree with the window: no more warning
    assert not est.relocking and est.relocks == 1
