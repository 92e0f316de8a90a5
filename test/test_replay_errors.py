"""``hac replay``'s errors and interruption: an existing output or one inside the input, missing
or renamed topics, a wrong message type, missing, empty and corrupt recordings, an invalid
parameter: each one line, exit 2, nothing written; malformed messages counted as the node counts
them; Ctrl-C leaves no output and never touches the input."""
from __future__ import annotations

import hashlib
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from scenes import walking_scene
from test_replay import (  # noqa: F401 (walk_bag: a fixture)
    REPO,
    _assert_clean_error,
    hac,
    walk_bag,
    write_recording,
)

from hac_ros.core.basics.errors import ArgumentError, HacError
from hac_ros.replay.replayer import replay


# ============================================================================ errors
def tree_digest(path: Path) -> str:
    """A digest of every file (name, size, bytes) under ``path``: IN must never change."""
    h = hashlib.sha256()
    for f in sorted(p for p in path.rglob('*') if p.is_file()):
        h.update(str(f.relative_to(path)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def test_existing_output_is_an_error_and_is_left_alone(walk_bag, tmp_path):
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'keep.txt').write_text('mine')
    _assert_clean_error(hac('replay', str(walk_bag), '-o', str(out)), 'already exists')
    assert (out / 'keep.txt').read_text() == 'mine'
    with pytest.raises(HacError, match='already exists'):
        replay(walk_bag, out)


def test_missing_input_topic_names_what_the_recording_contains(tmp_path):
    source = write_recording(tmp_path / 'nocloud', walking_scene(frames=20), skip=('cloud',))
    _assert_clean_error(hac('replay', str(source), '-o', str(tmp_path / 'out')),
                        '/slam/cloud', 'is not in', '(use --cloud-topic)',
                        '/slam/pose (geometry_msgs/msg/PoseStamped, 20)', '/hmr/joints')
    assert not (tmp_path / 'out').exists()


def test_renamed_topics_are_found_with_flags(tmp_path):
    source = write_recording(tmp_path / 'renamed', walking_scene(frames=30),
                             topics={'joints': '/vimo/joints'})
    _assert_clean_error(hac('replay', str(source), '-o', str(tmp_path / 'a')), '/hmr/joints',
                        '/vimo/joints', '(use --joints-topic)')
    with pytest.raises(ArgumentError, match=r'/hmr/joints is not in .* \(use joints_topic\)'):
        replay(source, tmp_path / 'a')
    result = hac('replay', str(source), '-o', str(tmp_path / 'b'), '--joints-topic', '/vimo/joints')
    assert result.returncode == 0, result.stderr


def test_every_missing_input_topic_names_its_flag(tmp_path):
    scene = walking_scene(frames=20)
    for kind, flag in (('pose', '--pose-topic'), ('joints', '--joints-topic'),
                       ('cloud', '--cloud-topic')):
        source = write_recording(tmp_path / kind, scene, topics={kind: f'/elsewhere/{kind}'})
        _assert_clean_error(hac('replay', str(source), '-o', str(tmp_path / f'{kind}_out')),
                            'is not in', f'(use {flag})', f'/elsewhere/{kind}')


def test_wrong_message_type_is_an_error(walk_bag, tmp_path):
    _assert_clean_error(hac('replay', str(walk_bag), '-o', str(tmp_path / 'out'), '--joints-topic',
                            '/slam/pose'),
                        '/slam/pose', 'geometry_msgs/msg/PoseStamped',
                        'expected geometry_msgs/msg/PoseArray')


def test_missing_input_path_is_an_error(tmp_path):
    _assert_clean_error(hac('replay', str(tmp_path / 'nothing'), '-o', str(tmp_path / 'out')),
                        'does not exist')


def test_empty_recording_is_an_error(tmp_path):
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS2_JAZZY)
    writer = Writer(tmp_path / 'empty', version=9)
    writer.open()
    for topic, msgtype in (('/slam/pose', 'geometry_msgs/msg/PoseStamped'),
                           ('/hmr/joints', 'geometry_msgs/msg/PoseArray'),
                           ('/slam/cloud', 'sensor_msgs/msg/PointCloud2')):
        writer.add_connection(topic, msgtype, typestore=typestore)
    writer.close()
    _assert_clean_error(hac('replay', str(tmp_path / 'empty'), '-o', str(tmp_path / 'out')),
                        'no messages')


