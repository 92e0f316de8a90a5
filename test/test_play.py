"""``hac play``: a recording's input topics over real DDS (localhost, this process's domain).

A simulated recording is played by :class:`hac_ros.ros.player.Player` (in-process) or by the
``hac play`` command (a subprocess), and received by a subscriber node in this process: every
message arrives, in the recording's order, byte for byte, on the topics and with the QoS asked
for. Driving the node with it is tested in test_node_process.py and by ``hac demo --live``.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip('rclpy')

from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosbags.typesys import Stores, get_typestore

from hac_ros.core.basics.errors import HacError, ParameterError
from hac_ros.recording.reader import Recording
from hac_ros.replay.feeder import tie_ordered
from hac_ros.ros.player import DEFAULT_TOPICS, KIND_OF_TYPE, Player
from hac_ros.ros.spin_thread import SpinThread
from msg_adapters import rclpy_types, stamp_to_ns

REPO = Path(__file__).resolve().parents[1]
TYPES = rclpy_types()
JAZZY = get_typestore(Stores.ROS2_JAZZY)
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
INPUTS = {'/slam/pose': 'geometry_msgs/msg/PoseStamped', '/slam/cloud': 'sensor_msgs/msg/PointCloud2',
          '/hmr/joints': 'geometry_msgs/msg/PoseArray',
          '/camera/camera_info': 'sensor_msgs/msg/CameraInfo'}
WAIT_S = 60.0  # at most (waiting returns once it has happened)


@pytest.fixture(scope='module')
def walk_bag(tmp_path_factory) -> Path:
    from hac_ros.simulate import make_scenario, write_recording

    path = tmp_path_factory.mktemp('play') / 'walk'
    return write_recording(make_scenario('walk', seed=2, duration=3.0), path)


def wait_for(predicate: Any, timeout: float = WAIT_S) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


class Listener:
    """A subscriber node (its own context, spun on a thread) recording what arrives per topic."""

    def __init__(self, topics: dict[str, str], qos: QoSProfile = RELIABLE) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('play_listener', context=self.context)
        self.received: dict[str, list[Any]] = {t: [] for t in topics}
        for topic, msgtype in topics.items():
            self.subscribe(topic, msgtype, qos)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.spinner = SpinThread(self.executor)

    def subscribe(self, topic: str, msgtype: str, qos: QoSProfile) -> None:
        self.received.setdefault(topic, [])
        self.node.create_subscription(TYPES.get(msgtype), topic,
                                      lambda m, t=topic: self.received[t].append(m), qos)

    def close(self) -> None:
        self.spinner.close()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


@pytest.fixture
def player_context():
    context = Context()
    rclpy.init(context=context)
    yield context
    rclpy.shutdown(context=context)


def canonical(cdr: bytes, msgtype: str) -> bytes:
    """A message's CDR with zero padding (Fast CDR leaves its alignment padding unset)."""
    return bytes(JAZZY.serialize_cdr(JAZZY.deserialize_cdr(bytes(cdr), msgtype), msgtype))


def recorded(path: Path, topics: list[str]) -> list[tuple[str, int, bytes]]:
    """The messages of ``topics`` in the order the player sends them."""
    with Recording(path) as rec:
        kinds = {t: KIND_OF_TYPE.get(rec.topics[t] or '', '') for t in topics}
        return [(t, log_ns, bytes(raw)) for t, log_ns, raw in tie_ordered(rec.messages(topics),
                                                                           kinds)]


