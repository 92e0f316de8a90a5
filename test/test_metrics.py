"""Metrics against evo on real TUM data, and known answers for the human metrics."""
from __future__ import annotations

import copy

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hac_ros.core.basics.errors import InputError
from hac_ros.evaluation import metrics
from hac_ros.files.tum import read_tum, write_tum


def evo_pairs_and_ape(ref_path, est_path):
    """evo's own association and its APE means (Sim(3) and SE(3) alignment)."""
    from evo.core import sync
    from evo.core.metrics import PoseRelation
    from evo.main_ape import ape
    from evo.tools import file_interface

    ref = file_interface.read_tum_trajectory_file(str(ref_path))
    est = file_interface.read_tum_trajectory_file(str(est_path))
    ref, est = sync.associate_trajectories(ref, est)
    ref_xyz, est_xyz = ref.positions_xyz.copy(), est.positions_xyz.copy()
    # ape() aligns the estimate in place: give each call its own copy
    means = {scale: ape(copy.deepcopy(ref), copy.deepcopy(est), PoseRelation.translation_part,
                        align=True, correct_scale=scale).stats['mean'] for scale in (True, False)}
    assert np.array_equal(est.positions_xyz, est_xyz)
    return ref_xyz, est_xyz, means


@pytest.mark.parametrize('name, expected_scale', [('fr2_desk', 2.23), ('freiburg1_xyz', 1.11)])
def test_ate_and_ate_s_agree_with_evo_on_real_tum_trajectories(shared_data, name, expected_scale):
    folder = shared_data / 'tum_rgbd'
    est_path = folder / (f'{name}_ORB_kf_mono.txt' if name == 'fr2_desk' else f'{name}-ORB_kf_mono.txt')
    ref_path = folder / (f'{name}_groundtruth.txt' if name == 'fr2_desk' else f'{name}-groundtruth.txt')
    ref, est, evo_means = evo_pairs_and_ape(ref_path, est_path)
    # the same pose pairs: our ATE / ATE-S against evo's stats['mean']
    assert metrics.ate(est, ref) == pytest.approx(evo_means[True], rel=1e-6)
    assert metrics.ate_s(est, ref) == pytest.approx(evo_means[False], rel=1e-6)
    assert evo_means[False] > 2 * evo_means[True]  # the unknown scale shows without Sim(3)
    s, _, _ = metrics.umeyama(est, ref, with_scale=True)
    assert s == pytest.approx(expected_scale, rel=0.01)
    # our association (integer nanoseconds) pairs the same poses as evo's (float seconds) except
    # where two reference stamps are equally near, which float rounding decides either way
    est_ns, est_p, _ = read_tum(est_path)
    ref_ns, ref_p, _ = read_tum(ref_path)
    ia, ib = metrics.associate_stamps(est_ns, ref_ns, 10_000_000)
    assert len(ia) == len(est)
    differ = np.flatnonzero(np.any(ref_p[ib] != ref, axis=1))
    for k in differ:
        gaps = np.sort(np.abs(ref_ns - est_ns[ia[k]]))[:2]
        assert gaps[1] - gaps[0] <= 1000, 'a pairing differs from evo without a tie'
    assert metrics.ate(est_p[ia], ref_p[ib]) == pytest.approx(evo_means[True], rel=1e-3)


def test_read_tum_matches_evo_and_write_tum_round_trips(shared_data, tmp_path):
    from evo.tools import file_interface

    path = shared_data / 'tum_rgbd' / 'fr2_desk_ORB_kf_mono.txt'
    stamps, pos, quats = read_tum(path)
    traj = file_interface.read_tum_trajectory_file(str(path))
    np.testing.assert_allclose(stamps / 1e9, traj.timestamps, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(pos, traj.positions_xyz)
    np.testing.assert_allclose(quats, traj.orientations_quat_wxyz[:, [1, 2, 3, 0]])
    out = tmp_path / 'copy.txt'
    write_tum(out, stamps, pos, quats)
    back = file_interface.read_tum_trajectory_file(str(out))
    np.testing.assert_allclose(back.positions_xyz, pos, atol=1e-9)
    assert read_tum(out)[0].tolist() == stamps.tolist()


def random_sim3(rng):
    return rng.uniform(0.1, 10), Rotation.random(random_state=int(rng.integers(1e6))).as_matrix(), \
        rng.normal(0, 5, 3)


def test_umeyama_recovers_a_known_similarity_exactly():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(50, 3))
    s, R, t = random_sim3(rng)
    dst = metrics.apply_sim3(s, R, t, src)
    s2, R2, t2 = metrics.umeyama(src, dst, with_scale=True)
    assert s2 == pytest.approx(s, rel=1e-9)
    np.testing.assert_allclose(R2, R, atol=1e-9)
    np.testing.assert_allclose(t2, t, atol=1e-8)
    s3, R3, _ = metrics.umeyama(src, metrics.apply_sim3(1.0, R, t, src), with_scale=False)
    assert s3 == 1.0 and np.allclose(R3, R, atol=1e-9)
    with pytest.raises(InputError):
        metrics.umeyama(np.ones((5, 3)), np.ones((5, 3)))
    with pytest.raises(InputError):
        metrics.umeyama(src[:2], dst[:2])


