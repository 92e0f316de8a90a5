"""hac_ros.core.bodies.human_filter: people followed across frames, their world roots filtered in stamp
time."""
from __future__ import annotations

import numpy as np
from scenes import STANDING, walking_scene

from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import HumanJointsOut
from hac_ros.core.bodies.human_filter import RootFilter, smooth_people
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.layouts import SMPL24
from hac_ros.core.rules.params import HacParams

NOISE_M = 0.05


def two_walkers(rate_hz: float, seconds: float = 6.0, noise_m: float = NOISE_M, seed: int = 0
                ) -> tuple[list[int], list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """Two people 1.5 m apart walking along x at 1.2 and 0.8 m/s (a slight curve); every frame
    lists them in a random order. Returns stamps (ns), the noisy joints (2, 24, 3) per frame, the
    true joints, and the order used (which person each block is)."""
    rng = np.random.default_rng(seed)
    stamps, noisy, truth, orders = [], [], [], []
    for i in range(int(seconds * rate_hz)):
        t = i / rate_hz
        people = []
        for speed, y in ((1.2, 0.0), (0.8, 1.5)):
            root = np.array([speed * t, y + 0.3 * np.sin(0.5 * t), 0.0])
            people.append(STANDING + root)
        order = rng.permutation(2)
        clean = np.stack([people[k] for k in order])
        jitter = rng.normal(0.0, noise_m, (2, 1, 3))  # the whole person moves (HMR depth error)
        stamps.append(int(t * NS))
        noisy.append(clean + jitter)
        truth.append(clean)
        orders.append(order)
    return stamps, noisy, truth, orders


def root_errors(joints: list[np.ndarray], truth: list[np.ndarray]) -> np.ndarray:
    return np.array([np.linalg.norm(j[:, 0] - t[:, 0], axis=1) for j, t in zip(joints, truth)])


def test_people_are_followed_when_their_blocks_swap_and_the_jitter_drops_online():
    stamps, noisy, truth, _ = two_walkers(30.0)
    filt = RootFilter(SMPL24)
    out = [filt.update(s, j) for s, j in zip(stamps, noisy)]
    raw, filtered = root_errors(noisy, truth)[30:], root_errors(out, truth)[30:]
    assert np.median(filtered) < 0.6 * np.median(raw)  # identities kept: else errors of 1.5 m
    assert filtered.max() < 0.3
    # the pose is untouched: each person moved rigidly
    for j, n in zip(out, noisy):
        np.testing.assert_allclose(j - j[:, :1], n - n[:, :1], atol=1e-12)
    assert len(filt.tracker.tracks) == 2


def test_offline_smoothing_is_zero_phase_and_keeps_identities():
    stamps, noisy, truth, _ = two_walkers(30.0)
    out = smooth_people(stamps, noisy, SMPL24)
    raw, smoothed = root_errors(noisy, truth), root_errors(out, truth)
    assert np.median(smoothed) < 0.5 * np.median(raw)
    # no lag on a walk at constant speed: the mean signed error along x is ~0
    along = np.array([(o[:, 0, 0] - t[:, 0, 0]) for o, t in zip(out, truth)])[10:-10]
    assert abs(along.mean()) < 0.005


def test_filtering_is_in_stamp_time_whatever_the_frame_rate():
    """Noise-free input at 30 and 15 Hz: the smoothed roots agree at the common stamps (the
    Gaussian is in seconds, not frames), and the online filter tracks both without lag."""
    s30, n30, t30, o30 = two_walkers(30.0, noise_m=0.0, seed=1)
    s15, n15, t15, o15 = two_walkers(15.0, noise_m=0.0, seed=1)
    a, b = smooth_people(s30, n30, SMPL24), smooth_people(s15, n15, SMPL24)
    common = {s: k for k, s in enumerate(s15)}
    for k, s in enumerate(s30):
        if s in common and 0.5 < s / NS < 5.5:
            order30, order15 = np.argsort(o30[k]), np.argsort(o15[common[s]])
            np.testing.assert_allclose(a[k][order30, 0], b[common[s]][order15, 0], atol=0.003)
    for stamps, noisy, truth in ((s30, n30, t30), (s15, n15, t15)):
        filt = RootFilter(SMPL24)
        out = [filt.update(s, j) for s, j in zip(stamps, noisy)]
        assert np.median(root_errors(out, truth)[len(out) // 2:]) < 0.01


def test_human_filter_none_publishes_the_joints_as_they_come():
    """human_filter none: /hac/human_joints is R J + s c exactly; smooth: each person moved
    rigidly (the same pose), never by more than a few centimetres here."""
    scene = walking_scene()
    contacts = scene.to_slam(scene.contact_world())
    runs = {}
    for mode in ('none', 'smooth'):
        cal = Calibrator(HacParams(human_filter=mode, cone_min_points=1, map_overlap_min=0.0))
        outs: list = []
        for t, stamp in enumerate(scene.stamps_ns):
            outs += cal.add_map(int(stamp), scene.with_backdrop(contacts[t:t + 1]), 'map')
            outs += cal.add_pose(int(stamp), scene.R_wc_slam[t], scene.c_slam[t], 'map')
            outs += cal.add_joints(int(stamp), scene.joints_cam[t][None], 'cam')
        runs[mode] = [o.joints_metric for o in outs if isinstance(o, HumanJointsOut)]
    scale = scene.true_scale
    expected = [scene.joints_cam[t] @ scene.R_wc_slam[t].T + scale * scene.c_slam[t]
                for t in range(len(scene.stamps_ns))][-len(runs['none']):]
    np.testing.assert_allclose(np.array(runs['none'])[:, 0], np.array(expected), atol=1e-9)
    for raw, smooth in zip(runs['none'], runs['smooth']):
        np.testing.assert_allclose(smooth - smooth[:, :1], raw - raw[:, :1], atol=1e-9)
        assert np.linalg.norm(smooth[0, 0] - raw[0, 0]) < 0.05