def test_every_input_message_arrives_in_order_byte_for_byte_and_the_map_is_latched(
        walk_bag, player_context):
    listener = Listener(INPUTS)
    try:
        with Player(walk_bag, rate=20.0, wait_s=WAIT_S, context=player_context) as player:
            assert [t.name for t in player.plan] == [t for t in DEFAULT_TOPICS if t in INPUTS]
            assert {t.name: t.latched for t in player.plan}['/slam/cloud']
            stats = player.run()
            expected = recorded(walk_bag, list(INPUTS))
            assert stats.total == len(expected) and not stats.stopped and stats.loops == 1
            assert wait_for(lambda: sum(map(len, listener.received.values())) == len(expected))
            for topic, msgtype in INPUTS.items():
                got = [canonical(serialize_message(m), msgtype) for m in listener.received[topic]]
                assert got == [canonical(raw, msgtype) for t, _, raw in expected if t == topic], \
                    topic
            # a subscriber that comes after the play still gets the last map (transient local)
            listener.subscribe('/slam/cloud', INPUTS['/slam/cloud'], LATCHED)
            late = listener.received['/slam/cloud']
            before = len(late)
            assert wait_for(lambda: len(late) > before)
            last_map = [raw for t, _, raw in expected if t == '/slam/cloud'][-1]
            assert canonical(serialize_message(late[-1]), INPUTS['/slam/cloud']) == \
                canonical(last_map, INPUTS['/slam/cloud'])
        # the ground truth is not an input: never played by default
        assert not any(t.startswith('/gt/') for t in stats.published)
    finally:
        listener.close()


def test_topics_remap_and_clock(walk_bag, player_context):
    listener = Listener({'/robot/pose': INPUTS['/slam/pose'],
                         '/clock': 'rosgraph_msgs/msg/Clock'})
    try:
        with Player(walk_bag, rate=10.0, clock_hz=50.0, topics=['/slam/pose'],
                    remap={'/slam/pose': '/robot/pose'}, wait_s=WAIT_S,
                    context=player_context) as player:
            # the player waits for its topics' subscribers, not /clock's: wait here, so that no
            # /clock message goes out before the listener has matched (a busy machine's race)
            assert wait_for(lambda: player.node.count_subscribers('/clock') > 0)
            stats = player.run()
        poses = [log_ns for t, log_ns, _ in recorded(walk_bag, ['/slam/pose'])]
        assert dict(stats.published) == {'/robot/pose': len(poses)}
        assert wait_for(lambda: len(listener.received['/robot/pose']) == len(poses))
        assert [stamp_to_ns(m.header.stamp) for m in listener.received['/robot/pose']] == poses
        # one before each message, more in between
        assert wait_for(lambda: len(listener.received['/clock']) >= len(poses))
        clock = [stamp_to_ns(m.clock) for m in listener.received['/clock']]
        assert clock == sorted(clock) and poses[0] <= clock[0] and clock[-1] <= poses[-1]
    finally:
        listener.close()


def test_loop_plays_again_until_stopped(walk_bag, player_context):
    listener = Listener({'/slam/pose': INPUTS['/slam/pose']})
    stop = threading.Event()
    poses = len(recorded(walk_bag, ['/slam/pose']))
    try:
        with Player(walk_bag, rate=50.0, loop=True, topics=['/slam/pose'], wait_s=WAIT_S,
                    context=player_context) as player:
            watcher = threading.Thread(target=lambda: wait_for(
                lambda: len(listener.received['/slam/pose']) > 2 * poses) and stop.set())
            watcher.start()
            stats = player.run(stop)
            watcher.join()
        assert stats.stopped and stats.loops >= 3
        stamps = [stamp_to_ns(m.header.stamp) for m in listener.received['/slam/pose']]
        assert stamps[poses:2 * poses] == stamps[:poses]  # the second loop repeats the first
    finally:
        listener.close()


@pytest.mark.slow
def test_rate_sets_the_pace(walk_bag, player_context):
    """3 s of recording at 2x take at least 1.5 s (never sooner: each message waits for its
    time); the upper bound is generous (a loaded machine)."""
    with Player(walk_bag, rate=2.0, topics=['/slam/pose'], context=player_context) as player:
        stats = player.run()
    assert 1.45 <= stats.wall_s < 30.0


def test_bad_arguments_are_errors_naming_them(walk_bag, player_context, tmp_path):
    with pytest.raises(ParameterError, match='rate'):
        Player(walk_bag, rate=0.0, context=player_context)
    with pytest.raises(HacError, match='does not exist'):
        Player(tmp_path / 'nothing', context=player_context)
    with pytest.raises(HacError, match=r'topics: /nope not in .*/slam/pose'):
        Player(walk_bag, topics=['/nope'], context=player_context)
    with pytest.raises(HacError, match=r'remap: /gt/scale is not a topic played'):
        Player(walk_bag, remap={'/gt/scale': '/x'}, context=player_context)


