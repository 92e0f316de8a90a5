"""The fault suite: what hac_ros does when its inputs go wrong (docs/node.md, "Faults").

Every fault is injected into a real simulated recording (``hac simulate walk --seed 1
--hmr-bias 0``, true scale in /gt/scale; :mod:`injected`) and replayed through the node's core as
``hac replay --mode online`` does; where the node differs from the replay (time, overload,
status, signals) it is also played to a live ``hac_node`` over DDS. For every fault: hac_ros keeps
running, counts it under its own reason, publishes no non-finite or absurd value, and never says
OK while it is wrong or blind.

This module holds time, anchoring, a frozen SLAM, plausibility and reports, and the recording and
helpers the other fault modules import from it: signals to the commands are in
test_faults_signals.py, full and read-only disks in test_faults_files.py, the live node in
test_faults_node.py.
"""
from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from faultkit import Run, run_online, written_diagnostics
from injected import (
    chained,
    joints_scaled,
    maps_big_endian,
    played,
    pose_moved,
    pose_stamped_ahead,
    poses_moved,
    rewrite,
    simulate,
    slam_frozen,
    truth_scale,
)
from scenes import walking_scene

from hac_ros.batch.runner import batch
from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import (
    CloudOut,
    NoticeOut,
    OdometryOut,
    Output,
    PoseOut,
    ResetOut,
    ScaleOut,
)
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.rules.health import OK, WARN
from hac_ros.core.rules.params import HacParams
from hac_ros.evaluation.evaluate import evaluate
from hac_ros.recording.reader import Recording
from hac_ros.replay.replayer import replay

rclpy = pytest.importorskip('rclpy')

SANE_M = 1e4  # no published value may be larger (metres; the bound)
REPO = Path(__file__).resolve().parents[1]
SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP]


