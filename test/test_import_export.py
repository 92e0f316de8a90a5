"""``hac import`` and ``hac export``: real files in, real rosbag2 recordings out (read back with
rosbags), a simulated scenario round-tripped through files, every bad file refused cleanly."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from hac_ros.cli import main as hac
from hac_ros.files.map_files import read_map
from hac_ros.files.readers import read_trajectory, seconds_to_ns
from hac_ros.files.tum import rotations_to_quats
from hac_ros.simulate import make_scenario, write_recording
from msg_adapters import cloud_to_xyz, pose_array_to_joints, stamp_to_ns

SEED, DURATION = 3, 8.0
CAMERA = '500,500,320,240,640,480'  # the simulator's intrinsics (rigs.K_DEFAULT, 640 x 480)


# ============================================================================ file writers
def write_tum(path: Path, t_s: np.ndarray, positions: np.ndarray, rotations: np.ndarray) -> Path:
    lines = ['# timestamp tx ty tz qx qy qz qw']
    for t, p, q in zip(t_s, positions, rotations_to_quats(rotations)):
        lines.append(f'{t:.9f} ' + ' '.join(f'{v:.12g}' for v in (*p, *q)))
    path.write_text('\n'.join(lines) + '\n')
    return path


def write_ply(path: Path, points: np.ndarray, binary: bool = True,
              count: int | None = None) -> Path:
    """x y z as double plus a uchar colour, a face element after the vertices (both skipped)."""
    n = len(points) if count is None else count
    fmt = 'binary_little_endian' if binary else 'ascii'
    header = (f'ply\nformat {fmt} 1.0\ncomment written by the test\nelement vertex {n}\n'
              'property double x\nproperty double y\nproperty double z\nproperty uchar red\n'
              'element face 1\nproperty list uchar int vertex_indices\nend_header\n')
    if binary:
        table = np.zeros(len(points), dtype=[('x', '<f8'), ('y', '<f8'), ('z', '<f8'), ('r', 'u1')])
        table['x'], table['y'], table['z'], table['r'] = *points.T, 200
        body = table.tobytes() + bytes([3]) + np.array([0, 1, 2], '<i4').tobytes()
    else:
        rows = ''.join(f'{x!r} {y!r} {z!r} 200\n' for x, y, z in points.tolist())
        body = rows.encode() + b'3 0 1 2\n'
    path.write_bytes(header.encode() + body)
    return path


def joints_npz(path: Path, t_s: np.ndarray, joints: np.ndarray) -> Path:
    np.savez(path, stamps=t_s, joints=joints)
    return path


def read_bag(path: Path) -> dict[str, list]:
    """topic -> [(log ns, message)] of a recording, with rosbags alone."""
    out: dict[str, list] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, log_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((log_ns, reader.deserialize(raw, conn.msgtype)))
    return out


# ============================================================================ a scenario as files
@pytest.fixture(scope='module')
def files(tmp_path_factory):
    """The walk scenario as a SLAM's and an HMR's files: TUM trajectory, its last map (binary PLY,
    .npy, text), joints .npz at every pose stamp (NaN where nobody is in view), ground truth."""
    sc = make_scenario('walk', seed=SEED, duration=DURATION)
    d = tmp_path_factory.mktemp('files')
    t_s = np.array([float(f'{s / 1e9:.9f}') for s in sc.pose_stamps_ns])  # as a TUM file holds them
    row = {int(s): i for i, s in enumerate(sc.pose_stamps_ns)}
    people = max(len(j) for j in sc.joints_cam)
    joints = np.full((len(t_s), people, 24, 3), np.nan)
    truth = joints.copy()
    for k, stamp in enumerate(sc.joints_stamps_ns):
        joints[row[int(stamp)], :len(sc.joints_cam[k])] = sc.joints_cam[k]
        truth[row[int(stamp)], :len(sc.gt_joints_world[k])] = sc.gt_joints_world[k]
    points = sc.maps[-1].points_slam.astype(float)
    np.savetxt(d / 'map.txt', points)
    np.save(d / 'map.npy', points)
    return {'sc': sc, 'dir': d, 't_s': t_s, 'points': points,
            'trajectory': write_tum(d / 'slam.tum', t_s, sc.slam_c, sc.slam_R_wc),
            'gt_trajectory': write_tum(d / 'gt.tum', t_s, sc.gt_c, sc.gt_R_wc),
            'map': write_ply(d / 'map.ply', points),
            'joints': joints_npz(d / 'joints.npz', t_s, joints),
            'gt_joints': joints_npz(d / 'gt_joints.npz', t_s, truth)}


def import_args(files: dict, out: Path, **override: str) -> list[str]:
    args = {'--trajectory': files['trajectory'], '--map': files['map'], '--joints': files['joints'],
            '--camera': CAMERA, '--gt-trajectory': files['gt_trajectory'],
            '--gt-joints': files['gt_joints'], '--joint-layout': 'smpl24', **override}
    argv = ['import', '-o', str(out)]
    for flag, value in args.items():
        if value is not None:
            argv += [flag, str(value)]
    return argv


def test_round_trip_import_replay_eval_export(files, tmp_path, capsys):
    sc = files['sc']
    rec, out, npz = tmp_path / 'rec', tmp_path / 'out', tmp_path / 'hac.npz'
    assert hac(import_args(files, rec)) == 0
    assert (rec / 'params.yaml').read_text().splitlines()[:3] == [
        'hac_node:', '  ros__parameters:', '    joint_layout: smpl24']

    bag = read_bag(rec)  # every input topic, at the stamps of the files, in the simulator's frames
    poses = bag['/slam/pose']
    assert [t for t, _ in poses] == [stamp_to_ns(m.header.stamp) for _, m in poses]
    assert np.array_equal([t for t, _ in poses], seconds_to_ns(files['t_s']))
    assert np.abs(np.array([t for t, _ in poses]) - sc.pose_stamps_ns).max() < 1000  # < 1 us
    assert {m.header.frame_id for _, m in poses} == {'map'}
    (cloud_ns, cloud), = bag['/slam/cloud']
    assert cloud_ns == poses[0][0] and cloud.header.frame_id == 'map'
    assert np.allclose(cloud_to_xyz(cloud), files['points'])
    assert len(bag['/camera/camera_info']) == len(poses)
    assert len(bag['/hmr/joints']) == len(sc.joints_stamps_ns)  # frames with nobody not written
    _, first = bag['/hmr/joints'][0]
    assert first.header.frame_id == 'camera_optical'
    assert np.allclose(pose_array_to_joints(first, 24), sc.joints_cam[0])
    (_, gt_scale), = bag['/gt/scale']
    assert gt_scale.data == pytest.approx(sc.true_scale[0], rel=2e-3)  # Sim(3) fit vs the truth

    assert hac(['replay', str(rec), '-o', str(out), '--params', str(rec / 'params.yaml'),
                '--no-progress']) == 0
    assert hac(['eval', str(out), '--gt', str(rec), '--no-references',
                '--json', str(tmp_path / 'imported.json')]) == 0
    assert hac(['export', str(out), '-o', str(npz)]) == 0
    arrays = np.load(npz)
    T = len(arrays['stamps_ns'])
    assert len(read_bag(out)['/hac/pose']) == T
    assert arrays['camera_position'].shape == (T, 3) and arrays['camera_quat_xyzw'].shape == (T, 4)
    assert arrays['joints_world'].shape == (T, 1, 24, 3) and arrays['scale'].shape == (T,)
    assert np.allclose(np.linalg.norm(arrays['camera_quat_xyzw'], axis=1), 1.0)
    assert np.isfinite(arrays['joints_world']).all() and np.isfinite(arrays['scale']).all()
    assert np.array_equal(arrays['scale'][-1:], [read_bag(out)['/hac/scale'][-1][1].data])
    assert hac(['export', str(out), '-o', str(tmp_path / 'coco.npz'), '--joint-layout',
                'coco17']) == 2  # the recording says 24 joints per person
    assert 'replayed with 24' in capsys.readouterr().err
    assert not (tmp_path / 'coco.npz').exists()

    # The simulator's own recording of the same scenario, replayed the same way. It publishes a
    # growing map every 2 s where the files hold one, the last, at the first stamp: with that one
    # map the simulator's recording gives the imported estimate exactly; its own maps move the
    # estimate by a few tenths of a percent (0.27 pp here; 0.3-0.55 pp on seeds 4 and 5).
    own, own_out = tmp_path / 'own', tmp_path / 'own_out'
    write_recording(sc, own)
    assert hac(['replay', str(own), '-o', str(own_out), '--no-progress']) == 0
    assert hac(['eval', str(own_out), '--gt', str(own), '--no-references',
                '--json', str(tmp_path / 'own.json')]) == 0
    one_map = dataclasses.replace(sc, maps=[dataclasses.replace(
        sc.maps[-1], stamp_ns=int(sc.pose_stamps_ns[0]))])
    write_recording(one_map, tmp_path / 'one')
    assert hac(['replay', str(tmp_path / 'one'), '-o', str(tmp_path / 'one_out'),
                '--no-progress']) == 0
    one_final = read_bag(tmp_path / 'one_out')['/hac/scale'][-1][1].data
    imported = json.loads((tmp_path / 'imported.json').read_text())['rows']['hac']
    simulated = json.loads((tmp_path / 'own.json').read_text())['rows']['hac']
    final = arrays['scale'][-1]
    true_error = abs(final / sc.true_scale[-1] - 1) * 100
    with capsys.disabled():
        print(f'\n  scale error: imported {imported["scale_error_pct"]:.3f} % (against the Sim(3) '
              f'fit), {true_error:.3f} % (against the true scale); simulator\'s own recording '
              f'{simulated["scale_error_pct"]:.3f} %; with the last map only '
              f'{abs(one_final / sc.true_scale[-1] - 1) * 100:.3f} %')
    assert final == pytest.approx(one_final, rel=1e-6)  # float32 map, 12-digit TUM text
    assert abs(imported['scale_error_pct'] - true_error) < 0.1  # the Sim(3) fit is near the truth
    assert abs(true_error - simulated['scale_error_pct']) < 0.75


def test_a_droid_slam_npz_trajectory_imports_as_its_tum_file(files, tmp_path, capsys):
    """``--trajectory traj.npz``: DROID-SLAM-style arrays (traj (N, 7) camera-to-world tx ty tz qx
    qy qz qw, tstamp seconds) give the TUM file's recording; frame indices need --fps."""
    sc = files['sc']
    traj = np.concatenate([sc.slam_c, rotations_to_quats(sc.slam_R_wc)], axis=1)
    np.savez(tmp_path / 'droid.npz', traj=traj, tstamp=files['t_s'], disps=np.zeros((2, 3)))
    assert hac(import_args(files, tmp_path / 'tum')) == 0
    assert hac(import_args(files, tmp_path / 'droid', **{'--trajectory':
                                                         str(tmp_path / 'droid.npz')})) == 0
    tum, droid = read_bag(tmp_path / 'tum'), read_bag(tmp_path / 'droid')
    assert [t for t, _ in droid['/slam/pose']] == [t for t, _ in tum['/slam/pose']]
    for (_, a), (_, b) in zip(droid['/slam/pose'], tum['/slam/pose']):
        pa, pb = a.pose.position, b.pose.position
        assert np.allclose([pa.x, pa.y, pa.z], [pb.x, pb.y, pb.z], atol=1e-9)  # TUM: 12 digits
        qa, qb = a.pose.orientation, b.pose.orientation
        assert abs(abs(np.dot([qa.x, qa.y, qa.z, qa.w], [qb.x, qb.y, qb.z, qb.w])) - 1) < 1e-9
    capsys.readouterr()

    # frame indices at 30 Hz, the joints stamped alike (frame k at k / 30 s)
    k = np.arange(len(traj))
    np.savez(tmp_path / 'frames.npz', traj=traj, tstamp=k)
    np.savez(tmp_path / 'joints_k.npz', stamps=k / 30.0, joints=np.load(files['joints'])['joints'])
    base = {'--joints': str(tmp_path / 'joints_k.npz'), '--gt-trajectory': None,
            '--gt-joints': None}
    assert hac(import_args(files, tmp_path / 'fps', **base, **{
        '--trajectory': str(tmp_path / 'frames.npz'), '--fps': '30'})) == 0
    poses = read_bag(tmp_path / 'fps')['/slam/pose']
    assert np.array_equal([t for t, _ in poses], seconds_to_ns(k / 30.0))
    assert len(read_bag(tmp_path / 'fps')['/hmr/joints']) == len(sc.joints_stamps_ns)
    capsys.readouterr()
    # ... without --fps they are refused, naming it (taken as seconds, a replay would keep only
    # the joints frames on whole seconds: 20 of 580 in issue 36) ...
    assert hac(import_args(files, tmp_path / 'secs', **base, **{
        '--trajectory': str(tmp_path / 'frames.npz')})) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and ('tstamp holds whole numbers (0, 1, ...): frame indices? give '
                                     'the frame rate, --fps (seconds = index / fps); a trajectory '
                                     'at 1 Hz stamped in seconds is --fps 1') in err, err
    assert not (tmp_path / 'secs').exists()
    # ... and --fps 1 takes them as a 1 Hz trajectory stamped in seconds
    assert hac(import_args(files, tmp_path / 'one_hz', **base, **{
        '--trajectory': str(tmp_path / 'frames.npz'), '--fps': '1'})) == 0
    poses = read_bag(tmp_path / 'one_hz')['/slam/pose']
    assert np.array_equal([t for t, _ in poses], seconds_to_ns(k / 1.0))
    capsys.readouterr()

    # what is wrong is said in one line, naming the array
    np.savez(tmp_path / 'no_traj.npz', poses=traj)
    np.savez(tmp_path / 'short.npz', traj=traj[:, :6], tstamp=files['t_s'])
    np.savez(tmp_path / 'no_tstamp.npz', traj=traj)
    np.savez(tmp_path / 'back.npz', traj=traj, tstamp=files['t_s'][::-1])
    for name, extra, fragment in [('no_traj', {}, "no 'traj' array (it holds: poses)"),
                                  ('short', {}, 'traj must be (N, 7)'),
                                  ('no_tstamp', {}, "no 'tstamp' array: give the frame rate"),
                                  ('back', {}, 'stamps must increase'),
                                  ('droid', {'--fps': '0'}, 'fps must be a number > 0')]:
        out = tmp_path / f'bad_{name}'
        assert hac(import_args(files, out, **extra, **{
            '--trajectory': str(tmp_path / f'{name}.npz')})) == 2, name
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and fragment in err, err
        assert not out.exists()
    assert hac(import_args(files, tmp_path / 'bad_tum', **{'--fps': '30'})) == 2
    assert 'fps applies to the frame indices' in capsys.readouterr().err


