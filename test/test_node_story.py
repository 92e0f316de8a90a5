"""hac_node's log tells the story of a run (docs/node.md, "The log"), and the README's
two-terminal example shows it: a result at 1x, no frame dropped.

The log is read as a user reads it: the node's stderr (in-process through capfd, or the file a
node process writes). Waits are upper bounds on what must happen; nothing is timed.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from logcapture import NodeLog
from test_node import PATIENCE_S, Event, harness, scenario_recording, wait_for  # noqa: F401

from hac_ros.core.basics.numeric import NS
from hac_ros.core.rules.reasons import REASONS
from hac_ros.recording.reader import Recording
from hac_ros.replay.replayer import replay

REPO = Path(__file__).resolve().parents[1]
STARTUP_S = 90.0  # at most: a node process imports numpy/scipy/rclpy and joins DDS discovery
# the log's lines (hac_ros/ros/story.py)
CONVERGED = re.compile(r'\[INFO\] .*converged: scale ([0-9.eE+-]+) \+- ([0-9.eE+-]+) m per SLAM '
                       r'unit \((\d+) samples\), ([0-9.]+) s after the first joints')
FRAMES = re.compile(r'\[INFO\] .*status (\S+?)[ :].*joints frames received (\d+) = processed '
                    r'(\d+) \+ dropped (\d+) \+ waiting (\d+)')
LEVEL_CHANGE = re.compile(r'\[INFO\] .*status (none|OK|WARN|ERROR|STALE) -> (OK|WARN|ERROR|STALE) '
                          r'\(([^)]*)\)')


def test_the_log_tells_inputs_first_map_convergence_level_changes_and_the_status(harness,
                                                                                  capfd):
    """In-process, a simulated walk: each input once with its topic, type and rate; the first
    map; convergence with scale, spread, samples and stamp seconds since the first joints; every
    change of the status level with its reasons; a status line each log_period_s whose counts
    add up; each warning ends with what to do."""
    walk = scenario_recording('walk', duration=8.0)
    # played faster than a slow host processes it: being behind is not this test's story (the
    # latency warning has tests of its own), so it may not hold the status at WARN
    h = harness(log_period_s=0.5, latency_warn_s=60.0)
    h.play(walk.events, frame_period_s=0.01)
    h.settle()
    log = NodeLog(capfd)
    assert log.wait_for(lambda t: len(FRAMES.findall(t)) >= 2 and
                        FRAMES.findall(t)[-1][1] == str(len(walk.joints_stamps)), PATIENCE_S), \
        log.text
    text = log.text
    for topic, msgtype in (('/slam/pose', 'geometry_msgs/msg/PoseStamped'),
                           ('/hmr/joints', 'geometry_msgs/msg/PoseArray'),
                           ('/camera/camera_info', 'sensor_msgs/msg/CameraInfo'),
                           ('/slam/cloud', 'sensor_msgs/msg/PointCloud2')):
        seen = re.findall(rf'\[INFO\] .*input {re.escape(topic)} \({re.escape(msgtype)}\): '
                          r'([0-9.]+ Hz|1 message)', text)  # the map and CameraInfo: once
        assert len(seen) == 1, (topic, text)
    assert len(re.findall(r'\[INFO\] .*first map: \d+ points in frame ', text)) == 1
    converged = CONVERGED.findall(text)
    assert len(converged) == 1, text
    scale, _, samples, after_s = converged[0]
    assert abs(float(scale) / walk.scale_at(int(walk.pose_stamps[-1])) - 1) < 0.05
    assert int(samples) >= h.node.params.min_samples and 0 < float(after_s) < 8.0
    changes = LEVEL_CHANGE.findall(text)
    assert changes[0][:2] == ('none', 'WARN') and 'not_converged' in changes[0][2]
    assert ('WARN', 'OK', 'all clear') in changes
    assert all(before != after for before, after, _ in changes)
    for _, received, processed, dropped, waiting in FRAMES.findall(text):
        assert int(received) == int(processed) + int(dropped) + int(waiting)
    for line in re.findall(r'\[WARN\] .*', text):
        cause = re.search(r'\(([a-z_]+)\)', line)
        if cause and cause.group(1) in REASONS and REASONS[cause.group(1)].remedy != 'none':
            assert 'what to do:' in line or REASONS[cause.group(1)].remedy in line, line


# ================================================================================ README example
def node_command() -> list[str]:
    """README's ``.venv/bin/hac_node`` (the console script beside this Python), or the module."""
    script = Path(sys.executable).with_name('hac_node')
    return [str(script)] if script.exists() else [sys.executable, '-m', 'hac_ros.ros.node']


