"""Real-data composite for the accuracy benchmark (and a test): real SLAM, real motion, a made scene.

Real: the camera trajectory a monocular ORB-SLAM produced on TUM RGB-D ``freiburg2_desk`` (157
keyframes, arbitrary scale) is the SLAM input; its motion-capture ground truth places the true
cameras; the walker is real CMU motion capture (subject 131, "Start Walk Stop").
Made: the walker's placement on the floor in front of the cameras (played forwards and backwards
to cover the 91 s), the HMR prediction (the true joints seen from the true camera plus 2 cm noise),
and the map (textured floor points seen by the true cameras, brought into the SLAM frame by the
inverse of the Sim(3) fit of the SLAM trajectory to the ground truth, plus 5 mm noise).
The reference scale is that Sim(3) fit's scale (≈ 2.23 metres per SLAM unit).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from hac_ros.core import metrics
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.estimator import sequence_scale
from hac_ros.core.outputs import ResetOut, SampleOut, ScaleOut
from hac_ros.core.params import HacParams
from hac_ros.tum import read_tum

# TUM freiburg2 intrinsics (the dataset's published calibration)
K_FR2 = np.array([[520.9, 0.0, 325.1], [0.0, 521.0, 249.7], [0.0, 0.0, 1.0]])
WIDTH, HEIGHT = 640, 480
HMR_NOISE_M = 0.02
MAP_NOISE_M = 0.005
WALKER_DISTANCE_M = 2.5  # from the mean camera centre along the mean horizontal view direction


def _y_up_to_z_up(joints: np.ndarray) -> np.ndarray:
    return np.stack([joints[..., 0], -joints[..., 2], joints[..., 1]], axis=-1)


def build(shared: Path, seed: int = 0) -> dict:
    """The composite's inputs; every array's frame and unit in its key."""
    rng = np.random.default_rng(seed)
    tum = shared / 'tum_rgbd'
    est_ns, est_pos, est_q = read_tum(tum / 'fr2_desk_ORB_kf_mono.txt')
    gt_ns, gt_pos, gt_q = read_tum(tum / 'fr2_desk_groundtruth.txt')
    ia, ib = metrics.associate_stamps(est_ns, gt_ns, 10_000_000)
    stamps = est_ns[ia]
    c_slam, R_slam = est_pos[ia], Rotation.from_quat(est_q[ia]).as_matrix()
    c_gt, R_gt = gt_pos[ib], Rotation.from_quat(gt_q[ib]).as_matrix()
    s_fit, R_fit, t_fit = metrics.umeyama(c_slam, c_gt, with_scale=True)

    # the walker: real motion, placed on the floor (z = 0) in front of the cameras
    motion = np.load(shared / 'cmu_mocap' / 'scaled_131_01.npz')
    walk = _y_up_to_z_up(motion['joints'].astype(float))
    fps = float(motion['fps'])
    view = np.mean(R_gt[:, :, 2], axis=0)
    view[2] = 0.0
    view /= np.linalg.norm(view)
    centre = np.mean(c_gt, axis=0) + WALKER_DISTANCE_M * view
    centre[2] = 0.0
    root_mid = walk[:, 0].mean(axis=0) * [1, 1, 0]
    heading = np.arctan2(view[1], view[0]) + np.pi / 2  # walk across the view
    R_place = Rotation.from_euler('z', heading).as_matrix()
    walk = (walk - root_mid) @ R_place.T + centre

    period = len(walk)
    joints_cam, joints_world, frame_stamps, frame_idx = [], [], [], []
    for i, t in enumerate(stamps):
        k = int(round((t - stamps[0]) / 1e9 * fps)) % (2 * period - 2)
        k = k if k < period else 2 * period - 2 - k  # forwards, then backwards
        Jw = walk[k]
        Jc = (Jw - c_gt[i]) @ R_gt[i]
        z = Jc[:, 2]
        if np.all(z > 0.1):
            u = K_FR2[0, 0] * Jc[:, 0] / z + K_FR2[0, 2]
            v = K_FR2[1, 1] * Jc[:, 1] / z + K_FR2[1, 2]
            if np.any((u >= 0) & (u < WIDTH) & (v >= 0) & (v < HEIGHT)):
                joints_cam.append(Jc + rng.normal(0.0, HMR_NOISE_M, Jc.shape))
                joints_world.append(Jw)
                frame_stamps.append(int(t))
                frame_idx.append(i)

    # textured floor points seen by at least one true camera (30 % of a 4 cm grid)
    lo = np.minimum(c_gt.min(0), walk[:, 0].min(0)) - 4.0
    hi = np.maximum(c_gt.max(0), walk[:, 0].max(0)) + 4.0
    xs, ys = np.arange(lo[0], hi[0], 0.04), np.arange(lo[1], hi[1], 0.04)
    xx, yy = np.meshgrid(xs, ys)
    floor = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], 1)
    floor = floor[rng.random(len(floor)) < 0.3]
    seen = np.zeros(len(floor), dtype=bool)
    for i in range(0, len(stamps), 3):
        pc = (floor - c_gt[i]) @ R_gt[i]
        z = np.where(pc[:, 2] > 0.1, pc[:, 2], np.inf)
        u = K_FR2[0, 0] * pc[:, 0] / z + K_FR2[0, 2]
        v = K_FR2[1, 1] * pc[:, 1] / z + K_FR2[1, 2]
        seen |= (u >= 0) & (u < WIDTH) & (v >= 0) & (v < HEIGHT) & np.isfinite(z)
    floor = floor[seen] + rng.normal(0.0, MAP_NOISE_M, (int(seen.sum()), 3))
    points_slam = (floor - t_fit) @ R_fit / s_fit
    return dict(stamps_ns=stamps, R_wc_slam=R_slam, c_slam=c_slam, c_gt=c_gt, scale_fit=s_fit,
                frame_stamps_ns=np.array(frame_stamps, dtype=np.int64), frame_index=np.array(frame_idx),
                joints_cam=joints_cam, joints_world=joints_world, points_slam=points_slam)


def run(data: dict, params: HacParams | None = None) -> dict:
    """Feed the composite to a Calibrator in SPEC order; returns the figures."""
    cal = Calibrator(params or HacParams())
    cal.add_camera_info(K_FR2, WIDTH, HEIGHT, 'camera')
    outs = cal.add_map(int(data['stamps_ns'][0]), data['points_slam'], 'map')
    frames = dict(zip(data['frame_stamps_ns'].tolist(), range(len(data['frame_stamps_ns']))))
    for i, t in enumerate(data['stamps_ns']):
        outs += cal.add_pose(int(t), data['R_wc_slam'][i], data['c_slam'][i], 'map')
        if int(t) in frames:
            outs += cal.add_joints(int(t), data['joints_cam'][frames[int(t)]][None], 'camera')
    outs += cal.flush()
    accepted = np.array([o.scale for o in outs if isinstance(o, SampleOut) and o.accepted])
    online = np.array([o.scale for o in outs if isinstance(o, ScaleOut)])
    offline = sequence_scale(accepted)
    truth = data['scale_fit']
    cams = offline * data['c_slam']
    return {
        'Sim(3) scale of SLAM to ground truth (reference)': truth,
        'keyframes (SLAM poses)': len(data['stamps_ns']),
        'frames with the walker in view': len(frames),
        'map points (made)': len(data['points_slam']),
        'offline scale (sequence median)': offline,
        'offline scale error %': abs(offline / truth - 1) * 100,
        'online scale at the end': float(online[-1]) if online.size else float('nan'),
        'online scale error at the end %': abs(online[-1] / truth - 1) * 100 if online.size else float('nan'),
        'fallback rate %': 100 * cal.status().fallback_rate,
        'resets detected': sum(isinstance(o, ResetOut) for o in outs),
        'ATE-S of the calibrated trajectory, m': metrics.ate_s(cams, data['c_gt']),
        'ATE-S with the reference scale, m': metrics.ate_s(truth * data['c_slam'], data['c_gt']),
    }


def real_composite(shared: Path) -> dict:
    data = build(shared)
    return {'description': __doc__.split('\n', 1)[1].strip().replace('\n', ' '), 'figures': run(data)}