def hac(*args: str, **kwargs: Any) -> subprocess.Popen:
    env = {**os.environ, 'PYTHONUNBUFFERED': '1'}
    return subprocess.Popen([sys.executable, '-m', 'hac_ros.cli', *args], cwd=REPO, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs)


@pytest.mark.parametrize('args, needle', [
    (['--rate', '0'], '--rate 0.0: must be > 0'),
    (['--remap', '/slam/pose'], "--remap '/slam/pose': expected OLD:=NEW"),
    (['--topics', '/nope'], '--topics: /nope not in'),
    (['--remap', '/gt/scale:=/x'], '--remap: /gt/scale is not a topic played'),
])
def test_command_line_errors_are_one_line_and_exit_2(walk_bag, args, needle):
    process = hac('play', str(walk_bag), *args)
    out, err = process.communicate(timeout=60)
    assert process.returncode == 2, out + err
    assert needle in err and 'Traceback' not in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.slow
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_a_signal_stops_the_play_cleanly(walk_bag, sig):
    process = hac('play', str(walk_bag), '--loop')
    try:
        first = process.stdout.readline()
        assert first.startswith('hac play: '), first + process.stderr.read()
        time.sleep(0.5)  # playing
        process.send_signal(sig)
        out, err = process.communicate(timeout=20)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 128 + sig, out + err
    assert f'interrupted ({signal.Signals(sig).name})' in err and 'Traceback' not in err, err
    assert len(err.strip().splitlines()) == 1, err


@pytest.mark.slow
def test_demo_live_gives_the_online_replays_final_scale(tmp_path):
    """``hac demo --live``: hac_node (a process) fed bags/demo_walk by hac play at real time (at
    4x a loaded machine could not keep up: the node dropped frames, as it should, and the test
    depended on the machine's speed); the final scale it prints equals ``hac replay --mode
    online``'s within 0.5 % (the node uses a new map from the first frame after it is indexed,
    the replay at its stamp)."""
    import re

    from hac_ros.replay.replayer import replay

    source = REPO / 'bags' / 'demo_walk'
    online = replay(source, tmp_path / 'online', mode='online')
    process = hac('demo', '--live', '--rate', '1')
    out, err = process.communicate(timeout=300)
    assert process.returncode == 0, out + err
    found = re.search(r'final scale ([0-9.eE+-]+) m/SLAM unit', out)
    assert found, out
    live = float(found.group(1))
    assert abs(live / online.status.scale - 1.0) < 0.005, (live, online.status.scale, out)
    frames = int(re.search(r'frames (\d+)', out).group(1))
    # /diagnostics is at most one stamp second behind, and on a loaded machine the node's
    # best-effort input may lose a few frames (counted in /diagnostics as joints_lost) and the
    # node drops the oldest frames when it falls behind (frames_dropped)
    dropped = re.search(r'frames_dropped (\d+)', out)
    frames += int(dropped.group(1)) if dropped else 0
    assert frames >= 0.85 * online.status.frames, out
    assert 'converged' in out and 'hac_node over DDS' in out
    # what the statuses said, counted from what came back as the replay counts what it wrote:
    # about as many, and no reason of the core's that the replay's statuses did not give (the
    # node adds its own: dropped or lost frames, latency)
    from hac_ros.core.rules.reasons import NODE, REASONS

    said = re.search(r'statuses \((\d+) /diagnostics, one per second\): (.*)', out)
    assert said and abs(int(said.group(1)) - online.statuses.total) <= 2, out
    reasons = set(re.findall(r'([a-z_]+) [<>]?\d+ %', said.group(2)))
    node_only = {r for r in reasons if r == 'frames_dropped' or r.endswith('_lost')
                 or REASONS[r].kind == NODE}
    assert 'not_converged' in reasons and reasons - node_only <= set(online.statuses.reasons), out
    # the counts are the last stamp-time status's, within the 20 s recording (not a status the
    # node republished on its steady clock after the play ended, stamped with its clock)
    as_of = re.search(r'counts as of t\+([0-9.]+) s', out)
    assert as_of and 18.0 <= float(as_of.group(1)) <= 20.5, out
