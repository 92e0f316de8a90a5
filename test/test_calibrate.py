"""``from hac_ros import calibrate``: one call on numpy arrays equals ``hac import`` + ``hac replay``.

The same arrays go through both paths: written as files (TUM, .npy map, joints .npz), imported
and replayed; and handed to :func:`hac_ros.calibrate`. A simulated walk and the real-data composite
(real ORB-SLAM keyframes and CMU motion, bench/composite.py; skipped without ../shared/data).
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from hac_ros.cli import main as hac
from hac_ros.core.basics.errors import InputError
from hac_ros.files.tum import rotations_to_quats

REPO = Path(__file__).resolve().parents[1]
CAMERA = (np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]), (640, 480))
TOLERANCE = 0.001  # the issue: equal to the replay within 0.1 %


def write_files(d: Path, t_s: np.ndarray, R_wc: np.ndarray, c: np.ndarray, points: np.ndarray,
                joint_t_s: np.ndarray, joints: np.ndarray) -> dict[str, Path]:
    d.mkdir(parents=True, exist_ok=True)
    lines = [repr(float(t)) + ' ' + ' '.join(repr(float(v)) for v in (*p, *q))
             for t, p, q in zip(t_s, c, rotations_to_quats(R_wc))]
    (d / 'traj.tum').write_text('\n'.join(lines) + '\n')
    np.save(d / 'map.npy', points)
    np.savez(d / 'joints.npz', stamps=joint_t_s, joints=joints)
    return {'trajectory': d / 'traj.tum', 'map': d / 'map.npy', 'joints': d / 'joints.npz'}


def import_and_replay(files: dict[str, Path], out: Path, camera: tuple[np.ndarray, tuple[int, int]],
                      mode: str = 'offline') -> dict[str, list]:
    """hac import + hac replay; the output recording's messages by topic."""
    (K, (w, h)) = camera
    args = ['import', '-o', str(out / 'rec'), '--trajectory', str(files['trajectory']),
            '--map', str(files['map']), '--joints', str(files['joints']),
            '--camera', ','.join(repr(float(v)) for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))
            + f',{w},{h}']
    assert hac(args) == 0
    assert hac(['replay', str(out / 'rec'), '-o', str(out / 'out'), '--mode', mode,
                '--no-progress']) == 0
    got: dict[str, list] = {}
    with AnyReader([out / 'out'], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, log_ns, raw in reader.messages():
            got.setdefault(conn.topic, []).append((log_ns, reader.deserialize(raw, conn.msgtype)))
    return got


@pytest.fixture(scope='module')
def walk():
    """The simulated walk as arrays: every pose, joints at the pose stamps (NaN where nobody is in
    view), the last map."""
    from hac_ros.simulate import make_scenario

    sc = make_scenario('walk', seed=4, duration=8.0)
    t_s = sc.pose_stamps_ns / 1e9
    row = {int(s): i for i, s in enumerate(sc.pose_stamps_ns)}
    people = max(len(j) for j in sc.joints_cam)
    joints = np.full((len(t_s), people, 24, 3), np.nan)
    for k, stamp in enumerate(sc.joints_stamps_ns):
        joints[row[int(stamp)], :len(sc.joints_cam[k])] = sc.joints_cam[k]
    return {'sc': sc, 't_s': t_s, 'R_wc': sc.slam_R_wc, 'c': sc.slam_c,
            'points': sc.maps[-1].points_slam.astype(float), 'joints': joints}


@pytest.mark.parametrize('mode', ['offline', 'online'])
def test_calibrate_equals_import_and_replay_on_a_simulated_walk(walk, tmp_path, mode):
    from hac_ros import calibrate

    files = write_files(tmp_path, walk['t_s'], walk['R_wc'], walk['c'], walk['points'],
                        walk['t_s'], walk['joints'])
    replayed = import_and_replay(files, tmp_path, CAMERA, mode)
    result = calibrate(walk['t_s'], walk['R_wc'], walk['c'], walk['points'], walk['joints'],
                       K=CAMERA[0], image_size=CAMERA[1], mode=mode)
    final = replayed['/hac/scale'][-1][1].data
    assert result.scale == pytest.approx(final, rel=TOLERANCE)
    assert result.converged and result.mode == mode
    assert abs(result.scale / walk['sc'].true_scale[-1] - 1.0) < 0.03

    # per frame: the scale published with each joints frame, the world joints, the camera
    scales = {t: m.data for (t, _), (_, m) in zip(replayed['/hac/human_joints'],
                                                  replayed['/hac/scale'])}
    stamps = np.round(walk['t_s'] * 1e9).astype(np.int64)
    published = np.isfinite(result.frame_scales)
    assert sorted(scales) == stamps[published].tolist()
    assert np.allclose(result.frame_scales[published], [scales[s] for s in stamps[published]],
                       rtol=TOLERANCE)
    joints = {t: m for t, m in replayed['/hac/human_joints']}
    t = int(np.flatnonzero(published)[len(np.flatnonzero(published)) // 2])
    present = ~np.isnan(walk['joints'][t]).all(axis=(1, 2))
    mine = result.joints_world[t][present]
    theirs = np.array([[p.position.x, p.position.y, p.position.z]
                       for p in joints[int(stamps[t])].poses]).reshape(mine.shape)
    assert np.abs(mine - theirs).max() < 0.01  # metres
    assert np.isnan(result.joints_world[t][~present]).all()
    poses = {t: m.pose.pose.position for t, m in replayed['/hac/pose']}
    placed = np.isfinite(result.camera_position[:, 0])
    assert sorted(poses) == stamps[placed].tolist()
    i = int(np.flatnonzero(placed)[-1])
    p = poses[int(stamps[i])]
    assert np.abs(result.camera_position[i] - [p.x, p.y, p.z]).max() < 0.01
    assert result.counts['frames'] == len(walk['sc'].joints_stamps_ns)
    assert result.samples.shape == walk['joints'].shape[:2]
    assert set(result.sources[np.isfinite(result.samples)]) <= {'map', 'ground'}


def test_calibrate_equals_import_and_replay_on_the_real_data_composite(shared_data, tmp_path):
    """Real ORB-SLAM keyframes (fr2_desk, 1.3 Hz) and a real CMU walk; the joints at the keyframe
    stamps, one person."""
    sys.path.insert(0, str(REPO / 'bench'))
    try:
        from composite import HEIGHT, WIDTH, build
    finally:
        sys.path.remove(str(REPO / 'bench'))
    from hac_ros import calibrate

    data = build(shared_data, seed=0)
    t_s, joint_t_s = data.stamps_ns / 1e9, data.frame_stamps_ns / 1e9
    joints = data.joints_cam[:, None]  # (F, 1, 24, 3)
    files = write_files(tmp_path, t_s, data.R_wc_slam, data.c_slam, data.points_slam, joint_t_s,
                        joints)
    camera = (data.K, (WIDTH, HEIGHT))
    replayed = import_and_replay(files, tmp_path, camera)
    result = calibrate(t_s, data.R_wc_slam, data.c_slam, data.points_slam, joints,
                       joint_stamps=joint_t_s, K=data.K, image_size=(WIDTH, HEIGHT))
    assert result.scale == pytest.approx(replayed['/hac/scale'][-1][1].data, rel=TOLERANCE)
    assert abs(result.scale / data.scale_fit - 1.0) < 0.05
    literal = calibrate(t_s, data.R_wc_slam, data.c_slam, data.points_slam, joints,
                        joint_stamps=joint_t_s, literal=True)
    assert literal.mode == 'literal' and abs(literal.scale / data.scale_fit - 1.0) < 0.10


def grid_scene(scale: float = 2.0, frames: int = 20):
    """A made scene whose literal answer is exact: 24 'joints' on a 6 x 4 grid 4 m ahead of a
    camera moving sideways, each joint's map point exactly on its ray and alone in its cone."""
    xs, ys = np.meshgrid(np.linspace(-1.5, 1.5, 6), np.linspace(-1.0, 1.0, 4))
    world = np.stack([xs.ravel(), ys.ravel(), np.full(24, 4.0)], axis=1)  # metres
    t_s = 100.0 + np.arange(frames) / 10.0
    c_world = np.stack([np.linspace(0.0, 0.5, frames), np.zeros(frames), np.zeros(frames)], 1)
    joints = (world[None] - c_world[:, None])[:, None]  # (T, 1, 24, 3), camera = world axes
    R = np.broadcast_to(np.eye(3), (frames, 3, 3)).copy()
    return t_s, R, c_world / scale, world / scale, joints, world


def test_literal_is_the_authors_method_with_the_replays_stamp_matching():
    from hac_ros import calibrate

    t_s, R, c, points, joints, world = grid_scene(scale=2.0)
    result = calibrate(t_s, R, c, points, joints, literal=True)
    assert result.scale == pytest.approx(2.0, rel=1e-12)
    assert np.allclose(result.samples, 2.0) and np.allclose(result.frame_scales, 2.0)
    assert np.allclose(result.joints_world[:, 0], world[None], atol=1e-12)  # R J + s c
    assert np.allclose(result.camera_position, 2.0 * c)

    # joints between two poses are matched by interpolation (the camera moves linearly), one
    # within the slop takes its pose, one outside the trajectory is counted and left out
    mid = (t_s[:-1] + t_s[1:]) / 2
    mid_joints = (world[None] - (c[:-1] + c[1:])[:, None] / 2 * 2.0)[:, None]
    stamps = np.concatenate([mid, [t_s[-1] + 0.003, t_s[-1] + 5.0]])
    more = np.concatenate([mid_joints, joints[-1:], joints[-1:]])
    result = calibrate(t_s, R, c, points, more, joint_stamps=stamps, literal=True)
    assert result.scale == pytest.approx(2.0, rel=1e-9)
    assert result.counts['rejected'] == {'no_pose': 1} and result.counts['frames'] == len(mid) + 1
    assert np.isnan(result.frame_scales[-1]) and np.isfinite(result.frame_scales[:-1]).all()


def test_a_person_absent_from_a_frame_keeps_its_place():
    from hac_ros import calibrate

    t_s, R, c, points, joints, _ = grid_scene()
    two = np.concatenate([joints, joints], axis=1)  # (T, 2, 24, 3)
    two[3, 0] = np.nan  # person 0 absent from frame 3
    two[5] = np.nan  # nobody in frame 5
    result = calibrate(t_s, R, c, points, two, literal=True)
    assert np.isnan(result.samples[3, 0]) and result.samples[3, 1] == pytest.approx(2.0)
    assert np.isnan(result.joints_world[3, 0]).all() and np.isfinite(result.joints_world[3, 1]).all()
    assert np.isnan(result.samples[5]).all() and result.sources[5, 0] == ''


def _bad(case: str) -> dict:
    """The grid scene's arguments with one made wrong (``case``)."""
    t_s, R, c, points, joints, _ = grid_scene()
    args = {'pose_stamps': t_s, 'R_wc': R, 'c_map': c, 'points_map': points, 'joints_cam': joints}
    wrong = {
        'stamps 2-D': {'pose_stamps': t_s[None]},
        'stamps text': {'pose_stamps': 'soon'},
        'stamps back': {'pose_stamps': t_s[::-1]},
        'stamps negative': {'pose_stamps': t_s - 1000.0},
        'R short': {'R_wc': R[:3]},
        'R scaled': {'R_wc': np.concatenate([R[:2], 2 * R[2:]])},
        'c short': {'c_map': c[:3]},
        'c NaN': {'c_map': np.where(c > 0.2, np.nan, c)},
        'points 2-D': {'points_map': np.ones((5, 2))},
        'points zero': {'points_map': np.zeros((5, 3))},
        'joints COCO': {'joints_cam': joints[:, :, :17]},
        'joints empty': {'joints_cam': np.full_like(joints, np.nan)},
        'joints inf': {'joints_cam': np.where(joints > 3.9, np.inf, joints)},
        'joints fewer': {'joints_cam': joints[1:]},
        'joint stamps fewer': {'joint_stamps': t_s[1:]},
        'K 2x2': {'K': np.eye(2)},
        'image size': {'K': CAMERA[0], 'image_size': (640, 0)},
        'mode': {'mode': 'batch'},
        'params': {'params': {'window_s': -1.0}},
        'layout': {'joint_layout': 'smpl99'},
    }[case]
    return {**args, **wrong}


@pytest.mark.parametrize('case, fragment', [
    ('stamps 2-D', 'pose_stamps: expected a non-empty (N,) array of seconds, got shape (1, 20)'),
    ('stamps text', 'pose_stamps: expected (N,) numbers (seconds)'),
    ('stamps back', 'pose_stamps: stamps must increase (seconds), but [1]'),
    ('stamps negative', 'pose_stamps: [0] = -900.0 s is not a ROS time'),
    ('R short', 'R_wc: expected (N, 3, 3) camera-to-map rotations with N = len(pose_stamps) = 20, '
                'got shape (3, 3, 3)'),
    ('R scaled', 'R_wc: [2] is not a rotation matrix'),
    ('c short', 'c_map: expected (N, 3) finite camera centres in SLAM units with N = '
                'len(pose_stamps) = 20, got shape (3, 3)'),
    ('c NaN', 'with non-finite values'),
    ('points 2-D', 'points_map: expected (M, 3) map points in SLAM units, got shape (5, 2)'),
    ('points zero', 'points_map: no finite map point other than (0, 0, 0)'),
    ('joints COCO', 'joints_cam: expected (T, P, K, 3) metres in the camera optical frame with '
                    'K = 24 (smpl24), got shape (20, 1, 17, 3)'),
    ('joints empty', 'joints_cam: no person in any frame'),
    ('joints inf', 'joints_cam: holds inf values (metres'),
    ('joints fewer', 'joints_cam: 19 frames but no joint_stamps'),
    ('joint stamps fewer', 'joint_stamps: 19 stamps (seconds) but joints_cam has 20 frames'),
    ('K 2x2', 'K: expected (3, 3) finite intrinsics in pixels'),
    ('image size', 'image_size: expected positive (width, height) in pixels, got (640, 0)'),
    ('mode', 'mode: expected one of offline, online'),
    ('params', 'window_s'),
    ('layout', 'joint_layout'),
])
def test_every_input_is_validated_naming_the_argument_its_shape_and_unit(case, fragment):
    from hac_ros import calibrate
    from hac_ros.core.basics.errors import HacError

    with pytest.raises(HacError) as caught:  # InputError; ParameterError for params
        calibrate(**_bad(case))
    assert fragment in str(caught.value), str(caught.value)
    assert isinstance(caught.value, InputError) or case in ('params', 'layout')


def test_importing_hac_ros_imports_no_ros_and_calibrate_lazily():
    code = ('import sys, hac_ros; assert "hac_ros.api" not in sys.modules; '
            'from hac_ros import calibrate, CalibrationResult; '
            'assert not [m for m in sys.modules if m.split(".")[0] in '
            '("rclpy", "rosbags", "geometry_msgs", "hac_ros.ros")]; print(calibrate.__name__)')
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, cwd=REPO)
    assert done.returncode == 0 and done.stdout.strip() == 'calibrate', done.stderr


def test_the_readme_example_runs(walk, tmp_path):
    """The README's calibrate example, run as it is on a simulated walk's arrays saved as the
    files it reads (tstamp in seconds)."""
    import re

    readme = (REPO / 'README.md').read_text()
    block = next(b for b in re.findall(r'```python\n(.*?)```', readme, re.S) if 'calibrate(' in b)
    quats = rotations_to_quats(walk['R_wc'])
    np.savez(tmp_path / 'masked_droid_slam.npz', traj=np.concatenate([walk['c'], quats], 1),
             tstamp=walk['t_s'])
    np.savez(tmp_path / 'joints.npz', stamps=walk['t_s'], joints=walk['joints'])
    np.save(tmp_path / 'map.npy', walk['points'])
    done = subprocess.run([sys.executable, '-c', block], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    scale, samples = done.stdout.split()
    assert abs(float(scale) / walk['sc'].true_scale[-1] - 1.0) < 0.03 and int(samples) > 100


# the same bad arrays through both doors: calibrate() and hac import of them written as files
def _wrong_arrays(walk: dict, case: str) -> dict:
    joints, t_s = walk['joints'], walk['t_s']
    return {'millimetres': {'joints': joints * 1000.0},
            'centimetres': {'joints': joints * 100.0},
            'inf': {'joints': np.where(joints > 3.0, np.inf, joints)},
            'nobody': {'joints': np.full_like(joints, np.nan)},
            'COCO K': {'joints': joints[:, :, :17]},
            'joint stamps back': {'joint_t_s': t_s[::-1].copy()},
            'joint stamps before 1970': {'joint_t_s': t_s - t_s[0] - 100.0},
            'fewer joint stamps': {'joint_t_s': t_s[1:]}}[case]


@pytest.mark.parametrize('case', ['millimetres', 'centimetres', 'inf', 'nobody', 'COCO K',
                                  'joint stamps back', 'joint stamps before 1970',
                                  'fewer joint stamps'])
def test_calibrate_and_hac_import_say_the_same_of_the_same_bad_arrays(walk, tmp_path, capsys,
                                                                     case):
    """One check for both (hac_ros.core.input_checks): what is wrong is said in the same words;
    only how each names the input differs (calibrate's argument, import's file and array)."""
    from hac_ros import calibrate

    wrong = {'joints': walk['joints'], 'joint_t_s': walk['t_s'], **_wrong_arrays(walk, case)}
    with pytest.raises(InputError) as caught:
        calibrate(walk['t_s'], walk['R_wc'], walk['c'], walk['points'], wrong['joints'],
                  joint_stamps=wrong['joint_t_s'])
    said = str(caught.value)
    argument, _, what = said.partition(': ')
    assert argument in ('joints_cam', 'joint_stamps'), said
    files = write_files(tmp_path, walk['t_s'], walk['R_wc'], walk['c'], walk['points'],
                        wrong['joint_t_s'], wrong['joints'])
    assert hac(['import', '-o', str(tmp_path / 'rec'), '--trajectory', str(files['trajectory']),
                '--map', str(files['map']), '--joints', str(files['joints'])]
               + (['--joint-layout', 'smpl24'] if case == 'COCO K' else [])) == 2
    line = capsys.readouterr().err.strip()
    array = 'joints' if argument == 'joints_cam' else 'stamps'
    what = what.replace('joints_cam', 'joints')  # the other input, as each door names it
    assert line == f'hac import: error: joints {files["joints"]}: {array}: {what}', (said, line)


def test_millimetre_joints_raise_naming_the_argument_and_the_unit_expected(walk):
    """Not a silent 'scale nan' with rejected joints_not_metres: an InputError before anything
    runs."""
    from hac_ros import calibrate

    with pytest.raises(InputError, match=r'^joints_cam: .* HMR joints must be metres, about '
                                         r'1000x too large: millimetres\? \(the median of \d+ '
                                         r'people\)$'):
        calibrate(walk['t_s'], walk['R_wc'], walk['c'], walk['points'], walk['joints'] * 1000.0)
