"""The simulator: deterministic recordings whose inputs agree with their own ground truth."""
from __future__ import annotations

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from hac_ros.cli import main as hac
from hac_ros.simulate import SCENARIOS, make_scenario, write_recording
from hac_ros.simulate.hmr import DEPTH_NOISE_M, JOINT_NOISE_M
from hac_ros.simulate.scenarios import SOLE_HEIGHT_M
from msg_adapters import pose_array_to_joints, stamp_to_ns

SHORT = 4.0  # seconds: every scenario runs in the suite at this length


@pytest.fixture(scope='module')
def scenarios():
    return {name: make_scenario(name, seed=1, duration=SHORT if name != 'reset' else 8.0,
                                hmr_bias=0.0) for name in SCENARIOS}


def test_same_seed_gives_byte_identical_recordings(tmp_path):
    for storage in ('mcap', 'sqlite3'):
        files = []
        for run in ('a', 'b'):
            (tmp_path / run).mkdir(exist_ok=True)
            out = tmp_path / run / storage
            assert hac(['simulate', 'walk', '-o', str(out), '--duration', '2', '--seed', '7',
                        '--storage', storage]) == 0
            files.append({p.name: p.read_bytes() for p in sorted(out.iterdir())})
        assert files[0] == files[1]
    a, b = make_scenario('walk', seed=7, duration=2.0), make_scenario('walk', seed=8, duration=2.0)
    assert a.true_scale[0] != b.true_scale[0]  # the seed matters


def test_an_existing_output_is_refused_and_left_untouched(tmp_path, capsys):
    out = tmp_path / 'rec'
    out.mkdir()
    (out / 'keep.txt').write_text('mine')
    assert hac(['simulate', 'walk', '-o', str(out), '--duration', '1']) == 2
    assert 'refusing to overwrite' in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ['keep.txt'] and (out / 'keep.txt').read_text() == 'mine'


def test_hmr_joints_are_the_truth_seen_from_the_true_camera(scenarios):
    """Clean recordings (hmr_bias 0): the body's shape is the truth within the joint noise; the
    person as a whole is off along its viewing ray by about DEPTH_NOISE_M per frame, no bias."""
    for name, sc in scenarios.items():
        index = {int(s): i for i, s in enumerate(sc.pose_stamps_ns)}
        outliers = set(sc.outlier_frames.tolist())
        shape_errors, depth_errors = [], []
        for k, stamp in enumerate(sc.joints_stamps_ns):
            i = index[int(stamp)]
            if i in outliers:
                continue
            truth_cam = (sc.gt_joints_world[k] - sc.gt_c[i]) @ sc.gt_R_wc[i]
            pred = sc.joints_cam[k]
            shape_errors.append(((pred - pred[:, :1]) - (truth_cam - truth_cam[:, :1])).ravel())
            depth_errors.append(np.linalg.norm(pred[:, 0], axis=1)
                                - np.linalg.norm(truth_cam[:, 0], axis=1))
        shape_errors, depth_errors = np.concatenate(shape_errors), np.concatenate(depth_errors)
        assert np.std(shape_errors) < 1.5 * np.sqrt(2) * JOINT_NOISE_M, name
        assert np.max(np.abs(shape_errors)) < 8 * np.sqrt(2) * JOINT_NOISE_M, name
        assert 0.6 * DEPTH_NOISE_M < np.std(depth_errors) < 1.4 * DEPTH_NOISE_M, name
        assert abs(np.median(depth_errors)) < 0.3 * DEPTH_NOISE_M, name


def test_hmr_depth_bias_moves_the_person_along_the_ray():
    sc = make_scenario('walk', seed=2, duration=SHORT, hmr_bias=0.1)
    index = {int(s): i for i, s in enumerate(sc.pose_stamps_ns)}
    ratios = []
    for k, stamp in enumerate(sc.joints_stamps_ns):
        i = index[int(stamp)]
        truth_root = (sc.gt_joints_world[k][0, 0] - sc.gt_c[i]) @ sc.gt_R_wc[i]
        ratios.append(np.linalg.norm(sc.joints_cam[k][0, 0]) / np.linalg.norm(truth_root))
    assert np.median(ratios) == pytest.approx(1.1, abs=0.02)  # the mean bias, and its wander
    assert sc.hmr_bias == 0.1 and np.std(sc.hmr_bias_frames) > 0.001


def test_slam_poses_are_the_truth_through_the_known_similarity(scenarios):
    for name, sc in scenarios.items():
        for i in range(len(sc.pose_stamps_ns)):
            s0 = sc.segment_start(i)
            R0, c0 = sc.gt_R_wc[s0], sc.gt_c[s0]
            if name == 'drift':
                continue  # integrated with a changing scale: checked below
            back = c0 + R0 @ (sc.slam_c[i] * sc.true_scale[i])
            assert np.linalg.norm(back - sc.gt_c[i]) < 0.05, (name, i)
            np.testing.assert_allclose(R0 @ sc.slam_R_wc[i], sc.gt_R_wc[i], atol=0.01)
        assert sc.slam_frame_ids[0] == 'map'
    reset = scenarios['reset']
    assert len(set(reset.slam_frame_ids)) == 2 and len(set(reset.true_scale)) == 2
    drift = scenarios['drift']
    assert drift.true_scale[-1] / drift.true_scale[0] == pytest.approx(1.40, abs=0.01)
    steps_slam = np.linalg.norm(np.diff(drift.slam_c, axis=0), axis=1) * drift.true_scale[1:]
    steps_true = np.linalg.norm(np.diff(drift.gt_c, axis=0), axis=1)
    assert np.median(np.abs(steps_slam - steps_true)) < 0.005


