"""The fault suite: what hac_ros does when its inputs go wrong (docs/node.md, "Faults").

Every fault is injected into a real simulated recording (``hac simulate walk --seed 1
--hmr-bias 0``, true scale in /gt/scale; :mod:`injected`) and replayed through the node's core as
``hac replay --mode online`` does; where the node differs from the replay (time, overload,
status, signals) it is also played to a live ``hac_node`` over DDS. For every fault: hac_ros keeps
running, counts it under its own reason, publishes no non-finite or absurd value, and never says
OK while it is wrong or blind.
"""
from __future__ import annotations

import os
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from faultkit import LiveNode, Run, run_online, wait_until, written_diagnostics
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
from hac_ros.core.rules.health import OK, STALE, WARN
from hac_ros.core.rules.params import HacParams
from hac_ros.evaluation.evaluate import evaluate
from hac_ros.recording.reader import Recording
from hac_ros.replay.replayer import replay

rclpy = pytest.importorskip('rclpy')
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from msg_adapters import rclpy_types, stamp_to_ns

TYPES = rclpy_types()
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
SANE_M = 1e4  # no published value may be larger (metres; the bound)
REPO = Path(__file__).resolve().parents[1]


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


# ============================================================================ signals
SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP]


def interrupted_midway(args: list[str], inside: Callable[[int], bool], signum: int,
                       tmp_path: Path) -> tuple[int, str]:
    """Run ``hac ARGS``, wait until ``inside(pid)`` says it is in the middle of its work, stop it
    there (SIGSTOP: it cannot finish meanwhile, however loaded the machine), send ``signum``, let
    it go on; its exit code and stderr. Its session must be empty afterwards (no process left)."""
    stderr_path = tmp_path / 'stderr.txt'
    with open(stderr_path, 'w') as stderr:
        proc = subprocess.Popen([sys.executable, '-m', 'hac_ros.cli', *args], cwd=REPO,
                                stdout=subprocess.DEVNULL, stderr=stderr, start_new_session=True)
        try:
            deadline = time.monotonic() + 600.0
            while not inside(proc.pid):
                assert proc.poll() is None, f'hac {args[0]} finished before it could be interrupted'
                assert time.monotonic() < deadline
                time.sleep(0.005)
            os.kill(proc.pid, signal.SIGSTOP)
            assert inside(proc.pid), 'left its work before it was stopped'
            os.kill(proc.pid, signum)
            os.kill(proc.pid, signal.SIGCONT)
            code = proc.wait(timeout=120.0)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    assert wait_until(lambda: not session_members(proc.pid), 30.0), session_members(proc.pid)
    return code, stderr_path.read_text()


def session_members(sid: int) -> list[str]:
    """The live processes of session ``sid`` (zombies waiting to be reaped left out)."""
    members = []
    for entry in os.listdir('/proc'):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f'/proc/{entry}/stat').read_text()
            if os.getsid(int(entry)) == sid and stat.rsplit(')', 1)[1].split()[0] != 'Z':
                members.append(Path(f'/proc/{entry}/cmdline').read_text().replace('\0', ' '))
        except OSError:
            continue
    return members


def staging(directory: Path) -> Callable[[int], bool]:
    """In the middle: a staging directory or file (``.*partial``) exists in ``directory``."""
    return lambda pid: directory.is_dir() and any(directory.glob('.*partial'))


def reading(path: Path) -> Callable[[int], bool]:
    """In the middle: the process has a file under ``path`` open."""
    target = str(path.resolve())

    def check(pid: int) -> bool:
        try:
            return any(os.readlink(f'/proc/{pid}/fd/{fd}').startswith(target)
                       for fd in os.listdir(f'/proc/{pid}/fd'))
        except OSError:
            return False
    return check


def assert_clean_interruption(code: int, stderr: str, signum: int) -> None:
    assert code == 128 + signum, stderr
    assert 'Traceback' not in stderr
    lines = [line for line in stderr.splitlines() if 'interrupted' in line]
    assert len(lines) == 1 and signal.Signals(signum).name in lines[0], stderr