def test_people_frames_layouts_and_storage(files, tmp_path, capsys):
    """Two people (NaN blocks left out, an empty frame not written), a COCO-17 layout, sqlite3,
    a text map, and a trajectory too sparse for the joints (a warning, not a failure)."""
    t_s = np.array([10.0, 10.1, 10.2, 10.3])
    joints = np.random.default_rng(0).normal(scale=0.3, size=(4, 2, 17, 3)) + [0.0, 0.0, 4.0]
    joints[1, 0] = np.nan  # person 0 absent in frame 1
    joints[2] = np.nan  # nobody in frame 2
    keyframes = write_tum(tmp_path / 'kf.tum', np.array([10.0, 10.3]), np.zeros((2, 3)),
                          np.stack([np.eye(3)] * 2))
    rec = tmp_path / 'rec'
    assert hac(['import', '-o', str(rec), '--trajectory', str(keyframes), '--map',
                str(files['dir'] / 'map.txt'), '--joints',
                str(joints_npz(tmp_path / 'j.npz', t_s, joints)), '--joint-layout', 'coco17',
                '--storage', 'sqlite3']) == 0
    err = capsys.readouterr().err
    assert 'too sparse' in err and '2 of 4 joints stamps' in err
    assert 'coco17' in (rec / 'params.yaml').read_text()
    assert list(rec.glob('*.db3'))
    bag = read_bag(rec)
    assert '/camera/camera_info' not in bag and '/gt/scale' not in bag
    msgs = bag['/hmr/joints']
    assert [t for t, _ in msgs] == [10_000_000_000, 10_100_000_000, 10_300_000_000]
    assert [len(m.poses) for _, m in msgs] == [34, 17, 34]
    assert np.allclose(pose_array_to_joints(msgs[1][1], 17)[0], joints[1, 1])
    assert np.allclose(cloud_to_xyz(bag['/slam/cloud'][0][1]), files['points'])
    meta = (rec / 'metadata.yaml').read_text()
    assert 'hac_ros.joints_per_person' in meta and 'coco17' in meta