def test_human_metrics_known_answers():
    rng = np.random.default_rng(1)
    gt = rng.normal(size=(250, 24, 3)) + np.linspace(0, 10, 250)[:, None, None] * [1, 0, 0]
    s, R, t = random_sim3(rng)
    pred = metrics.apply_sim3(s, R, t, gt)
    for fn in (metrics.w_mpjpe, metrics.wa_mpjpe, metrics.pa_mpjpe):
        assert fn(pred, gt) == pytest.approx(0.0, abs=1e-6)
    # a wrong global scale: RTE sees it, PA-MPJPE does not
    scaled = gt * 1.5
    assert metrics.pa_mpjpe(scaled, gt) == pytest.approx(0.0, abs=1e-6)
    root = np.c_[np.linspace(0, 10, 250), np.zeros(250), np.full(250, 0.9)]  # a 10 m straight walk
    expected = np.mean(np.abs(0.5 * (root[:, 0] - root[:, 0].mean()))) / 10 * 100
    assert metrics.rte(root * 1.5, root) == pytest.approx(expected, rel=1e-6)
    assert metrics.rte(root + [3.0, -2.0, 1.0], root) == pytest.approx(0.0, abs=1e-9)


def test_wa_mpjpe_chunks_like_tram():
    """250 frames: chunks [0, 100) and [100, 249) (TRAM stops one frame short); chunk errors
    differ."""
    rng = np.random.default_rng(2)
    gt = rng.normal(size=(250, 24, 3))
    pred = gt.copy()
    pred[100:, 5] += [0.0, 0.03, 0.0]  # one joint 30 mm off in the second chunk only
    got = metrics.wa_mpjpe(pred, gt)
    # by hand: chunk 2 is aligned on itself, so compute its residual the same way
    second = pred[100:249]
    s, R, t = metrics.umeyama(second.reshape(-1, 3), gt[100:249].reshape(-1, 3))
    err2 = np.linalg.norm(metrics.apply_sim3(s, R, t, second) - gt[100:249], axis=2).mean(axis=1)
    expected = np.concatenate([np.zeros(100), err2]).mean() * 1000
    assert got == pytest.approx(expected, rel=1e-9)
    assert got > 0.5


def test_w_mpjpe_aligns_on_the_first_two_frames():
    gt = np.zeros((3, 24, 3))
    gt[:, :, 0] = np.arange(24)
    gt[:, :, 1] = np.arange(24) % 5
    gt[:, :, 2] = np.arange(3)[:, None]
    pred = gt.copy()
    pred[2] += [0.01, 0.0, 0.0]  # the third frame drifts 10 mm
    assert metrics.w_mpjpe(pred, gt) == pytest.approx(10.0 / 3, rel=1e-9)


def test_scale_error_is_a_percentage():
    np.testing.assert_allclose(metrics.scale_error([2.2, 1.8], 2.0), [10.0, 10.0])


def test_associate_stamps_pairs_nearest_within_tolerance():
    a = np.array([100, 205, 400])
    b = np.array([0, 100, 200, 300])
    ia, ib = metrics.associate_stamps(a, b, 10)
    assert ia.tolist() == [0, 1] and ib.tolist() == [1, 2]


def test_rpe_is_frame_invariant_and_measures_a_scale_error_in_percent():
    """RPE (hac eval's odometry metric): a rigid motion of the estimate changes nothing; a 3 %
    scale error is 3 % of the distance; a jump costs its size once per pair that spans it."""
    rng = np.random.default_rng(0)
    n = 300
    stamps = (np.arange(n) * 1e9 / 30).astype(np.int64)
    R_gt = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.02, (n, 3)), axis=0)).as_matrix()
    p_gt = np.cumsum(rng.normal(0, 0.05, (n, 3)), axis=0)
    G = Rotation.from_rotvec([0.3, -1.0, 2.0]).as_matrix()
    m, pct = metrics.rpe(p_gt @ G.T + [5.0, -2.0, 1.0], G @ R_gt, p_gt, R_gt, stamps)
    assert m == pytest.approx(0.0, abs=1e-12) and pct == pytest.approx(0.0, abs=1e-9)
    m, pct = metrics.rpe(1.03 * p_gt, R_gt, p_gt, R_gt, stamps)
    assert pct == pytest.approx(3.0, rel=1e-9)
    jumped = p_gt.copy()
    jumped[150:] += [0.2, 0.0, 0.0]
    m, _ = metrics.rpe(jumped, R_gt, p_gt, R_gt, stamps)
    spanning = 30  # pairs (i, i + 30 frames) with i < 150 <= i + 30
    assert m == pytest.approx(0.2 * spanning / (n - 30), rel=1e-9)
    assert np.isnan(metrics.rpe(p_gt[:10], R_gt[:10], p_gt[:10], R_gt[:10], stamps[:10])[0])