def test_corrupt_recordings_are_errors(walk_bag, tmp_path):
    # not a recording at all
    junk = tmp_path / 'junk.mcap'
    junk.write_bytes(b'this is not an mcap file' * 10)
    _assert_clean_error(hac('replay', str(junk), '-o', str(tmp_path / 'a')), 'junk.mcap')
    # a recording directory whose storage file was truncated half-way
    broken = tmp_path / 'broken'
    broken.mkdir()
    for f in walk_bag.iterdir():
        data = f.read_bytes()
        (broken / f.name).write_bytes(data[:len(data) // 2] if f.suffix == '.mcap' else data)
    _assert_clean_error(hac('replay', str(broken), '-o', str(tmp_path / 'b')), 'broken')
    assert not (tmp_path / 'a').exists() and not (tmp_path / 'b').exists()
    assert not list(tmp_path.glob('.*partial'))


def _with_messages_broken(source: Path, target: Path, broken: dict[int, Callable[[bytes], bytes]],
                          topic: str = '/slam/cloud') -> Path:
    """A copy of ``source`` whose k-th message of ``topic`` has the bytes ``broken[k](bytes)``."""
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    writer = Writer(target, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    count = 0
    with Reader(source) as reader:
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=None,
                                             msgdef=c.msgdef.data, rihs01=c.digest)
                 for c in reader.connections}
        for conn, log_ns, raw in reader.messages():
            if conn.topic == topic:
                raw = broken.get(count, bytes)(bytes(raw))
                count += 1
            writer.write(conns[conn.id], log_ns, bytes(raw))
    writer.close()
    return target


@pytest.mark.parametrize('mode', ['online', 'offline'])
def test_a_malformed_map_cloud_is_a_counted_rejection_as_in_the_node(tmp_path, mode):
    """A cloud whose points do not decode (its width says one point more than its data holds)
    and one whose header does not (cut inside its frame_id) are rejected as ``cloud_malformed``,
    at their place in the order, and the replay goes on with the map before them (hac_node counts
    the same bytes the same way)."""
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS2_JAZZY)
    cloud_type = 'sensor_msgs/msg/PointCloud2'

    def one_point_short(data: bytes) -> bytes:
        msg = typestore.deserialize_cdr(data, cloud_type)
        msg.width += 1
        msg.row_step += msg.point_step
        return bytes(typestore.serialize_cdr(msg, cloud_type))

    source = write_recording(tmp_path / 'rec', walking_scene(frames=80), cloud_every=20)
    bad = _with_messages_broken(source, tmp_path / 'bad', {1: one_point_short, 2: lambda b: b[:14]})
    good = replay(source, tmp_path / 'good', mode=mode)
    summary = replay(bad, tmp_path / 'out', mode=mode)
    assert summary.status.rejected.get('cloud_malformed') == 2
    assert good.status.rejected.get('cloud_malformed') is None
    assert summary.status.frames == good.status.frames == 80
    # the floor is the same in every cloud: the map before the broken ones serves as well
    assert summary.status.scale == pytest.approx(good.status.scale, rel=1e-9)


@pytest.mark.parametrize('mode', ['online', 'offline'])
def test_pose_and_joints_bytes_that_do_not_deserialize_are_counted_rejections(tmp_path, mode):
    """A SLAM pose and a joints message truncated inside their header are rejected as
    ``pose_nonfinite`` and ``joints_malformed`` at their place (hac_node counts the same bytes the
    same way); the replay goes on, and the frame whose pose is gone is interpolated."""
    source = write_recording(tmp_path / 'rec', walking_scene(frames=80))
    poses_cut = _with_messages_broken(source, tmp_path / 'p', {30: lambda b: b[:10]}, '/slam/pose')
    bad = _with_messages_broken(poses_cut, tmp_path / 'bad', {40: lambda b: b[:10]}, '/hmr/joints')
    summary = replay(bad, tmp_path / 'out', mode=mode)
    assert summary.status.rejected.get('pose_nonfinite') == 1
    assert summary.status.rejected.get('joints_malformed') == 1
    assert summary.status.frames == 79


def test_invalid_parameter_is_an_error(walk_bag, tmp_path):
    params_file = tmp_path / 'hac.yaml'
    params_file.write_text('hac_node:\n  ros__parameters:\n    window_s: -3.0\n')
    _assert_clean_error(hac('replay', str(walk_bag), '-o', str(tmp_path / 'out'), '--params',
                            str(params_file)), 'window_s')


@pytest.mark.slow
def test_ctrl_c_leaves_no_output_and_never_touches_the_input(tmp_path):
    source = write_recording(tmp_path / 'long', walking_scene(frames=3000, rate=30.0),
                             cloud_every=30)
    before = tree_digest(source)
    results = tmp_path / 'results'  # OUT's parent does not exist yet: the replay makes it
    out = results / 'out'
    proc = subprocess.Popen([sys.executable, '-m', 'hac_ros.cli', 'replay', str(source), '-o',
                             str(out)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    deadline = time.monotonic() + 600.0
    while not list(results.glob('.out.*partial')):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.005)
    # held inside the replay (it cannot finish meanwhile, however loaded the machine), then
    # Ctrl-C, then let go
    proc.send_signal(signal.SIGSTOP)
    assert list(results.glob('.out.*partial')), 'the replay finished before it could be stopped'
    proc.send_signal(signal.SIGINT)
    proc.send_signal(signal.SIGCONT)
    _stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    assert 'Traceback' not in stderr
    assert not out.exists()
    assert not results.exists()  # nor the temporary directory, nor the parent it made
    assert tree_digest(source) == before


def test_output_inside_the_input_is_refused(walk_bag):
    _assert_clean_error(hac('replay', str(walk_bag), '-o', str(walk_bag / 'out')), 'inside')
