"""Two SLAMs on one pose topic (two robots in one domain without namespaces): poses whose frame
flips back and forth are another publisher's, not a re-initialisation every 33 ms (a new frame is
a re-initialisation once ``reset_confirm_poses`` more poses follow in it, docs/method.md); in one
frame, their poses zigzag between the two robots (``pose_zigzag``). The node also sees the second
publisher in the graph (test_node_story.py)."""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
from faultkit import run_online
from injected import POSE, _nth, _stamp_ns, rewrite, simulate, truth_scale

from hac_ros.core.rules.health import OK, HealthMonitor
from hac_ros.core.stream.pose_stream import ZIGZAG_POSES, ZigzagWatch
from hac_ros.recording.reader import Recording
from hac_ros.replay.replayer import replay

REPO = Path(__file__).resolve().parents[1]


def in_frame(frame_id: str):
    def change(msg):
        msg = copy.deepcopy(msg)
        msg.header.frame_id = frame_id
        return msg
    return change


@pytest.fixture(scope='module')
def walk(tmp_path_factory) -> Path:
    return simulate(tmp_path_factory.mktemp('walk') / 'walk', 'walk', seed=0, duration=12.0)


def test_poses_that_flip_between_two_frames_are_refused_not_taken_for_resets(walk, tmp_path):
    """Every other pose in 'map2': counted pose_wrong_frame, no reset, every status WARN with
    the reason, and the log says it once, not once per pose."""
    path = rewrite(walk, tmp_path / 'flip', _nth(POSE, set(range(1, 400, 2)), in_frame('map2')))
    run = run_online(path)
    cal = run.calibrator
    assert cal.resets == 0
    assert cal.rejected['pose_wrong_frame'] == 180  # the odd poses (the recording has 361)
    monitor = HealthMonitor()
    flipping = [s for s in run.statuses if s.stamp_ns < _stamp_ns_of_pose(walk, 359)]
    assert flipping and all(monitor.assess(s).level != OK for s in flipping)
    notices = [o for o in run.outputs if getattr(o, 'cause', '') == 'pose_wrong_frame']
    assert len(notices) == 1
    assert "SLAM pose in frame 'map2', the poses before and after it in 'map'" in notices[0].text
    summary = replay(path, tmp_path / 'out')
    assert not summary.resets and summary.calibrated
    assert abs(summary.final_scale / truth_scale(walk) - 1.0) < 0.02


def test_one_pose_in_another_frame_is_refused_and_the_run_goes_on(walk, tmp_path):
    path = rewrite(walk, tmp_path / 'one', _nth(POSE, {100}, in_frame('odom')))
    run = run_online(path)
    assert run.calibrator.resets == 0 and run.calibrator.rejected['pose_wrong_frame'] == 1
    clean = run_online(walk)
    assert run.scales[-1] == pytest.approx(clean.scales[-1], rel=1e-3)


def test_a_slam_that_restarts_in_a_new_frame_resets_once_at_its_first_pose(tmp_path):
    """bags/reset_short: the SLAM re-initialises at 6 s in a new frame; the segment starts at
    the first pose in it, as before the confirmation, and that pose is not lost."""
    source = REPO / 'bags' / 'reset_short'
    with Recording(source) as recording:
        poses = [msg for _, msg in recording.read('/slam/pose')]
    first = next(_stamp_ns(m) for m in poses if m.header.frame_id != poses[0].header.frame_id)
    summary = replay(source, tmp_path / 'out')
    assert [(r.cause, r.stamp_ns) for r in summary.resets] == [('map_frame', first)]
    assert not summary.status.rejected.get('pose_wrong_frame')


def _stamp_ns_of_pose(path: Path, index: int) -> int:
    with Recording(path) as recording:
        return _stamp_ns(recording.read('/slam/pose')[index][1])


def test_two_robots_in_one_frame_zigzag_and_the_status_says_so(walk, tmp_path):
    """Every other pose is another robot's, 5 m away in the same frame: from the 30th pose on,
    every status WARNs pose_zigzag; the clean run never does."""
    def elsewhere(msg):
        msg = copy.deepcopy(msg)
        msg.pose.position.x += 5.0
        msg.pose.position.y += 2.0
        return msg

    path = rewrite(walk, tmp_path / 'two', _nth(POSE, set(range(1, 400, 2)), elsewhere))
    statuses = run_online(path).statuses
    monitor = HealthMonitor()
    later = [s for s in statuses if s.stamp_ns >= _stamp_ns_of_pose(walk, ZIGZAG_POSES + 2)]
    assert later and all('pose_zigzag' in s.conditions and monitor.assess(s).level != OK
                         for s in later)
    assert not any('pose_zigzag' in s.conditions for s in run_online(walk).statuses)


@pytest.mark.parametrize('motion', ['still and noisy', 'frozen', 'walking', 'circling'])
def test_one_camera_never_zigzags(motion):
    rng = np.random.default_rng(0)
    t = np.arange(300) / 30.0
    centres = {'still and noisy': rng.normal(0.0, 1e-3, (300, 3)),
               'frozen': np.zeros((300, 3)),
               'walking': np.c_[0.04 * np.arange(300), 0.01 * np.sin(7 * t), 0.005 * rng.normal(
                   size=300)],
               'circling': np.c_[np.cos(t), np.sin(t), np.zeros(300)]}[motion]
    watch = ZigzagWatch()
    for c in centres:
        watch.pose(c)
        assert not watch.holds


def test_a_recording_of_two_publishers_on_the_pose_topic_says_so_at_replay(walk, tmp_path,
                                                                           capsys):
    from hac_ros.cli import main

    two = rewrite(walk, tmp_path / 'two', lambda messages: messages, {'/slam/pose': 2})
    assert main(['replay', str(two), '-o', str(tmp_path / 'out')]) == 0
    said = 'the recording says 2 publishers offered /slam/pose: their messages interleave'
    assert said in capsys.readouterr().err
    one = rewrite(walk, tmp_path / 'one', lambda messages: messages, {'/slam/pose': 1})
    assert main(['replay', str(one), '-o', str(tmp_path / 'out1')]) == 0
    assert 'publishers offered' not in capsys.readouterr().err