@pytest.mark.slow
def test_the_readme_two_terminal_example_converges_at_1x_and_drops_nothing(tmp_path):
    """README, "Try the node": ``hac_node`` with its defaults in one process, ``hac play
    bags/demo_walk --wait 30`` at real time in another. The node's log has the convergence line,
    its scale within 0.5 % of the first /hac/scale of ``hac replay --mode online`` of the same
    recording; its status lines add up (received = processed + dropped + waiting) and, once the
    play is over, every frame received was processed, none dropped (and all but at most 1 %
    played were received); nothing is logged at WARN or above."""
    source = REPO / 'bags' / 'demo_walk'
    replay(source, tmp_path / 'online', mode='online')
    with Recording(tmp_path / 'online') as out:
        first_scale = out.read('/hac/scale')[0][1].data
    log_path = tmp_path / 'node.log'
    env = {**os.environ, 'PYTHONUNBUFFERED': '1', 'RCUTILS_COLORIZED_OUTPUT': '0',
           'RCUTILS_LOGGING_BUFFERED_STREAM': '0'}
    with open(log_path, 'w') as log:
        node = subprocess.Popen(node_command(), cwd=REPO, env=env, stdout=log,
                                stderr=subprocess.STDOUT)
    try:
        play = subprocess.run([sys.executable, '-m', 'hac_ros.cli', 'play', str(source),
                               '--wait', str(STARTUP_S)], cwd=REPO, env=env,
                              capture_output=True, text=True, timeout=STARTUP_S + 120)
        assert play.returncode == 0, play.stdout + play.stderr
        played = int(re.search(r'/hmr/joints (\d+)', play.stdout).group(1))

        def settled() -> bool:  # a status line after the play: all received, nothing waiting
            text = log_path.read_text(encoding='utf-8')
            lines = FRAMES.findall(text)
            return bool(lines) and lines[-1][4] == '0' and (
                lines[-1][1] == str(played) or text.count('joints frames received') >= 4)
        # log_period_s (10 s) after the play at most, on a loaded machine more
        assert wait_for(settled, PATIENCE_S), log_path.read_text(encoding='utf-8')
    finally:
        node.send_signal(signal.SIGINT)
        try:
            code = node.wait(timeout=30.0)
        except subprocess.TimeoutExpired:
            node.kill()
            code = node.wait()
    text = log_path.read_text(encoding='utf-8')
    assert code == 0, text
    converged = CONVERGED.findall(text)
    assert converged, text
    assert abs(float(converged[0][0]) / first_scale - 1.0) < 0.005, (converged[0], first_scale)
    lines = FRAMES.findall(text)
    for _, received, processed, dropped, waiting in lines:
        assert int(received) == int(processed) + int(dropped) + int(waiting), text
    _, received, processed, dropped, waiting = (int(x) if x.isdigit() else x for x in lines[-1])
    assert (processed, dropped, waiting) == (received, 0, 0), lines[-1]
    # best-effort DDS may lose a message on a loaded machine before the node sees it (counted as
    # rejected.joints_lost where the middleware reports it): not a frame the node dropped
    assert played * 0.99 <= received <= played, (received, played)
    assert 'frames_dropped' not in text and 'Traceback' not in text
    assert not re.findall(r'^\[(WARN|ERROR|FATAL)\]', text, re.M), text  # a correct run: quiet


# ================================================================================ same name
def test_a_second_node_of_the_same_name_is_warned_about_by_both(harness, capfd):
    """Two hac_node in one domain with one name: each logs one warning naming the remedy and
    its /diagnostics says WARN duplicate_name while the other is there; when one leaves, the
    other says so. (The check runs every 0.5 s of steady time, so both warn within 2 s of the
    second appearing to DDS; the waits here are only upper bounds.)"""
    first = harness(stale_after_s=0.5)
    second = harness(stale_after_s=0.5)
    for h in (first, second):
        assert wait_for(lambda h=h: h.node.names.others == 1, PATIENCE_S)
        assert wait_for(lambda h=h: any(
            'duplicate_name' in {kv.key: kv.value for kv in m.status[0].values}['reasons']
            for _, m in list(h.received['/diagnostics'])), PATIENCE_S)
    log = NodeLog(capfd)
    assert log.wait_for(lambda t: t.count('another node named /hac_node is in the graph') == 2,
                        PATIENCE_S), log.text
    assert '-r __node:=NAME' in log.text
    second.close()
    assert wait_for(lambda: first.node.names.others == 0, PATIENCE_S)
    assert log.wait_for(lambda t: 'no other node named /hac_node in the graph' in t, PATIENCE_S)


