"""The summaries say what the run measured and what its statuses said (issues 35 and 36).

``hac replay``'s summary gives the share of its ``/diagnostics`` statuses at each level and each
reason's share, never a bare "converged" over a run that was mostly WARN (exit 0 still means a scale
was published); ``hac batch``'s summary.csv has them as ``warn_pct`` and ``reasons``.
"""
from __future__ import annotations

import copy
import csv
import re
import subprocess
import sys
from pathlib import Path

import pytest
from injected import JOINTS, _nth, rewrite, simulate

from hac_ros.core.rules.health import OK, WARN
from hac_ros.core.rules.status_shares import StatusShares
from hac_ros.recording.reader import Recording

REPO = Path(__file__).resolve().parents[1]
DURATION_S = 20.0


def hac(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'hac_ros.cli', *argv], cwd=REPO, text=True,
                          capture_output=True, timeout=600)


def _with_a_bystander_in_millimetres(frames: int):
    """The joints messages of the first ``frames`` frames carry a second person in millimetres
    (a second HMR output in the wrong unit): refused as joints_not_metres, a reason that makes
    every status WARN while it grows."""
    def add(msg):
        msg = copy.deepcopy(msg)
        extra = copy.deepcopy(msg.poses[:24])
        for pose in extra:
            pose.position.x *= 1000.0
            pose.position.y *= 1000.0
            pose.position.z *= 1000.0
        msg.poses = list(msg.poses) + extra
        return msg
    return _nth(JOINTS, set(range(frames)), add)


@pytest.fixture(scope='module')
def mostly_warn(tmp_path_factory) -> Path:
    """A 20 s walk whose first 14 s carry a bystander in millimetres: calibrated, mostly WARN."""
    base = tmp_path_factory.mktemp('summaries')
    walk = simulate(base / 'walk', 'walk', seed=3, duration=DURATION_S)
    return rewrite(walk, base / 'mostly_warn', _with_a_bystander_in_millimetres(14 * 30))


def _written_statuses(path: Path) -> StatusShares:
    """The /diagnostics statuses a replay wrote, counted as its summary counts them."""
    shares = StatusShares()
    with Recording(path) as recording:
        for _, msg in recording.read('/diagnostics'):
            values = {kv.key: kv.value for kv in msg.status[0].values}
            shares.add(int(msg.status[0].level), values['reasons'].split(','))
    return shares


def test_the_summary_says_what_the_statuses_said(mostly_warn, tmp_path):
    result = hac('replay', str(mostly_warn), '-o', str(tmp_path / 'out'))
    assert result.returncode == 0, result.stderr  # a scale was published
    written = _written_statuses(tmp_path / 'out')
    assert written.percent(written.levels[WARN]) > 60  # the run was mostly WARN
    assert written.reasons['joints_not_metres'] > written.reasons['not_converged'] > 0
    line, = [line for line in result.stdout.splitlines() if 'statuses (' in line]
    assert line == f'  statuses ({written.total} /diagnostics, one per second): {written.text()}'
    assert re.search(r'OK \d+ %, WARN \d+ % \(joints_not_metres \d+ %, not_converged \d+ %\)',
                     line), line
    at_end, = [line for line in result.stdout.splitlines() if 'at the end' in line]
    assert at_end.endswith(f'converged, status {written.last_text()}'), at_end


def test_batch_rows_have_the_statuses_share_and_reasons(mostly_warn, tmp_path):
    result = hac('batch', str(mostly_warn), '-o', str(tmp_path / 'batch'), '--workers', '1')
    assert result.returncode == 0, result.stderr
    with open(tmp_path / 'batch' / 'summary.csv', encoding='utf-8') as f:
        row, = csv.DictReader(f)
    written = _written_statuses(tmp_path / 'batch' / 'mostly_warn')
    assert float(row['warn_pct']) == pytest.approx(written.warn_pct, abs=0.05)
    assert row['reasons'] == written.reasons_text()
    assert f'mostly WARN: {mostly_warn}: WARN {written.warn_pct:.0f} %' in result.stdout