@pytest.mark.slow
@pytest.mark.parametrize('signum', SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_a_signal_to_hac_replay_leaves_nothing_and_exits_128_plus_it(walk, tmp_path, signum):
    """SIGTERM and SIGHUP (timeout, systemd, Slurm, a closed terminal) end hac replay as Ctrl-C
    does: no OUT, no staging directory, the input untouched, one line, exit 128 + the signal."""
    results = tmp_path / 'results'
    out = results / 'out'
    code, stderr = interrupted_midway(['replay', str(walk), '-o', str(out), '--mode', 'online'],
                                      staging(results), signum, tmp_path)
    assert_clean_interruption(code, stderr, signum)
    assert not results.exists()  # nor OUT, nor its staging, nor the parent it made


def loading(library: str) -> Callable[[int], bool]:
    """In the middle: the process has mapped a file of ``library`` (it is importing it)."""
    def check(pid: int) -> bool:
        try:
            return f'/{library}/' in Path(f'/proc/{pid}/maps').read_text()
        except OSError:
            return False
    return check


@pytest.mark.slow
@pytest.mark.parametrize('library', ['numpy', 'scipy'])
def test_a_signal_while_hac_replay_starts_is_one_line_too(walk, tmp_path, library):
    """Ctrl-C while the command is still starting (importing numpy for the package, scipy for
    the replay): one line, exit 130, no traceback, nothing written."""
    out = tmp_path / 'results' / 'out'
    code, stderr = interrupted_midway(['replay', str(walk), '-o', str(out)], loading(library),
                                      signal.SIGINT, tmp_path)
    assert_clean_interruption(code, stderr, signal.SIGINT)
    assert not (tmp_path / 'results').exists()


@pytest.mark.slow
def test_a_signal_to_hac_batch_stops_its_workers_and_keeps_what_finished(walk, tmp_path):
    """SIGTERM to hac batch alone (not its workers): it stops them within seconds, starts no
    new recording, leaves no process and no partial output, keeps what finished; --resume
    completes the rest."""
    inputs = []
    for name in ('one', 'two', 'three'):
        inputs.append(tmp_path / name)
        shutil.copytree(walk, inputs[-1])
    out = tmp_path / 'out'
    start = time.monotonic()
    code, stderr = interrupted_midway(
        ['batch', *map(str, inputs), '-o', str(out), '--workers', '1'],
        lambda pid: bool(list(out.glob('*.done.json'))) and any(out.glob('.*partial')),
        signal.SIGTERM, tmp_path)
    assert_clean_interruption(code, stderr, signal.SIGTERM)
    assert time.monotonic() - start < 300.0  # a hang, not a busy machine
    finished = {p.name[:-len('.done.json')] for p in out.glob('*.done.json')}
    assert len(finished) == 1  # the recording in progress was stopped, not let finish
    assert not list(out.glob('.*partial')) and not (out / 'summary.csv').exists()
    assert {p.name for p in out.iterdir() if p.is_dir()} == finished | {'logs'}
    result = batch(inputs, out, workers=1, resume=True)
    assert [r.skipped for r in result.rows].count(True) == 1 and all(r.ok for r in result.rows)


@pytest.mark.slow
@pytest.mark.parametrize('command', ['simulate', 'import', 'export', 'eval', 'plot', 'demo'])
def test_every_command_stops_cleanly_on_sigterm(walk, tmp_path, command):
    """SIGTERM in the middle of each other command: exit 143, one line, nothing partial."""
    work = tmp_path / 'work'
    work.mkdir()
    if command == 'simulate':
        args, inside = ['simulate', 'walk', '-o', str(work / 'sim')], staging(work)
    elif command == 'import':
        args, inside = _import_args(walk, tmp_path, work / 'imported'), staging(work)
    elif command in ('export', 'eval', 'plot'):
        replayed = tmp_path / 'replayed'
        replay(walk, replayed)
        args = {'export': ['export', str(replayed), '-o', str(work / 'out.npz')],
                'eval': ['eval', str(replayed), '--gt', str(walk), '--json',
                         str(work / 'eval.json')],
                'plot': ['plot', str(replayed), '--gt', str(walk), '-o', str(work / 'figures')]
                }[command]
        inside = staging(work / 'figures') if command == 'plot' else reading(replayed)
    else:
        args = ['demo', '--recording', str(walk), '-o', str(work / 'demo')]
        inside = staging(work / 'demo')  # its replay is being written
    code, stderr = interrupted_midway(args, inside, signal.SIGTERM, tmp_path)
    assert_clean_interruption(code, stderr, signal.SIGTERM)
    left = [p for p in work.rglob('*')]
    assert left == [], left  # hac demo -o NEWDIR: not even the directory it made


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


# ============================================================================ files
@pytest.fixture(scope='module')
def unshare() -> list[str]:
    """A private mount namespace, where an unprivileged user may mount a tiny tmpfs: a real full
    or read-only filesystem, no mock."""
    command = ['unshare', '--user', '--map-root-user', '--mount']
    try:
        probe = subprocess.run([*command, 'sh', '-c', 'mount -t tmpfs -o size=16k tmpfs /mnt'],
                               capture_output=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as exc:
        pytest.skip(f'unshare not available: {exc}')
    if probe.returncode != 0:
        pytest.skip(f'cannot mount a tmpfs in a user namespace here: {probe.stderr!r}')
    return command


def on_small_filesystem(unshare: list[str], tmp_path: Path, args: list[str], size: str,
                        read_only: bool = False) -> tuple[int, str, list[str]]:
    """``hac ARGS`` with ``{fs}`` in them standing for a fresh tmpfs of ``size`` (read-only if
    asked): its exit code, stderr, and what is left on the filesystem afterwards."""
    mount = tmp_path / 'fs'
    mount.mkdir()
    left, err = tmp_path / 'left.txt', tmp_path / 'stderr.txt'
    command = ' '.join(shlex.quote(a.replace('{fs}', str(mount)))
                       for a in [sys.executable, '-m', 'hac_ros.cli', *args])
    options = f'size={size}' + (',ro' if read_only else '')
    script = (f'mount -t tmpfs -o {options} tmpfs {mount} || exit 99; cd {REPO}; '
              f'{command} >/dev/null 2>{err}; code=$?; ls -A {mount} > {left}; exit $code')
    code = subprocess.run([*unshare, 'sh', '-c', script], timeout=600).returncode
    assert code != 99, 'the tmpfs could not be mounted'
    return code, err.read_text(), left.read_text().split()


def assert_one_line_error(code: int, stderr: str, *needles: str) -> None:
    assert code == 2, stderr
    assert 'Traceback' not in stderr, stderr
    lines = [line for line in stderr.splitlines() if ': error: ' in line]
    assert len(lines) == 1, stderr  # (notices printed before it are the replay's own)
    for needle in needles:
        assert needle in lines[0], stderr


@pytest.mark.slow
def test_a_full_disk_gives_one_line_and_leaves_nothing(unshare, walk, tmp_path):
    """hac replay onto a 1 MB filesystem (its output needs about 5 MB): one line naming the
    problem, exit 2, no OUT and no staging left."""
    code, stderr, left = on_small_filesystem(
        unshare, tmp_path, ['replay', str(walk), '-o', '{fs}/out', '--no-progress'], '1m')
    assert_one_line_error(code, stderr, 'No space left on device')
    assert left == []


@pytest.mark.slow
def test_a_read_only_output_gives_one_line(unshare, walk, tmp_path):
    code, stderr, left = on_small_filesystem(
        unshare, tmp_path, ['replay', str(walk), '-o', '{fs}/out', '--no-progress'], '1m',
        read_only=True)
    assert_one_line_error(code, stderr, 'Read-only file system')
    assert left == []


@pytest.mark.slow
@pytest.mark.parametrize('command', ['simulate', 'export', 'batch'])
def test_other_commands_on_a_full_disk_give_one_line_and_leave_nothing(unshare, walk, tmp_path,
                                                                       command):
    if command == 'simulate':
        args, size = ['simulate', 'walk', '-o', '{fs}/sim'], '1m'
    elif command == 'export':
        replayed = tmp_path / 'replayed'
        replay(walk, replayed)
        args, size = ['export', str(replayed), '-o', '{fs}/out.npz'], '64k'
    else:
        args, size = ['batch', str(walk), '-o', '{fs}/batch', '--workers', '1'], '1m'
    code, stderr, left = on_small_filesystem(unshare, tmp_path, args, size)
    if command == 'batch':  # the recording's own failure is its row; the summary is written
        assert code in (1, 2), stderr
        assert 'Traceback' not in stderr
    else:
        assert_one_line_error(code, stderr, 'No space left on device')
        assert left == []


@pytest.mark.parametrize('factor, shift_s, needle', [
    (1000.0, 0.0, 'millimetres'), (0.01, 0.0, 'centimetres converted to metres twice'),
    (1.0, 3600.0, 'share no time')], ids=['mm', 'cm_twice', 'outside_in_time'])
def test_hac_import_refuses_joints_the_calibrator_would_refuse(walk, tmp_path, factor, shift_s,
                                                              needle):
    """hac import judges the joints as the calibrator does (a body's size in metres, naming the
    likely unit) and checks they overlap the trajectory in time: exit 2, one line, nothing
    written."""
    out = tmp_path / 'imported'
    result = hac(*_import_args(walk, tmp_path, out, factor, shift_s))
    assert result.returncode == 2, result.stderr
    assert 'Traceback' not in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert needle in result.stderr
    assert not out.exists()


# ============================================================================ the node over DDS
@pytest.fixture
def live() -> Any:
    nodes: list[LiveNode] = []

    def make(**params: Any) -> LiveNode:
        nodes.append(LiveNode(**params))
        return nodes[-1]
    yield make
    for node in nodes:
        node.close()


@pytest.mark.slow
def test_a_recording_looped_into_the_node_calibrates_its_second_loop(walk, live):
    """``hac play --loop`` into hac_node over DDS: the second loop (header time back 30 s) is a
    new stream, calibrated within 3 % of the truth; the status says so."""
    from hac_ros.ros.player import Player

    node = live()
    truth = truth_scale(walk)
    stop = threading.Event()
    with Player(walk, rate=3.0, loop=True, wait_s=30.0, context=node.context) as player:
        playing = threading.Thread(target=player.run, args=(stop,))
        playing.start()
        try:
            def second_loop_done() -> bool:
                stamps = [stamp_to_ns(m.header.stamp) for m in node.received['/hac/human_joints']]
                back = [k for k in range(1, len(stamps)) if stamps[k] < stamps[k - 1]]
                return bool(back) and len(stamps) - back[0] > 800
            assert wait_until(second_loop_done, 300.0), 'the second loop was not calibrated'
        finally:
            stop.set()
            playing.join()
    stamps = [stamp_to_ns(m.header.stamp) for m in node.received['/hac/human_joints']]
    back = next(k for k in range(1, len(stamps)) if stamps[k] < stamps[k - 1])
    scales = [m.data for m in node.received['/hac/scale']]
    second = np.array(scales[back:back + 800])
    assert abs(second[-1] / truth - 1) < 0.03
    # settled: the second half of it (a loaded machine drops frames, and the new stream's
    # estimate then gathers its samples over more stamp time: seen 2.1-2.8 % a tenth in)
    assert np.all(np.abs(second[len(second) // 2:] / truth - 1) < 0.03)
    statuses = node.statuses()
    # one jump back per loop played (a busy machine drops frames and plays more loops)
    assert any(int(values.get('event.time_jump_back', 0)) >= 1 for _, _, values in statuses)
    assert not any('pose_out_of_order' in values for _, _, values in statuses)


def test_the_inbox_drops_the_oldest_joints_frames_never_a_pose():
    """Input faster than processing, in the node's inbox (joints_backlog_max 2, a node that
    takes a second a frame): of six joints frames waiting, the four oldest are dropped, in order;
    every pose stays, in arrival order."""
    from hac_ros.ros.intake import Inbox

    inbox = Inbox(backlog_max=2)
    inbox.frame_cost_s = 1.0  # as the processing thread measures it
    for k in range(6):
        inbox.put('pose', k)
        inbox.put('joints', k)
    taken, dropped = [], []
    while True:
        took = inbox.get()
        item, waiting = took.item, took.waiting
        assert item is not None
        dropped += [frame.data for frame in took.dropped]
        taken.append((item.kind, item.data))
        assert waiting <= 2
        if (item.kind, item.data) == ('joints', 5):
            break
    assert taken == [('pose', k) for k in range(5)] + [('joints', 4), ('pose', 5), ('joints', 5)]
    assert dropped == [0, 1, 2, 3]
    assert inbox.received == {'pose': 6, 'joints': 6}


def test_the_node_warns_latency_backlog_and_a_silent_input():
    """The node's own findings for /diagnostics (wall clock, the margins seconds wide): WARN
    latency over latency_warn_s, backlog at joints_backlog_max, no_joints while poses come;
    on its steady-clock timer WARN no_status while input comes but makes no status, STALE
    no_input when nothing comes."""
    from hac_ros.ros.liveness import Liveness

    params = HacParams(latency_warn_s=0.1, joints_backlog_max=2, stale_after_s=2.0)
    quiet = Liveness()
    assert quiet.findings(params)[0] == []  # no frame yet: no latency, nothing silent yet
    busy = Liveness()
    for _ in range(100):
        busy.load.frame(0.5, 2)  # half a second from arrival to processed, two frames waiting
    now = time.monotonic()
    busy.arrived = {'pose': now, 'joints': now - 60.0}
    found, values = busy.findings(params)
    assert {f.reason for f in found} == {'latency', 'backlog', 'no_joints'}
    assert all(f.level == WARN for f in found)
    assert dict(values)['latency_p99_ms'] == '500.0' and dict(values)['backlog'] == '2'
    assert dict(busy.findings(params)[1])['backlog'] == '0'  # counted again since the last status
    busy.status_sent_s = now - 60.0
    busy.first_arrival_s = now - 120.0
    late = busy.stale(params)
    assert late is not None and late.reason == 'no_status' and late.level == WARN
    busy.arrived = {'pose': now - 60.0, 'joints': now - 60.0}
    gone = busy.stale(params)
    assert gone is not None and gone.reason == 'no_input' and gone.level == STALE
    never = Liveness()  # no input ever
    never.status_sent_s = now - 60.0
    blind = never.stale(params)
    assert blind is not None and blind.reason == 'no_input' and blind.level == STALE


@pytest.mark.slow
def test_overload_drops_the_oldest_frames_counts_them_and_warns(live):
    """Twenty people at 200 frames/s, more than the node can process: it never lets a backlog
    build (the newest frames are answered), drops the oldest joints frames, counts them
    (frames_dropped) and warns; every frame sent is answered, dropped or lost."""
    from scenes import walking_scene

    from msg_adapters import joints_to_pose_array, rt_to_pose_stamped, xyz_to_cloud

    # twenty copies of one person: their samples are one sample's evidence, and the window's
    # 2000 samples cover a few seconds of it, so the estimate's own uncertainty may sit near the
    # default converged_max_rel_sigma (1 %) and flip 'converged'; this test is about the backlog
    node = live(input_qos='reliable', min_samples=5, converged_max_rel_sigma=0.05)
    scene = walking_scene(frames=1200, rate=200.0)
    pose_pub = node.io.create_publisher(TYPES.get('geometry_msgs/msg/PoseStamped'), '/slam/pose',
                                        RELIABLE)
    joints_pub = node.io.create_publisher(TYPES.get('geometry_msgs/msg/PoseArray'),
                                          '/hmr/joints', RELIABLE)
    cloud_pub = node.io.create_publisher(TYPES.get('sensor_msgs/msg/PointCloud2'), '/slam/cloud',
                                         LATCHED)
    assert wait_until(lambda: pose_pub.get_subscription_count() > 0
                      and joints_pub.get_subscription_count() > 0
                      and cloud_pub.get_subscription_count() > 0, 30.0)
    first = int(scene.stamps_ns[0])
    cloud_pub.publish(xyz_to_cloud(scene.floor_points_slam(), first, 'map', TYPES))
    crowd = np.repeat(scene.joints_cam[:, None], 20, axis=1)  # twenty people
    start = time.monotonic()
    for t in range(len(scene.stamps_ns)):
        stamp = int(scene.stamps_ns[t])
        pose_pub.publish(rt_to_pose_stamped(scene.R_wc_slam[t], scene.c_slam[t], stamp, 'map',
                                            TYPES))
        joints_pub.publish(joints_to_pose_array(crowd[t], stamp, 'camera', TYPES))
        time.sleep(max(0.0, start + (t + 1) / 200.0 - time.monotonic()))
    last = int(scene.stamps_ns[-1])
    assert wait_until(lambda: node.received['/hac/human_joints'] and stamp_to_ns(
        node.received['/hac/human_joints'][-1].header.stamp) == last, 60.0), \
        'the newest frame was not answered'
    assert wait_until(lambda: any(int(v.get('frames', 0)) + int(v.get('rejected.frames_dropped', 0))
                                  + int(v.get('rejected.joints_lost', 0)) == len(scene.stamps_ns)
                                  for _, _, v in node.statuses()), 30.0), node.statuses()[-1]
    statuses = node.statuses()
    final = statuses[-1][2]
    assert int(final['rejected.frames_dropped']) > 0
    flagged = [s for s in statuses if 'frames_dropped' in s[2]['reasons']]
    assert flagged and all(level >= WARN for level, _, _ in flagged)
    assert 'latency_p99_ms' in final and 'backlog' in final


@pytest.mark.slow
def test_a_node_without_input_says_stale_and_checks_types_without_clock(live):
    """No input at all: /diagnostics says STALE (no_input) on the node's steady clock, also
    under use_sim_time with no /clock, where the input-type check still runs: a publisher of the
    wrong type on slam/pose is reported within seconds."""
    from rclpy.context import Context

    node = live(use_sim_time=True, stale_after_s=1.0)
    other = Context()  # a participant of its own: one may not use two types on one topic
    rclpy.init(context=other)
    try:
        publisher = rclpy.create_node('hac_faults_wrong_type', context=other)
        publisher.create_publisher(TYPES.get('nav_msgs/msg/Odometry'), '/slam/pose', RELIABLE)
        assert wait_until(lambda: any(level == STALE and 'no_input' in values['reasons']
                                      for level, _, values in node.statuses()), 30.0)
        assert wait_until(lambda: node.node.core.rejected.get('pose_wrong_type', 0) >= 1, 30.0)
        publisher.destroy_node()
    finally:
        rclpy.shutdown(context=other)


@pytest.mark.slow
def test_poses_without_joints_warn_no_joints(live):
    """SLAM poses keep coming, joints stopped: the stamp-time statuses carry WARN no_joints."""
    from scenes import walking_scene

    from msg_adapters import rt_to_pose_stamped

    node = live(input_qos='reliable', stale_after_s=1.0)
    scene = walking_scene(frames=200, rate=30.0)
    pose_pub = node.io.create_publisher(TYPES.get('geometry_msgs/msg/PoseStamped'), '/slam/pose',
                                        RELIABLE)
    assert wait_until(lambda: pose_pub.get_subscription_count() > 0, 30.0)
    start = time.monotonic()
    for t in range(len(scene.stamps_ns)):
        pose_pub.publish(rt_to_pose_stamped(scene.R_wc_slam[t], scene.c_slam[t],
                                            int(scene.stamps_ns[t]), 'map', TYPES))
        time.sleep(max(0.0, start + (t + 1) / 30.0 - time.monotonic()))
        if any('no_joints' in values['reasons'] for _, _, values in node.statuses()):
            break
    flagged = [s for s in node.statuses() if 'no_joints' in s[2]['reasons']]
    assert flagged and flagged[-1][0] == WARN


@pytest.mark.slow
@pytest.mark.parametrize('signum', SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_a_signal_ends_the_node_cleanly(tmp_path, signum):
    """hac_node (a process) ends cleanly on SIGINT, SIGTERM and SIGHUP: exit 0, no traceback."""
    log_path = tmp_path / 'node.log'
    with open(log_path, 'w') as log:
        proc = subprocess.Popen([sys.executable, '-m', 'hac_ros.ros.node'], cwd=REPO,
                                stdout=log, stderr=subprocess.STDOUT,
                                env={**os.environ, 'PYTHONUNBUFFERED': '1'})
        try:
            assert wait_until(lambda: '-> /hac/* in' in log_path.read_text()
                              or proc.poll() is not None, 120.0), log_path.read_text()
            assert proc.poll() is None, log_path.read_text()
            proc.send_signal(signum)
            code = proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    text = log_path.read_text()
    assert code == 0, text
    assert 'Traceback' not in text