def test_map_formats_agree(files, tmp_path):
    points = files['points']
    assert np.array_equal(read_map(files['map']), points)
    assert np.array_equal(read_map(files['dir'] / 'map.npy'), points)
    assert np.allclose(read_map(files['dir'] / 'map.txt'), points)
    assert np.array_equal(read_map(write_ply(tmp_path / 'a.ply', points, binary=False)), points)
    big = tmp_path / 'be.ply'
    big.write_bytes(b'ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty float x\n'
                    b'property float y\nproperty float z\nend_header\n'
                    + np.arange(6, dtype='>f4').tobytes())
    assert np.array_equal(read_map(big), np.arange(6.0).reshape(2, 3))


def test_real_tum_keyframes_parse_and_fit_their_ground_truth(shared_data, tmp_path, capsys):
    """ORB-SLAM monocular keyframes of TUM fr2_desk against motion capture (data README: Sim(3)
    scale about 2.23). The map and the joints are placeholders (the data has none)."""
    kf = shared_data / 'tum_rgbd' / 'fr2_desk_ORB_kf_mono.txt'
    traj = read_trajectory(kf)
    assert len(traj) == 157 and np.all(np.diff(traj.stamps_ns) > 0)
    assert np.allclose(np.linalg.norm(traj.quats_xyzw, axis=1), 1.0)
    first = float(kf.read_text().split()[0])
    assert traj.stamps_ns[0] == round(first * 1e9)
    np.save(tmp_path / 'map.npy', np.random.default_rng(0).normal(size=(100, 3)))
    t_s = np.arange(first, first + 5.0, 1 / 30)  # HMR at 30 Hz between the keyframes
    body = np.random.default_rng(0).normal(scale=0.3, size=(1, 24, 3)) + [0.0, 0.0, 3.0]
    joints_npz(tmp_path / 'j.npz', t_s, np.repeat(body[None], len(t_s), axis=0))
    rec = tmp_path / 'rec'
    assert hac(['import', '-o', str(rec), '--trajectory', str(kf), '--map',
                str(tmp_path / 'map.npy'), '--joints', str(tmp_path / 'j.npz'), '--gt-trajectory',
                str(shared_data / 'tum_rgbd' / 'fr2_desk_groundtruth.txt')]) == 0
    captured = capsys.readouterr()
    assert 'too sparse' in captured.err and 'keyframes only' in captured.err
    assert 'repeats the stamp' in captured.err  # one duplicated mocap stamp: the first pose kept
    (_, scale), = read_bag(rec)['/gt/scale']
    assert scale.data == pytest.approx(2.23, abs=0.02)