# ============================================================================ recordings
@pytest.fixture(scope='module')
def walk(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The issue's recording: 30 s walk, seed 1, no HMR bias (true scale 1.7838)."""
    return simulate(tmp_path_factory.mktemp('walk') / 'walk')


@pytest.fixture(scope='module')
def clean(walk: Path) -> Run:
    return run_online(walk)


def faulty(walk: Path, tmp_path: Path, *edits: Any) -> Path:
    return rewrite(walk, tmp_path / 'faulty', chained(*edits))


def ate_s(output: Path, truth: Path) -> float:
    result = evaluate(output, truth)
    return float(result.rows['hac']['ate_s_m'])


def _import_args(walk: Path, tmp_path: Path, out: Path, factor: float = 1.0,
                 shift_s: float = 0.0) -> list[str]:
    """``hac import`` arguments for the walk's SLAM and HMR data written as files (the joints
    times ``factor``, their stamps ``shift_s`` later)."""
    from scipy.spatial.transform import Rotation

    from hac_ros.files.tum import write_tum
    from msg_adapters import cloud_to_xyz, pose_msg_to_rt, stamp_to_ns

    with Recording(walk) as recording:
        poses = [(stamp_to_ns(m.header.stamp), *pose_msg_to_rt(m))
                 for _, m in recording.read('/slam/pose')]
        joints = [(stamp_to_ns(m.header.stamp),
                   np.array([[p.position.x, p.position.y, p.position.z] for p in m.poses]))
                  for _, m in recording.read('/hmr/joints')]
        clouds = recording.read('/slam/cloud')
    stamps = np.array([p[0] for p in poses], dtype=np.int64)
    write_tum(tmp_path / 'traj.tum', stamps, np.array([p[2] for p in poses]),
              Rotation.from_matrix(np.array([p[1] for p in poses])).as_quat())
    np.save(tmp_path / 'map.npy', cloud_to_xyz(clouds[-1][1]))
    np.savez(tmp_path / 'joints.npz', stamps=np.array([j[0] for j in joints]) / NS + shift_s,
             joints=factor * np.stack([j[1].reshape(-1, 24, 3) for j in joints]))
    return ['import', '-o', str(out), '--trajectory', str(tmp_path / 'traj.tum'), '--map',
            str(tmp_path / 'map.npy'), '--joints', str(tmp_path / 'joints.npz')]


# ============================================================================ time
def test_a_recording_played_twice_calibrates_its_second_loop(walk, tmp_path):
    """``ros2 bag play --loop``: header time jumps back 30 s. A new stream starts (counted as
    time_jump_back, state and anchor dropped, the counters go on) and its frames are calibrated
    within 3 % of the truth; /diagnostics goes on in the new stream's time."""
    truth = truth_scale(walk)
    looped = run_online(faulty(walk, tmp_path, played(2)))
    cal = looped.calibrator
    assert cal.events['time_jump_back'] == 1
    assert not cal.rejected.get('pose_out_of_order') and not cal.rejected.get('late_frame')
    assert cal.frames == 2 * 901  # counted on across the jump
    restart = [o for o in looped.of(ResetOut) if o.cause == 'time_jump_back']
    assert len(restart) == 1
    second = [o.scale for o in looped.outputs[looped.outputs.index(restart[0]):]
              if isinstance(o, ScaleOut)]
    assert len(second) > 500  # once its own uncertainty is under 1 %: some 10 s into it
    assert abs(second[-1] / truth - 1) < 0.03
    assert np.all(np.abs(np.array(second[len(second) // 10:]) / truth - 1) < 0.03)
    assert len(looped.statuses) == 2 * 31  # one a second of stamp time, in both loops
    # the odometry goes on across the jump (a zero step there): its first message in the new
    # stream, once that stream has converged, has moved by the camera's true travel since the
    # new stream's first pose (the steps of the gap summed with the new stream's scale)
    odometry = looped.of(OdometryOut)
    stamps = [o.stamp_ns for o in odometry]
    back = next(k for k in range(1, len(stamps)) if stamps[k] < stamps[k - 1])
    step = np.linalg.norm(odometry[back].position_metric - odometry[back - 1].position_metric)
    with Recording(walk) as recording:
        truth_c = {m.header.stamp.sec * NS + m.header.stamp.nanosec:
                   np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z])
                   for _, m in recording.read('/gt/camera_pose')}
    travel = np.linalg.norm(truth_c[stamps[back]] - truth_c[restart[0].stamp_ns])
    assert abs(step - travel) < 0.03 * travel  # the gap's steps at the new stream's scale
    assert looped.largest_value_m() < SANE_M


def test_a_small_step_back_is_a_late_frame_not_a_new_stream():
    """A pose and a joints frame half a second older than the newest: late, counted, refused
    (time_jump_back_s is 1 s); the stream goes on."""
    scene = walking_scene(frames=60)
    cal = Calibrator()
    floor = scene.floor_points_slam()
    cal.add_map(int(scene.stamps_ns[0]), floor, 'map')
    for t in range(40):
        cal.add_pose(int(scene.stamps_ns[t]), scene.R_wc_slam[t], scene.c_slam[t], 'map')
        cal.add_joints(int(scene.stamps_ns[t]), scene.joints_cam[t][None], 'camera')
    late = int(scene.stamps_ns[39]) - NS // 2
    cal.add_pose(late, scene.R_wc_slam[34], scene.c_slam[34], 'map')
    cal.add_joints(late, scene.joints_cam[34][None], 'camera')
    assert cal.rejected['pose_out_of_order'] == 1 and cal.rejected['late_frame'] == 1
    assert not cal.events
    frames = cal.frames
    for t in range(40, 60):
        cal.add_pose(int(scene.stamps_ns[t]), scene.R_wc_slam[t], scene.c_slam[t], 'map')
        cal.add_joints(int(scene.stamps_ns[t]), scene.joints_cam[t][None], 'camera')
    assert cal.frames == frames + 20 and cal.resets == 0


def test_one_pose_stamped_an_hour_ahead_is_refused_and_the_rest_goes_on(walk, clean, tmp_path):
    """Pose 450 stamped an hour ahead: refused as pose_stamp_outlier (the next pose is back in
    the stream's time); every later pose and frame is used, /diagnostics goes on and says WARN."""
    path = faulty(walk, tmp_path, pose_stamped_ahead(450, 3600.0))
    ahead = run_online(path)
    cal = ahead.calibrator
    assert cal.rejected['pose_stamp_outlier'] == 1 and not cal.rejected.get('pose_out_of_order')
    assert cal.frames == clean.calibrator.frames and cal.resets == 0
    assert len(ahead.statuses) == len(clean.statuses)
    assert all(s.stamp_ns < 3600 * NS + ahead.statuses[0].stamp_ns for s in ahead.statuses)
    assert abs(ahead.scales[-1] / clean.scales[-1] - 1) < 1e-3
    summary = replay(path, tmp_path / 'out', mode='online')
    assert summary.status.rejected['pose_stamp_outlier'] == 1
    diagnostics = written_diagnostics(tmp_path / 'out')
    flagged = [d for d in diagnostics if 'pose_stamp_outlier' in d[3]['reasons']]
    assert len(flagged) == 1 and flagged[0][1] == WARN


def test_time_that_jumps_ahead_and_goes_on_starts_a_new_segment():
    """Every pose from frame 30 on stamped two hours later (a clock set forward): after
    reset_confirm_poses poses it is a new segment (time_jump_ahead), which converges again."""
    scene = walking_scene(frames=120)
    cal = Calibrator(HacParams(min_samples=5))
    cal.add_map(int(scene.stamps_ns[0]), scene.floor_points_slam(), 'map')
    outputs: list[Output] = []
    for t in range(120):
        stamp = int(scene.stamps_ns[t]) + (7200 * NS if t >= 30 else 0)
        outputs += cal.add_pose(stamp, scene.R_wc_slam[t], scene.c_slam[t], 'map')
        outputs += cal.add_joints(stamp, scene.joints_cam[t][None], 'camera')
    resets = [o.cause for o in outputs if isinstance(o, ResetOut)]
    assert resets == ['time_jump_ahead'] and cal.events['time_jump_ahead'] == 1
    assert not cal.rejected.get('pose_stamp_outlier')
    assert cal.converged and abs(cal.scale / scene.true_scale - 1) < 0.05
    assert cal.map is not None  # the same SLAM map goes on


# ============================================================================ anchoring
@pytest.mark.parametrize('glitched', [{0}, {0, 1}], ids=['first', 'first_two'])
def test_a_glitched_first_pose_is_refused_and_anchors_nothing(walk, tmp_path, glitched):
    """The first SLAM pose (or first two) 1e6 units off: refused as pose_outlier like a glitch
    mid-run; nothing is anchored on it, so ATE-S stays within 2x the clean run's."""
    path = faulty(walk, tmp_path, poses_moved(glitched, 1e6))
    run = run_online(path)
    assert run.calibrator.rejected['pose_outlier'] == len(glitched)
    assert run.largest_value_m() < 100.0  # the walk stays within a few metres of the origin
    clean_out, out = tmp_path / 'clean_out', tmp_path / 'out'
    replay(walk, clean_out)
    replay(path, out)
    assert ate_s(out, path) <= 2.0 * ate_s(clean_out, walk)


def test_a_glitch_mid_run_is_still_an_outlier(walk, clean, tmp_path):
    run = run_online(faulty(walk, tmp_path, pose_moved(450, 1e6)))
    assert run.calibrator.rejected['pose_outlier'] == 1 and run.calibrator.resets == 0
    assert run.largest_value_m() < 100.0


# ============================================================================ a frozen SLAM
def test_a_frozen_slam_warns_and_its_resume_is_anchored_where_it_was(walk, tmp_path):
    """The SLAM repeats its pose bit for bit for 10 s while the person walks on: slam_frozen
    (WARN, frames not sampled); when it resumes in the same map nothing is reset, so /hac/pose
    after the resume is as good as the clean run's."""
    path = faulty(walk, tmp_path, slam_frozen(10.0, 10.0))
    out = tmp_path / 'out'
    summary = replay(path, out, mode='online')
    assert summary.status.resets == 0
    assert summary.status.rejected['slam_frozen'] > 200
    diagnostics = written_diagnostics(out)
    start = diagnostics[0][0]
    frozen = [d for d in diagnostics if 11.5 * NS < d[0] - start < 19.5 * NS]
    assert frozen and all(d[1] == WARN and 'slam_frozen' in d[3]['reasons'] for d in frozen)
    after = [d for d in diagnostics if d[0] - start > 22 * NS]
    assert after and all('slam_frozen' not in d[3]['reasons'] for d in after)
    # /hac/pose after the resume: on the clean run's (same segment, same anchor)
    clean_out = tmp_path / 'clean'
    replay(walk, clean_out, mode='online')
    resumed = _positions(out, after_s=21.0)
    reference = _positions(clean_out, after_s=21.0)
    common = sorted(set(resumed) & set(reference))
    assert len(common) > 200
    gap = np.array([np.linalg.norm(resumed[s] - reference[s]) for s in common])
    assert np.median(gap) < 0.1  # metres; the anchor on the frozen pose was metres off


def test_a_still_camera_repeating_its_pose_with_still_people_is_ok():
    """A SLAM that reports a still camera bit for bit, and a person standing still: not frozen."""
    scene = walking_scene(frames=80)
    cal = Calibrator(HacParams(min_samples=5))
    cal.add_map(int(scene.stamps_ns[0]), scene.floor_points_slam(), 'map')
    for t in range(80):
        stamp = int(scene.stamps_ns[t])
        cal.add_pose(stamp, scene.R_wc_slam[0], scene.c_slam[0], 'map')
        cal.add_joints(stamp, scene.joints_cam[0][None], 'camera')
    assert cal.track.frozen(int(scene.stamps_ns[-1]))  # repeated bit for bit ...
    assert 'slam_frozen' not in cal.conditions() and not cal.rejected.get('slam_frozen')
    assert cal.converged


def _positions(path: Path, after_s: float) -> dict[int, np.ndarray]:
    from msg_adapters import pose_msg_to_rt, stamp_to_ns

    with Recording(path) as recording:
        start = recording.start_ns
        out = {}
        for _, msg in recording.read('/hac/pose'):
            stamp = stamp_to_ns(msg.header.stamp)
            if stamp - start > after_s * NS:
                out[stamp] = pose_msg_to_rt(msg)[1]
    return out


def test_a_clean_run_says_ok_once_converged(walk, tmp_path):
    """The reference: no fault, every status OK once the estimate has converged, which it does
    once its own uncertainty is under converged_max_rel_sigma (1 %: some 10 s of this walk)."""
    out = tmp_path / 'out'
    replay(walk, out, mode='online')
    diagnostics = written_diagnostics(out)
    first = next(k for k, d in enumerate(diagnostics) if d[3]['converged'] == 'true')
    assert (diagnostics[first][0] - diagnostics[0][0]) / NS < 15.0
    assert all(d[1] == OK and d[3]['reasons'] == '' for d in diagnostics[first:])


# ============================================================================ plausibility
def test_a_map_whose_bytes_decode_to_garbage_is_refused(walk, tmp_path):
    """``is_bigendian`` set on little-endian floats: every map refused as cloud_implausible
    (judged on the points' depths from the camera, whatever the unit), so no scale and no value
    beyond 1e4 m is published, and /diagnostics warns with the reason."""
    path = faulty(walk, tmp_path, maps_big_endian())
    run = run_online(path)
    assert run.calibrator.rejected['cloud_implausible'] == 15
    truth = truth_scale(walk)
    assert all(abs(s / truth - 1) <= 0.2 for s in run.scales)
    assert run.largest_value_m() < SANE_M
    out = tmp_path / 'out'
    replay(path, out, mode='online')
    diagnostics = written_diagnostics(out)
    assert all(d[1] == WARN for d in diagnostics)
    assert any('cloud_implausible' in d[3]['reasons'] for d in diagnostics)


def test_one_garbage_map_among_good_ones_is_refused_and_the_others_serve(walk, clean, tmp_path):
    run = run_online(faulty(walk, tmp_path, maps_big_endian({3})))
    assert run.calibrator.rejected['cloud_implausible'] == 1
    assert abs(run.scales[-1] / clean.scales[-1] - 1) < 0.01
    assert run.largest_value_m() < 100.0


@pytest.mark.parametrize('scenario', ['walk', 'static', 'ego', 'stairs', 'crowd', 'reset'])
def test_real_maps_and_bodies_are_plausible(tmp_path, scenario):
    """Every map of the simulator's scenes (a still camera's and the first map included) and
    every body is accepted: the rules do not refuse what a SLAM and an HMR model produce."""
    run = run_online(simulate(tmp_path / scenario, scenario, seed=2, duration=8.0))
    assert not run.calibrator.rejected.get('cloud_implausible')
    assert not run.calibrator.rejected.get('joints_not_metres')
    assert not run.calibrator.rejected.get('output_implausible')


@pytest.mark.parametrize('factor, unit', [(0.01, '100x too small'), (0.1, '10x too small'),
                                          (1000.0, 'millimetres')])
def test_joints_in_another_unit_are_refused_naming_the_unit(walk, tmp_path, factor, unit):
    """Joints 100x or 10x too small (a unit converted twice) are refused as joints_not_metres
    as too-large ones are, the notice naming the likely unit: no scale 20 % off is published,
    and the convention check does not blame the joint order."""
    path = faulty(walk, tmp_path, joints_scaled(factor))
    run = run_online(path)
    assert run.calibrator.rejected['joints_not_metres'] == 901
    notices = [o.text for o in run.of(NoticeOut) if o.cause == 'joints_not_metres']
    assert len(notices) == 1 and unit in notices[0]
    truth = truth_scale(walk)
    assert all(abs(s / truth - 1) <= 0.2 for s in run.scales)
    assert run.largest_value_m() < SANE_M
    assert not run.calibrator.check.suspects
    assert all(not s.converged for s in run.statuses)


def test_a_map_with_a_few_points_no_slam_produces_loses_them():
    """A map with 5 % of its points a billion SLAM units away: accepted without them (they would
    poison its extent, its floor and /hac/cloud); the estimate is the clean map's."""
    scene = walking_scene(frames=60)
    floor = scene.floor_points_slam()
    far = np.vstack([floor, np.full((len(floor) // 20, 3), 1e9)])
    results = []
    for points in (floor, far):
        cal = Calibrator(HacParams(min_samples=5, cloud_min_period_s=0.0))
        outputs = cal.add_map(int(scene.stamps_ns[0]), points, 'map')
        for t in range(60):
            outputs += cal.add_pose(int(scene.stamps_ns[t]), scene.R_wc_slam[t], scene.c_slam[t],
                                    'map')
            outputs += cal.add_joints(int(scene.stamps_ns[t]), scene.joints_cam[t][None], 'camera')
        results.append(Run(cal, outputs))
    clean_run, far_run = results
    assert far_run.calibrator.map is not None and len(far_run.calibrator.map) == len(floor)
    assert far_run.scales[-1] == pytest.approx(clean_run.scales[-1], rel=1e-9)
    assert far_run.largest_value_m() == pytest.approx(clean_run.largest_value_m(), rel=1e-9)


def test_no_output_carries_a_value_beyond_output_max_m():
    """output_max_m set to 2 m on a walk that goes beyond it: the poses, odometry and joints
    beyond are suppressed and the cloud loses its points beyond, each counted as
    output_implausible; everything published is within the bound."""
    scene = walking_scene(frames=60)
    cal = Calibrator(HacParams(min_samples=5, cloud_min_period_s=0.0, output_max_m=2.0))
    outputs = cal.add_map(int(scene.stamps_ns[0]), scene.floor_points_slam(), 'map')
    for t in range(60):
        outputs += cal.add_pose(int(scene.stamps_ns[t]), scene.R_wc_slam[t], scene.c_slam[t], 'map')
        outputs += cal.add_joints(int(scene.stamps_ns[t]), scene.joints_cam[t][None], 'camera')
    run = Run(cal, outputs)
    assert run.largest_value_m() <= 2.0
    assert run.of(PoseOut) and run.of(CloudOut)
    suppressed = cal.status().rejected['output_implausible']
    assert suppressed >= len(run.of(CloudOut))  # every cloud trimmed (the floor is 12 m wide)
    assert len(run.of(PoseOut)) < 60 - 5  # the poses beyond 2 m are gone


# ============================================================================ reports
def test_every_report_gives_the_last_scale_written(tmp_path):
    """The summary's final scale is the last /hac/scale written, in hac replay, hac batch and
    hac eval alike (offline, on a drifting SLAM, where the online estimate differs from it)."""
    drift = simulate(tmp_path / 'drift', 'drift', seed=1, duration=30.0)
    summary = replay(drift, tmp_path / 'out')
    with Recording(tmp_path / 'out') as recording:
        written = [m.data for _, m in recording.read('/hac/scale')]
    assert summary.final_scale == written[-1]
    assert f'final scale {written[-1]:.6g} ' in summary.text()
    assert abs(summary.status.scale / written[-1] - 1) > 1e-3  # the case the issue saw
    result = batch([drift], tmp_path / 'batch', workers=1)
    assert result.rows[0].final_scale == pytest.approx(written[-1], rel=1e-12)
    evaluation = evaluate(tmp_path / 'out', drift)
    assert evaluation.rows['hac']['scale_final'] == pytest.approx(written[-1], rel=1e-12)


def test_a_replay_that_calibrated_nothing_exits_3_and_its_batch_row_fails(walk, tmp_path):
    """Every map garbage: nothing calibrated. hac replay exits 3 with one line saying why and a
    summary without a made-up scale; in hac batch that input's row is failed with the reason."""
    path = faulty(walk, tmp_path, maps_big_endian())
    result = hac('replay', str(path), '-o', str(tmp_path / 'out'), '--no-progress')
    assert result.returncode == 3, result.stderr
    assert 'final scale: none' in result.stdout and 'Traceback' not in result.stderr
    why = [line for line in result.stderr.splitlines() if 'nothing calibrated' in line]
    assert len(why) == 1 and 'rejected most' in why[0]
    rows = batch([path], tmp_path / 'batch', workers=1).rows
    assert rows[0].status == 'failed' and 'nothing calibrated' in rows[0].error


def hac(*args: str, timeout: float = 300.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'hac_ros.cli', *args], cwd=REPO,
                          capture_output=True, text=True, timeout=timeout)
