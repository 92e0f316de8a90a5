"""Real-data composite for the accuracy benchmark (and a test): real SLAM, real motion, a made
scene.

Real: the camera trajectory a monocular ORB-SLAM produced on TUM RGB-D (``freiburg2_desk``: 157
keyframes over 91 s; ``freiburg1_xyz``: 32 over 18.6 s; arbitrary scale) is the SLAM input; its
motion-capture ground truth places the true cameras; the walker is real CMU motion capture (subject
131: two "Start Walk Stop" and one "Start Hop Stop"), its joints at their real heights above the
floor. Made, per seed: the walker's placement on the floor in front of the cameras (distance,
heading; the motion played forwards then backwards to cover the recording), the HMR prediction
(the true joints seen from the true camera with the simulator's HMR errors: joint noise, per-frame
depth noise, an optional depth bias, ``hac_ros.simulate.hmr``), and the map (textured floor points
seen by the true cameras, brought into the SLAM frame by the inverse of the Sim(3) fit of the SLAM
trajectory to the ground truth, plus 5 mm noise). The reference scale is that Sim(3) fit's scale.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from hac_ros.core.layouts import SMPL24
from hac_ros.evaluation import metrics
from hac_ros.files.tum import read_tum
from hac_ros.simulate.feed import ORDER
from hac_ros.simulate.hmr import DepthBias, predict

# TUM intrinsics (the dataset's published calibrations)
INTRINSICS = {'fr2_desk': np.array([[520.9, 0.0, 325.1], [0.0, 521.0, 249.7], [0.0, 0.0, 1.0]]),
              'freiburg1_xyz': np.array([[517.3, 0.0, 318.6], [0.0, 516.5, 255.3], [0.0, 0.0, 1.0]])}
TRAJECTORIES = {'fr2_desk': ('fr2_desk_ORB_kf_mono.txt', 'fr2_desk_groundtruth.txt'),
                'freiburg1_xyz': ('freiburg1_xyz-ORB_kf_mono.txt', 'freiburg1_xyz-groundtruth.txt')}
MOTIONS = ('scaled_131_01.npz', 'scaled_131_02.npz', 'scaled_131_03.npz')
WIDTH, HEIGHT = 640, 480
MAP_NOISE_M = 0.005
# the walker's distance from the mean camera centre along the mean horizontal view, metres: on
# freiburg1_xyz (the camera 1.6 m high, pitched about 48 degrees down) a steep view of a person
# 1-2 m away
WALKER_DISTANCE_M = {'fr2_desk': (2.0, 3.5), 'freiburg1_xyz': (1.2, 2.0)}
# a drifting composite: the SLAM's scale (metres per SLAM unit) grows by ``drift`` over this much
# stamp time, linearly, as the simulator's drift scenario; its map is republished this often,
# placed about the camera of that moment at the scale of that moment (tracking keeps the local map
# consistent with the current pose)
DRIFT_SPAN_S = 90.0
DRIFT_MAP_PERIOD_S = 2.0


@dataclass
class Composite:
    """One composite recording as arrays (frames and units in the names).

    Poses at ``stamps_ns`` (T,): ``R_wc_slam`` (T, 3, 3) camera to SLAM map, ``c_slam`` (T, 3)
    SLAM units; ``c_gt``, ``R_gt`` the true camera, metres, world (z up). Joints at
    ``frame_stamps_ns`` (F,): ``joints_cam`` (F, 24, 3) the HMR prediction, metres, camera optical
    frame; ``joints_world`` (F, 24, 3) the truth, world frame. ``points_slam`` (N, 3) the map,
    SLAM units. ``scale_fit``: the reference scale, metres per SLAM unit.
    """

    name: str
    K: np.ndarray
    stamps_ns: np.ndarray
    R_wc_slam: np.ndarray
    c_slam: np.ndarray
    R_gt: np.ndarray
    c_gt: np.ndarray
    scale_fit: float
    frame_stamps_ns: np.ndarray
    joints_cam: np.ndarray
    joints_world: np.ndarray
    points_slam: np.ndarray
    true_scale: np.ndarray
    maps: list[tuple[int, np.ndarray]]


def _y_up_to_z_up(joints: np.ndarray) -> np.ndarray:
    return np.stack([joints[..., 0], -joints[..., 2], joints[..., 1]], axis=-1)


def hand_eye(R_gt: np.ndarray, R_slam_world: np.ndarray) -> np.ndarray:
    """The constant rotation (3, 3) from the motion-capture "camera" frame to the optical frame
    the SLAM tracked: the mean of R_gt[i]^T R_slam_world[i] (both camera-to-world, (N, 3, 3)).

    SLAM estimates the orientation of the camera whose images it sees; an error it makes drifts, it
    cannot be constant in the camera's own frame. A constant part is the motion capture's
    marker-to-optical calibration: 0.8 deg on fr2_desk, 2.2 deg on freiburg1_xyz (mostly pitch,
    against a frame-to-frame spread of 0.2-0.6 deg). Left in, it tilts every joint's ray against
    the map by that much: about +3 % of scale at the walker's grazing angles, on every method.
    """
    return Rotation.from_matrix(np.einsum('nji,njk->nik', R_gt, R_slam_world)).mean().as_matrix()


def build(shared: Path, seed: int = 0, hmr_bias: float = 0.0, sequence: str | None = None,
          motion: int | None = None, rate: float | None = None,
          poses: str = 'orb', drift: float = 0.0) -> Composite:
    """The composite of ``seed``: sequence (fr2_desk for even seeds, freiburg1_xyz for every
    fourth odd one, unless given), motion (an index into MOTIONS, unless given), placement and
    noise drawn from the seed; ``hmr_bias``: the mean relative HMR depth bias (0: clean, no bias
    and no wander).

    ``rate`` None: the SLAM poses and the joints are at the real ORB-SLAM keyframes. A rate (Hz):
    the same scene (walker, placement, map: the same draws) seen by a camera at that frame rate
    between the first and the last keyframe, as a SLAM that publishes every frame: the true camera
    from the motion capture (interpolated), the SLAM pose the Sim(3) fit's image of it plus the
    SLAM's own error at the keyframes, interpolated between them (:func:`dense_poses`); its HMR
    noise drawn from a generator of its own.

    ``poses`` 'orb': the SLAM poses are ORB-SLAM's; 'fit': the Sim(3) fit's image of the true
    cameras, a SLAM without error (the map, the true floor brought into the SLAM frame by that
    fit, is then exactly consistent with its poses: bench/steep_views.py)."""
    rng = np.random.default_rng([seed, 7])
    if sequence is None:
        sequence = 'freiburg1_xyz' if seed % 4 == 3 else 'fr2_desk'
    tum = shared / 'tum_rgbd'
    est_ns, est_pos, est_q = read_tum(tum / TRAJECTORIES[sequence][0])
    gt_ns, gt_pos, gt_q = read_tum(tum / TRAJECTORIES[sequence][1])
    ia, ib = metrics.associate_stamps(est_ns, gt_ns, 10_000_000)
    stamps = est_ns[ia]
    c_slam, R_slam = est_pos[ia], Rotation.from_quat(est_q[ia]).as_matrix()
    c_gt, R_gt = gt_pos[ib], Rotation.from_quat(gt_q[ib]).as_matrix()
    s_fit, R_fit, t_fit = metrics.umeyama(c_slam, c_gt, with_scale=True)
    R_gt = R_gt @ hand_eye(R_gt, R_fit @ R_slam)
    if poses == 'fit':
        c_slam, R_slam = (c_gt - t_fit) @ R_fit / s_fit, np.einsum('ij,njk->nik', R_fit.T, R_gt)
    K = INTRINSICS[sequence]

    # the walker: real motion at its real heights, on the floor (z = 0) in front of the cameras
    drawn = int(rng.integers(len(MOTIONS)))  # drawn also when given: the other draws stay
    data = np.load(shared / 'cmu_mocap' / MOTIONS[drawn if motion is None else motion])
    walk = _y_up_to_z_up(data['joints'].astype(float))
    fps = float(data['fps'])
    view = np.mean(R_gt[:, :, 2], axis=0)
    view[2] = 0.0
    view /= np.linalg.norm(view)
    centre = np.mean(c_gt, axis=0) + rng.uniform(*WALKER_DISTANCE_M[sequence]) * view
    centre[2] = 0.0
    root_mid = walk[:, 0].mean(axis=0) * [1, 1, 0]
    heading = np.arctan2(view[1], view[0]) + rng.uniform(0.3, 2.8)  # across the view, any way
    R_place = Rotation.from_euler('z', heading).as_matrix()
    walk = (walk - root_mid) @ R_place.T + centre
    offset_s = rng.uniform(0.0, len(walk) / fps)

    period = len(walk)
    t_s = (stamps - stamps[0]) / 1e9
    bias = DepthBias(hmr_bias, t_s, rng, wander=hmr_bias != 0.0)
    joints_cam, joints_world, frame_stamps = [], [], []
    for i, t in enumerate(stamps):
        k = int(round((t_s[i] + offset_s) * fps)) % (2 * period - 2)
        k = k if k < period else 2 * period - 2 - k  # forwards, then backwards
        if _in_view(walk[k], R_gt[i], c_gt[i], K):
            prediction, _ = predict(walk[k], R_gt[i], c_gt[i], bias[i], rng, SMPL24)
            joints_cam.append(prediction)
            joints_world.append(walk[k])
            frame_stamps.append(int(t))

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
        u = K[0, 0] * pc[:, 0] / z + K[0, 2]
        v = K[1, 1] * pc[:, 1] / z + K[1, 2]
        seen |= (u >= 0) & (u < WIDTH) & (v >= 0) & (v < HEIGHT) & np.isfinite(z)
    floor = floor[seen] + rng.normal(0.0, MAP_NOISE_M, (int(seen.sum()), 3))
    points_slam = (floor - t_fit) @ R_fit / s_fit
    if rate is not None:  # the same scene seen at a frame rate (the docstring)
        stamps, R_slam, c_slam, R_gt, c_gt = dense_poses(
            stamps, R_slam, c_slam, R_gt, gt_ns, gt_pos, gt_q, (s_fit, R_fit, t_fit), rate)
        rng = np.random.default_rng([seed, 7, int(round(rate))])
        t_s = (stamps - stamps[0]) / 1e9
        bias = DepthBias(hmr_bias, t_s, rng, wander=hmr_bias != 0.0)
        joints_cam, joints_world, frame_stamps = [], [], []
    for i, t in enumerate(stamps if rate is not None else []):
        k = int(round((t_s[i] + offset_s) * fps)) % (2 * period - 2)
        k = k if k < period else 2 * period - 2 - k
        if _in_view(walk[k], R_gt[i], c_gt[i], K):
            prediction, _ = predict(walk[k], R_gt[i], c_gt[i], bias[i], rng, SMPL24)
            joints_cam.append(prediction)
            joints_world.append(walk[k])
            frame_stamps.append(int(t))
    growth = 1.0 + drift * (stamps - stamps[0]) / 1e9 / DRIFT_SPAN_S
    maps: list[tuple[int, np.ndarray]] = []
    if drift:
        c_slam, maps = drifted(stamps, c_slam, points_slam, growth)
    return Composite(sequence, K, stamps, R_slam, c_slam, R_gt, c_gt, float(s_fit),
                     np.array(frame_stamps, dtype=np.int64), np.array(joints_cam),
                     np.array(joints_world), points_slam, float(s_fit) * growth, maps)


def drifted(stamps: np.ndarray, c_slam: np.ndarray, points_slam: np.ndarray, growth: np.ndarray
            ) -> tuple[np.ndarray, list[tuple[int, np.ndarray]]]:
    """A SLAM whose scale is ``growth`` (T,) times its first one at each pose: its positions
    (T, 3), SLAM units, integrate each step at the scale of the moment; its maps, every
    DRIFT_MAP_PERIOD_S, are the points placed about the camera of that moment at that moment's
    scale: (stamp ns, (N, 3) SLAM units)."""
    steps = np.diff(c_slam, axis=0) / growth[1:, None]
    c_out = np.vstack([c_slam[:1], c_slam[0] + np.cumsum(steps, axis=0)])
    maps, next_ns = [], int(stamps[0])
    for i, stamp in enumerate(stamps):
        if stamp >= next_ns:
            maps.append((int(stamp), c_out[i] + (points_slam - c_slam[i]) / growth[i]))
            next_ns = int(stamp) + int(DRIFT_MAP_PERIOD_S * 1e9)
    return c_out, maps


def _in_view(joints_world: np.ndarray, R_gt: np.ndarray, c_gt: np.ndarray, K: np.ndarray) -> bool:
    """Whether the walker is seen (every joint in front, at least 4 in the image)."""
    Jc = (joints_world - c_gt) @ R_gt
    z = Jc[:, 2]
    if not np.all(z > 0.1):
        return False
    u = K[0, 0] * Jc[:, 0] / z + K[0, 2]
    v = K[1, 1] * Jc[:, 1] / z + K[1, 2]
    return bool(np.count_nonzero((u >= 0) & (u < WIDTH) & (v >= 0) & (v < HEIGHT)) >= 4)


def dense_poses(key_ns: np.ndarray, R_slam: np.ndarray, c_slam: np.ndarray, R_gt: np.ndarray,
                gt_ns: np.ndarray, gt_pos: np.ndarray, gt_q: np.ndarray,
                fit: tuple[float, np.ndarray, np.ndarray], rate: float
                ) -> tuple[np.ndarray, ...]:
    """Poses at ``rate`` Hz between the first and the last keyframe: (stamps ns, SLAM R_wc,
    SLAM c (SLAM units), true R (optical, hand-eye applied), true c (metres)).

    The true camera: the motion capture (gt_*, 100 Hz, camera-to-world) interpolated (slerp,
    linear), turned by the keyframes' constant hand-eye rotation (``R_gt`` (K, 3, 3) of the
    keyframes, already turned; :func:`hand_eye`). The SLAM pose: the inverse of the Sim(3) fit
    ``fit`` = (s, R, t) (metres = s R slam + t) applied to the true camera, plus the SLAM's own
    error at the keyframes (position in SLAM units, rotation) interpolated between keyframes, so
    that at a keyframe's stamp it is the keyframe itself.
    """
    s_fit, R_fit, t_fit = fit
    stamps = np.arange(int(key_ns[0]), int(key_ns[-1]) + 1, int(round(1e9 / rate)), dtype=np.int64)
    def seconds(ns: np.ndarray) -> np.ndarray:  # float seconds from the first keyframe
        return (ns - key_ns[0]) / 1e9

    keep = np.r_[True, np.diff(gt_ns) > 0]  # fr2_desk's ground truth repeats one stamp
    gt_ns, gt_pos, gt_q = gt_ns[keep], gt_pos[keep], gt_q[keep]
    t, t_key, t_gt = seconds(stamps), seconds(key_ns), seconds(gt_ns)
    gt_rot = Slerp(t_gt, Rotation.from_quat(gt_q))
    turn = np.einsum('nji,njk->nik', gt_rot(t_key).as_matrix(), R_gt)  # the hand-eye rotation
    R_true = gt_rot(t).as_matrix() @ Rotation.from_matrix(turn).mean().as_matrix()
    c_true = np.stack([np.interp(t, t_gt, gt_pos[:, k]) for k in range(3)], axis=1)
    c_key_true = np.stack([np.interp(t_key, t_gt, gt_pos[:, k]) for k in range(3)], axis=1)
    slam_of = (c_key_true - t_fit) @ R_fit / s_fit  # the fit's image of the true keyframes
    dc = c_slam - slam_of  # the SLAM's position error at the keyframes, SLAM units
    dR = Rotation.from_matrix(R_slam @ np.einsum('ij,njk->nik', R_fit.T, R_gt).transpose(0, 2, 1))
    c_out = (c_true - t_fit) @ R_fit / s_fit + np.stack(
        [np.interp(t, t_key, dc[:, k]) for k in range(3)], axis=1)
    R_out = Slerp(t_key, dR)(t).as_matrix() @ np.einsum('ij,njk->nik', R_fit.T, R_true)
    return stamps, R_out, c_out, R_true, c_true


def events(data: Composite) -> list[tuple[int, str, tuple]]:
    """The composite as calibrator inputs in SPEC order: (stamp, kind, payload) like
    ``hac_ros.simulate.feed.scenario_events`` (the map once, at the first stamp, unless the SLAM
    drifts)."""
    maps = data.maps or [(int(data.stamps_ns[0]), data.points_slam)]
    out: list[tuple[int, str, tuple]] = [(stamp, 'map', (points, 'map')) for stamp, points in maps]
    out += [(int(s), 'pose', (data.R_wc_slam[i], data.c_slam[i], 'map'))
            for i, s in enumerate(data.stamps_ns)]
    out += [(int(s), 'joints', (data.joints_cam[k][None], 'camera'))
            for k, s in enumerate(data.frame_stamps_ns)]
    return sorted(out, key=lambda e: (e[0], ORDER[e[1]]))