def distance_to_world(world, points):
    """Metres from each point (N, 3) to the nearest surface (floor or box)."""
    best = np.abs(points[:, 2])
    for b in world.boxes:
        outside = np.maximum(np.maximum(b.lo - points, 0.0), points - b.hi)
        d_out = np.linalg.norm(outside, axis=1)
        d_in = np.min(np.minimum(points - b.lo, b.hi - points), axis=1)  # depth inside the box
        best = np.minimum(best, np.where(d_out > 0, d_out, d_in))
    return best


def test_map_points_lie_on_the_world_and_never_on_people(scenarios):
    for name, sc in scenarios.items():
        assert sc.maps, name
        for m in sc.maps:
            i = int(np.searchsorted(sc.pose_stamps_ns, m.stamp_ns))
            s0 = sc.segment_start(i)
            world = sc.gt_c[s0] + (m.points_slam * sc.true_scale[i]) @ sc.gt_R_wc[s0].T
            if name != 'drift':
                # noise: 4 mm + 0.4 % of the depth at creation (up to 10 m), plus the pose drift
                dist = distance_to_world(sc.world, world)
                assert np.median(dist) < 0.03 and np.percentile(dist, 99) < 0.15, name
            k = int(np.searchsorted(sc.joints_stamps_ns, m.stamp_ns))
            if k < len(sc.gt_joints_world) and name != 'drift':
                body = sc.gt_joints_world[k].reshape(-1, 3)
                body = body[body[:, 2] > 0.3]  # the trunk and head: no landmark can be there
                d = np.linalg.norm(world[:, None] - body[None], axis=2).min()
                assert d > 0.1, name
        # the map grows as the camera explores
        sizes = [len(m.points_slam) for m in sc.maps if m.frame_id == sc.maps[0].frame_id]
        assert sizes == sorted(sizes), name


def test_walk_contact_stands_its_sole_height_above_the_floor_and_lifts_like_real_gait():
    """The lowest joint stands at the person's contact height above the floor (drawn per person in
    SOLE_HEIGHT_M: a foot joint is not on the surface) only while the foot is flat: it is lifted
    at heel strike and towards toe-off (motions.FootRoll) about as much as in the real CMU walks
    (131_02, 131_03: 0.5-0.9 cm above their stance height at the quartile, 0.9-1.2 cm at the
    median, 2.8 cm at the 95th percentile)."""
    sc = make_scenario('walk', seed=3, duration=20.0)
    height = sc.contact_heights[0]
    assert SOLE_HEIGHT_M[0] <= height <= SOLE_HEIGHT_M[1]
    lift = np.array([j[:, :, 2].min() for j in sc.gt_joints_world]) - height
    assert lift.min() > -1e-9 and np.mean(lift < 1e-3) > 0.05  # planted now and then, never below
    quartile, median, top = np.percentile(lift, [25, 50, 95])
    assert 0.0 <= quartile <= 0.01 and 0.003 <= median <= 0.015 and 0.02 <= top <= 0.045
    other = make_scenario('walk', seed=4, duration=SHORT)
    assert other.contact_heights[0] != height  # drawn per person
    feet = np.array([j[0, [10, 11], 2] for j in sc.gt_joints_world])
    assert feet.max() > 0.05  # the swing foot leaves the floor


@pytest.mark.parametrize('name', sorted(SCENARIOS))
def test_each_scenario_writes_a_readable_recording(tmp_path, name):
    sc = make_scenario(name, seed=0, duration=2.0 if name != 'reset' else 4.0)
    out = write_recording(sc, tmp_path / name, pose_type='Odometry' if name == 'static' else 'PoseStamped')
    typestore = get_typestore(Stores.ROS2_JAZZY)
    counts: dict[str, int] = {}
    last = {}
    with AnyReader([out], default_typestore=typestore) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for conn, logtime, raw in reader.messages():
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
            msg = reader.deserialize(raw, conn.msgtype)
            if hasattr(msg, 'header'):
                assert stamp_to_ns(msg.header.stamp) == logtime
            assert logtime >= last.get(conn.topic, 0)
            last[conn.topic] = logtime
            if conn.topic == '/hmr/joints':
                assert pose_array_to_joints(msg).shape[1:] == (24, 3)
    assert types['/slam/pose'] == ('nav_msgs/msg/Odometry' if name == 'static'
                                   else 'geometry_msgs/msg/PoseStamped')
    assert counts['/slam/pose'] == len(sc.pose_stamps_ns)
    assert counts['/hmr/joints'] == counts['/gt/human_joints'] == len(sc.joints_stamps_ns)
    assert counts['/slam/cloud'] == len(sc.maps) and counts['/gt/scale'] >= 1
    assert counts['/camera/camera_info'] == counts['/gt/camera_pose'] == len(sc.pose_stamps_ns)


def test_real_motion_capture_drives_the_person(shared_data, tmp_path):
    motion = shared_data / 'cmu_mocap' / 'scaled_131_01.npz'
    assert hac(['simulate', 'walk', '-o', str(tmp_path / 'cmu'), '--duration', '3', '--motion',
                str(motion)]) == 0
    sc = make_scenario('walk', seed=0, duration=3.0, motion=str(motion))
    lowest = np.array([j[:, :, 2].min() for j in sc.gt_joints_world])
    assert np.all(lowest > -0.01) and np.all(lowest < 0.1)  # the CMU floor contacts (0–6 cm)
    assert len(sc.joints_stamps_ns) > 0