def test_shares_are_said_in_whole_percent_without_hiding_a_rare_level():
    shares = StatusShares()
    for k in range(300):
        shares.add(WARN if k == 0 else OK, ['not_converged'] if k == 0 else [])
    assert shares.text() == 'OK >99 %, WARN <1 % (not_converged <1 %)'
    shares.add(WARN, ['floor_unknown', 'floor_unknown', ''])  # each reason once per status
    assert shares.reasons == {'not_converged': 1, 'floor_unknown': 1}
    assert shares.last_text() == 'WARN (floor_unknown)'
    assert StatusShares().text() == 'no status' and StatusShares().last_text() == 'no status'


# ============================================================================ what was measured
def _segment_lines(stdout: str) -> list[str]:
    return [line for line in stdout.splitlines() if line.startswith('  segment ')]


def test_the_segment_line_gives_the_drift_tests_probability(tmp_path):
    """bags/demo_walk is a constant scale: its segment keeps its median, with the median's
    standard error and the drift test's probability (docs/replay.md, "The two modes"), whatever
    the window."""
    for name, window in (('default', ''), ('short', 'window_s: 6.0')):
        args = []
        if window:
            params = tmp_path / 'short_window.yaml'
            params.write_text(f'hac_node:\n  ros__parameters:\n    {window}\n', encoding='utf-8')
            args = ['--params', str(params)]
        result = hac('replay', 'bags/demo_walk', '-o', str(tmp_path / name), *args)
        assert result.returncode == 0, result.stderr
        line, = _segment_lines(result.stdout)
        assert re.search(r'median \d\.\d+ \+- \d\.\d+(e-\d+)?, constant: median \(drift test: '
                         r'drift probability 0\.\d\d\)$', line), line


# ============================================================================ exit 3: why
def _stamps_moved(topics: tuple[str, ...], by_s: float, until_s: float | None = None):
    """Header stamps of ``topics`` moved by ``by_s`` (another clock); with ``until_s``, those
    messages are dropped instead while their stamp is before the recording's first + until_s (a
    SLAM that starts late)."""
    from injected import _set_stamp, _stamp_ns

    from hac_ros.core.basics.numeric import NS

    def edit(messages):
        first = None
        for topic, log_ns, msg in messages:
            if topic in topics:
                stamp = _stamp_ns(msg)
                first = stamp if first is None else first
                if until_s is not None:
                    if stamp < first + until_s * NS:
                        continue
                else:
                    msg = _set_stamp(msg, stamp + int(by_s * NS))
            yield topic, log_ns, msg
    return edit


SLAM_TOPICS = ('/slam/pose', '/slam/cloud', '/camera/camera_info')


@pytest.fixture(scope='module')
def walk(tmp_path_factory) -> Path:
    return simulate(tmp_path_factory.mktemp('walk') / 'walk', 'walk', seed=3, duration=12.0)


def _why(result: subprocess.CompletedProcess) -> str:
    assert result.returncode == 3, (result.returncode, result.stderr)
    assert 'Traceback' not in result.stderr
    why, = [line for line in result.stderr.splitlines()
            if line.startswith('hac replay: nothing calibrated')]
    return why