# ============================================================================ bad files
def _garbage(tmp: Path, files: dict) -> dict[str, tuple[dict, str]]:
    """case -> (flags to override, a fragment the one-line error must hold)."""
    good_t = files['t_s'][:5]
    ok_joints = np.load(files['joints'])['joints'][:5]
    tum_lines = files['trajectory'].read_text().splitlines()
    (tmp / 'short.ply').write_bytes(files['map'].read_bytes()[:400])
    (tmp / 'short.npz').write_bytes(files['joints'].read_bytes()[:3000])
    (tmp / 'garbage.ply').write_bytes(b'plx\x00\x01 this is not a header\n' * 3)
    write_ply(tmp / 'short_ascii.ply', files['points'][:10], binary=False, count=50)
    (tmp / 'cols.tum').write_text('\n'.join(tum_lines[:3] + ['1.0 2.0 3.0']) + '\n')
    (tmp / 'nan.tum').write_text('\n'.join(tum_lines[:4] + [tum_lines[4].rsplit(' ', 7)[0]
                                                            + ' nan 0 0 0 0 0 1']) + '\n')
    (tmp / 'back.tum').write_text('\n'.join(tum_lines[:3] + [tum_lines[1]]) + '\n')
    np.savez(tmp / 'nokeys.npz', times=good_t, poses=ok_joints)
    np.savez(tmp / 'frames.npz', stamps=good_t, joints=ok_joints[:4])
    np.savez(tmp / 'back.npz', stamps=good_t[[0, 2, 1, 3, 4]], joints=ok_joints)
    np.savez(tmp / 'negative.npz', stamps=good_t - good_t[0] - 100.0, joints=ok_joints)
    poses = [line for line in tum_lines if not line.startswith('#')]
    (tmp / 'future.tum').write_text('\n'.join(f'{1e11 + k} {line.split(" ", 1)[1]}'
                                             for k, line in enumerate(poses[:5])) + '\n')
    # a face element before the vertices whose list announces -100 indices (signed char count)
    (tmp / 'neglist.ply').write_bytes(
        b'ply\nformat binary_little_endian 1.0\nelement face 1\nproperty list char int i\n'
        b'element vertex 4\nproperty float x\nproperty float y\nproperty float z\nend_header\n'
        + np.int8(-100).tobytes() + np.zeros(12, '<f4').tobytes())
    return {
        'missing trajectory': ({'--trajectory': tmp / 'none.tum'}, 'none.tum does not exist'),
        'missing map': ({'--map': tmp / 'none.ply'}, 'none.ply does not exist'),
        'missing joints': ({'--joints': tmp / 'none.npz'}, 'none.npz does not exist'),
        'truncated PLY': ({'--map': tmp / 'short.ply'}, 'truncated PLY'),
        'truncated ASCII PLY': ({'--map': tmp / 'short_ascii.ply'}, 'announces 50 vertices'),
        'garbage PLY header': ({'--map': tmp / 'garbage.ply'}, 'not a PLY file'),
        'truncated npz': ({'--joints': tmp / 'short.npz'}, 'not a readable .npz'),
        'npz without the arrays': ({'--joints': tmp / 'nokeys.npz'}, "no 'stamps' or 'joints'"),
        'npz stamps vs joints': ({'--joints': tmp / 'frames.npz'},
                                 '5 stamps (seconds) but joints has 4 frames'),
        'K vs joint layout': ({'--joint-layout': 'coco17'}, 'with K = 17 (coco17), got shape'),
        'joints stamps go back': ({'--joints': tmp / 'back.npz'}, 'stamps must increase'),
        'trajectory stamps go back': ({'--trajectory': tmp / 'back.tum'}, 'stamps must increase'),
        'joints stamps before 1970': ({'--joints': tmp / 'negative.npz'}, 'not a ROS time'),
        'trajectory stamps past 2^31 s': ({'--trajectory': tmp / 'future.tum'}, 'not a ROS time'),
        'PLY list of negative length': ({'--map': tmp / 'neglist.ply'}, 'a list of -100 items'),
        'TUM wrong columns': ({'--trajectory': tmp / 'cols.tum'}, 'expected 8 values'),
        'NaN in trajectory': ({'--trajectory': tmp / 'nan.tum'}, 'not finite'),
        'GT joints shapes': ({'--gt-joints': tmp / 'frames.npz'},
                             '5 stamps (seconds) but joints has 4 frames'),
        'GT shares no stamp': ({'--gt-trajectory': files['dir'] / 'far.tum'}, 'Sim(3) fit needs 3'),
        'bad camera': ({'--camera': '500,500,320'}, 'fx,fy,cx,cy,width,height'),
    }