def test_a_second_publisher_on_the_pose_topic_is_warned_about_while_it_is_there(harness,
                                                                                 capfd):
    """Two SLAMs on /slam/pose (two robots in one domain without namespaces): their poses would
    interleave. The node warns once naming both publishers, /diagnostics says WARN
    many_publishers while the second is there, and the log says when it left."""
    from test_node import INPUTS, RELIABLE, TYPES

    h = harness(stale_after_s=0.5)
    topic, msgtype = INPUTS['pose']
    other = rclpy.create_node('second_slam', context=h.context)
    try:
        other.create_publisher(TYPES.get(msgtype), topic.lstrip('/'), RELIABLE)
        assert wait_for(lambda: '/slam/pose' in h.node.graph.crowded, PATIENCE_S)
        assert sorted(h.node.graph.crowded['/slam/pose']) == ['/hac_test_io', '/second_slam']
        assert wait_for(lambda: any(
            'many_publishers' in {kv.key: kv.value for kv in m.status[0].values}['reasons']
            for _, m in list(h.received['/diagnostics'])), PATIENCE_S)
        log = NodeLog(capfd)
        assert log.wait_for(lambda t: '2 publishers on /slam/pose' in t and 'namespace' in t,
                            PATIENCE_S), log.text
    finally:
        other.destroy_node()
    assert wait_for(lambda: not h.node.graph.crowded, PATIENCE_S)
    assert log.wait_for(lambda t: 'one publisher on /slam/pose again' in t, PATIENCE_S), log.text


# ================================================================================ escaping
def test_strings_from_topics_reach_the_log_escaped(harness, capfd):
    """A frame id with ESC and BEL (clear the screen, ring) in a map and in the SLAM poses: the
    log writes them as \\x1b and \\x07, never the characters a terminal obeys."""
    from test_node import TYPES

    from msg_adapters import rt_to_pose_stamped, xyz_to_cloud

    hostile = 'map\x1b[2J\x07'
    h = harness()
    points = np.random.default_rng(0).uniform(-3, 3, (500, 3))
    h.publish(Event(NS, 'cloud', xyz_to_cloud(points, NS, hostile, TYPES)))
    for k in range(3):  # then poses in another frame: the map's frame is refused, and said
        h.publish(Event(NS + k, 'pose', rt_to_pose_stamped(np.eye(3), np.zeros(3), NS + k * NS,
                                                           'other\x1b]0;owned\x07', TYPES)))
    log = NodeLog(capfd)
    assert log.wait_for(lambda t: 'first map:' in t and 'cloud_wrong_frame' in t, PATIENCE_S), \
        log.text
    assert '\x1b' not in log.text and '\x07' not in log.text
    assert "frame 'map\\x1b[2J\\x07'" in log.text


def test_joints_without_a_slam_pose_say_at_info_that_the_node_waits_for_one(harness, capfd):
    """Joints come, no SLAM pose yet: once the joints' first-seen line is written, one INFO
    line says the node waits for the first pose on its topic; no warning says it."""
    walk = scenario_recording('walk', duration=6.0)
    h = harness()
    log = NodeLog(capfd)
    joints = [e for e in walk.events if e.kind == 'joints']

    def waiting() -> bool:
        h.publishers['joints'].publish(joints[len(log.text) % len(joints)].msg)
        return 'waiting for the first SLAM pose on /slam/pose' in log.read()
    assert wait_for(waiting, PATIENCE_S), log.text
    line = next(x for x in log.text.splitlines() if 'waiting for the first SLAM pose' in x)
    assert line.startswith('[INFO]') and log.text.count('waiting for the first SLAM pose') == 1


def test_after_a_slam_reset_the_log_tells_the_new_convergence(harness, capfd):
    """A SLAM re-initialisation (new map frame, new scale): the reset is logged once (at the
    core's level), and convergence is told again, timed from the first joints after the reset."""
    reset = scenario_recording('reset', duration=12.0)
    h = harness(log_period_s=0.0)
    h.play(reset.events, frame_period_s=0.01)
    log = NodeLog(capfd)
    assert log.wait_for(lambda t: len(CONVERGED.findall(t)) >= 2, PATIENCE_S), log.text
    assert 'after the first joints since the reset' in log.text.split('estimator reset')[-1]
    assert h.node.notices['reset'] == 1 and log.text.count('estimator reset (') == 1


def test_the_documented_log_lines_are_in_the_logs_format():
    """docs/node.md's example log (a real run, pasted) and README's quoted convergence line are
    in the format the log writes today (the regular expressions above read the real log)."""
    doc = (REPO / 'docs' / 'node.md').read_text()
    block = doc[doc.index('## The log'):].split('```')[1]
    assert len(CONVERGED.findall(block)) == 1, block
    assert FRAMES.findall(block) and LEVEL_CHANGE.findall(block), block
    for _, received, processed, dropped, waiting in FRAMES.findall(block):
        assert int(received) == int(processed) + int(dropped) + int(waiting)
    quoted = re.search(r'`(converged: scale [^`]*)`', (REPO / 'README.md').read_text())
    assert quoted and CONVERGED.search(f'[INFO] [hac_node]: {quoted.group(1)}'), quoted