def test_joints_and_poses_on_different_clocks_say_by_how_much(walk, tmp_path):
    """The SLAM on a simulated clock that starts at 5 s, the joints on the wall clock: no frame
    ever finds its pose; the notice and the exit-3 line say how far apart they are."""
    from injected import _stamp_ns

    with Recording(walk) as recording:
        first_ns = _stamp_ns(recording.read('/slam/pose')[0][1])
    apart_s = first_ns / 1e9 - 5.0  # the joints' stamps minus the poses'
    path = rewrite(walk, tmp_path / 'clocks', _stamps_moved(SLAM_TOPICS, -apart_s))
    result = hac('replay', str(path), '-o', str(tmp_path / 'out'))
    why = _why(result)
    said = f'the joints are stamped {apart_s:.6g} s after the poses (different clocks?)'
    assert said in why, why
    notices = [line for line in result.stderr.splitlines() if 'never come within reach' in line]
    assert len(notices) == 1 and notices[0].startswith('hac replay: warning: ')
    assert f'{apart_s:.6g} s after the newest SLAM pose (different clocks?' in notices[0]


def test_a_slam_that_starts_late_is_not_taken_for_another_clock(walk, tmp_path):
    path = rewrite(walk, tmp_path / 'late', _stamps_moved(SLAM_TOPICS, 0.0, until_s=4.0))
    result = hac('replay', str(path), '-o', str(tmp_path / 'out'))
    assert result.returncode == 0, result.stderr
    assert 'within reach' not in result.stderr and 'no_pose' in result.stdout


@pytest.mark.parametrize('min_samples, said', [
    (100000, 'min_samples 100000 can never be reached: the window holds at most '
             'window_max_samples 2000 samples'),
    (1000, 'min_samples 1000 was never reached: the window of window_s 30 s held at most ')])
def test_exit_3_names_the_setting_that_kept_the_scale_from_converging(walk, tmp_path,
                                                                     min_samples, said):
    """Online: not 'rejected most: no_map 9' (the few frames before the first map), but the
    reason. Offline the same run gets its scale, flagged "few samples" (issue 43)."""
    params = tmp_path / 'params.yaml'
    params.write_text(f'hac_node:\n  ros__parameters:\n    min_samples: {min_samples}\n',
                      encoding='utf-8')
    why = _why(hac('replay', str(walk), '-o', str(tmp_path / 'out'), '--params', str(params),
                   '--mode', 'online'))
    assert said in why and 'rejected most' not in why, why
    offline = hac('replay', str(walk), '-o', str(tmp_path / 'offline'), '--params', str(params))
    assert offline.returncode == 0 and 'few samples' in offline.stdout, offline.stderr


def test_maps_refused_for_their_frame_are_named_as_the_cause_with_both_frames(walk, tmp_path):
    """The map published in 'odom', the SLAM poses in 'map' (a user's first hour): not only
    'rejected most: no_map', but the refusal behind it, its remedy, and both frames."""
    from injected import CLOUD

    def in_odom(msg):
        msg = copy.deepcopy(msg)
        msg.header.frame_id = 'odom'
        return msg

    path = rewrite(walk, tmp_path / 'odom', _nth(CLOUD, None, in_odom))
    result = hac('replay', str(path), '-o', str(tmp_path / 'out'))
    why = _why(result)
    assert 'rejected most: no_map' in why
    assert re.search(r'the maps were refused: cloud_wrong_frame \d+ \(map cloud in a frame other '
                     r'than the SLAM pose frame; remedy: publish the map in the frame_id of the '
                     r'SLAM poses\)', why), why
    assert "map cloud in frame 'odom', the SLAM poses in 'map': refused" in result.stderr


def test_every_input_a_waiting_reason_names_is_refused_under_a_reason_of_the_table():
    from hac_ros.core.rules.reasons import REASONS, WAITS_FOR, refusals_behind

    for waiting, (_, refusing) in WAITS_FOR.items():
        assert waiting in REASONS and set(refusing) <= set(REASONS), waiting
    assert refusals_behind('no_map', {'no_map': 9}) == ''
    assert refusals_behind('gated', {'cloud_empty': 3}) == ''
    two = refusals_behind('no_pose', {'pose_nonfinite': 2, 'pose_out_of_order': 5})
    assert two.startswith('the SLAM poses were refused: pose_out_of_order 5 (')
    assert ', pose_nonfinite 2 (' in two