CASES = ('missing trajectory', 'missing map', 'missing joints', 'truncated PLY',
         'truncated ASCII PLY', 'garbage PLY header', 'truncated npz', 'npz without the arrays',
         'npz stamps vs joints', 'K vs joint layout', 'joints stamps go back',
         'trajectory stamps go back', 'joints stamps before 1970', 'trajectory stamps past 2^31 s',
         'PLY list of negative length', 'TUM wrong columns', 'NaN in trajectory', 'GT joints shapes',
         'GT shares no stamp', 'bad camera')


@pytest.mark.parametrize('case', CASES)
def test_a_bad_file_exits_2_with_one_line_and_writes_nothing(case, files, tmp_path, capsys):
    sc = files['sc']
    write_tum(files['dir'] / 'far.tum', files['t_s'] + 1000.0, sc.gt_c, sc.gt_R_wc)
    override, fragment = _garbage(tmp_path, files)[case]
    out = tmp_path / 'new' / 'rec'
    assert hac(import_args(files, out, **{k: str(v) for k, v in override.items()})) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('hac import: error: '), err
    assert fragment in err, err
    assert not out.exists() and not (tmp_path / 'new').exists()


def test_export_refuses_what_it_cannot_read_and_never_overwrites(files, tmp_path, capsys):
    npz = tmp_path / 'x.npz'
    assert hac(['export', str(tmp_path / 'nothing'), '-o', str(npz)]) == 2
    assert 'does not exist' in capsys.readouterr().err and not npz.exists()
    rec = tmp_path / 'rec'  # an input recording: no /hac/pose
    assert hac(import_args(files, rec)) == 0
    capsys.readouterr()
    assert hac(['export', str(rec), '-o', str(npz)]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'no /hac/pose' in err and not npz.exists()
    npz.write_text('mine')
    assert hac(['export', str(rec), '-o', str(npz)]) == 2
    assert 'already exists' in capsys.readouterr().err and npz.read_text() == 'mine'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['rec', 'x.npz']  # no partial files
