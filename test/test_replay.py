"""``hac replay``: storage round trips and modes (sqlite3 and mcap in and out, a ROS 1 bag in,
online and offline, the parameters, the summary, the progress bar, the notices).

Recordings are written here from the constructed scenes of ``scenes.py`` (known answers), so these
tests need neither the simulator nor ROS. The writer and helpers here are shared: errors and
interruption are in test_replay_errors.py, the offline estimate and the modes' accuracy in
test_replay_offline.py.
"""
from __future__ import annotations

import contextlib
import fcntl
import logging
import os
import pty
import struct
import subprocess
import sys
import termios
from collections.abc import Callable, Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from scenes import NS, QUICK_CONVERGENCE, Scene, walking_scene

from hac_ros.bridge.topics import TOPICS
from hac_ros.core.basics.errors import ArgumentError
from hac_ros.core.rules.params import HacParams
from hac_ros.replay.replayer import replay

REPO = Path(__file__).resolve().parents[1]
K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
# what a replay with the default parameters writes (hac_ros.bridge.topics)
OUTPUT_TOPICS = tuple(t.rooted for t in TOPICS if t.replay and t.enabled(HacParams()))


# ============================================================================ recordings
def write_recording(path: Path, scene: Scene, storage: str = 'mcap', *, cloud_every: int = 0,
                    camera_info: bool = True, gt: bool = True, pose_type: str = 'PoseStamped',
                    topics: dict[str, str] | None = None, skip: tuple[str, ...] = (),
                    slam_noise: float = 0.0, seed: int = 0,
                    scale_of: Callable[[int], float] | None = None) -> Path:
    """A rosbag2 recording of ``scene``: SPEC's input topics (and ground truth), logged at stamps.

    The map (the scene's floor points, SLAM units) is published at the first stamp and again every
    ``cloud_every`` frames (0: once). ``topics`` renames input topics; ``skip`` leaves kinds out;
    ``slam_noise`` adds Gaussian noise of that many metres (in SLAM units) to the SLAM centres.
    ``scale_of(t)`` makes the SLAM scale of frame t change over time (a drifting monocular SLAM,
    locally consistent: the pose and the map republished at t share the scale of t; /gt/scale
    follows it).
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from msg_adapters import (
        intrinsics_to_camera_info,
        joints_to_pose_array,
        rosbags_types,
        rt_to_odometry,
        rt_to_pose_stamped,
        xyz_to_cloud,
    )

    typestore = get_typestore(Stores.ROS2_JAZZY)
    types = rosbags_types()
    names = {'pose': '/slam/pose', 'joints': '/hmr/joints', 'cloud': '/slam/cloud',
             'camera_info': '/camera/camera_info', **(topics or {})}
    pose_msgtype = 'nav_msgs/msg/Odometry' if pose_type == 'Odometry' else 'geometry_msgs/msg/PoseStamped'
    kinds = {'pose': pose_msgtype, 'joints': 'geometry_msgs/msg/PoseArray',
             'cloud': 'sensor_msgs/msg/PointCloud2', 'camera_info': 'sensor_msgs/msg/CameraInfo'}
    plugin = StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3
    writer = Writer(path, version=9, storage_plugin=plugin)
    writer.open()
    conns = {kind: writer.add_connection(names[kind], msgtype, typestore=typestore)
             for kind, msgtype in kinds.items() if kind not in skip and
             (kind != 'camera_info' or camera_info)}
    if gt:
        conns['gt_camera'] = writer.add_connection('/gt/camera_pose', 'geometry_msgs/msg/PoseStamped',
                                                   typestore=typestore)
        conns['gt_joints'] = writer.add_connection('/gt/human_joints', 'geometry_msgs/msg/PoseArray',
                                                   typestore=typestore)
        conns['gt_scale'] = writer.add_connection('/gt/scale', 'std_msgs/msg/Float64',
                                                  typestore=typestore)

    def put(kind: str, stamp: int, msg, msgtype: str) -> None:
        if kind in conns:
            writer.write(conns[kind], stamp, typestore.serialize_cdr(msg, msgtype))

    scales = np.array([scene.true_scale if scale_of is None else scale_of(t)
                       for t in range(len(scene.stamps_ns))])
    floor = scene.floor_points_slam() * scene.true_scale  # metres, in the SLAM map's axes
    R, J = scene.R_wc_slam, scene.joints_cam
    c = scene.c_slam * scene.true_scale / scales[:, None]
    if slam_noise:
        rng = np.random.default_rng(seed)
        c = c + rng.normal(0.0, 1.0, c.shape) * (slam_noise / scales)[:, None]
    for t, stamp in enumerate(scene.stamps_ns.tolist()):
        if t == 0 or (cloud_every and t % cloud_every == 0):
            put('cloud', stamp, xyz_to_cloud(floor / scales[t], stamp, 'map', types),
                kinds['cloud'])
        if t == 0:
            put('camera_info', stamp, intrinsics_to_camera_info(K, 640, 480, stamp, 'camera', types),
                kinds['camera_info'])
        if t == 0 or scales[t] != scales[t - 1]:
            put('gt_scale', stamp, typestore.types['std_msgs/msg/Float64'](data=float(scales[t])),
                'std_msgs/msg/Float64')
        if pose_type == 'Odometry':
            pose = rt_to_odometry(R[t], c[t], stamp, 'map', 'camera', types)
        else:
            pose = rt_to_pose_stamped(R[t], c[t], stamp, 'map', types)
        put('pose', stamp, pose, pose_msgtype)
        put('joints', stamp, joints_to_pose_array(J[t], stamp, 'camera', types), kinds['joints'])
        put('gt_camera', stamp, rt_to_pose_stamped(scene.R_wc_world[t], scene.c_world[t], stamp,
                                                   'world', types), 'geometry_msgs/msg/PoseStamped')
        put('gt_joints', stamp, joints_to_pose_array(scene.joints_world[t], stamp, 'world', types),
            'geometry_msgs/msg/PoseArray')
    writer.close()
    return path


def read_all(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    """topic -> [(log time, CDR bytes)] sorted by log time (then bytes, for ties)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    out: dict[str, list[tuple[int, bytes]]] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, log_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((log_ns, bytes(raw)))
    return {topic: sorted(items) for topic, items in out.items()}


def hac(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
    """Run the ``hac`` command line in a subprocess (as a user would)."""
    return subprocess.run([sys.executable, '-m', 'hac_ros.cli', *args], cwd=REPO, text=True,
                          capture_output=True, timeout=timeout)


def _assert_clean_error(result: subprocess.CompletedProcess, *needles: str) -> None:
    assert result.returncode == 2, (result.returncode, result.stderr)
    assert 'Traceback' not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.startswith('hac replay: error:')]
    assert len(lines) == 1, result.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


@pytest.fixture(scope='module')
def walk_bag(tmp_path_factory) -> Path:
    """8 s at 10 Hz of the walking scene, mcap, with CameraInfo and ground truth."""
    return write_recording(tmp_path_factory.mktemp('rec') / 'walk', walking_scene(frames=80))


# ============================================================================ round trips and modes
@pytest.mark.parametrize('mode', ['online', 'offline'])
def test_sqlite3_and_mcap_give_identical_outputs(tmp_path, mode):
    scene = walking_scene(frames=60)
    outputs = {}
    for storage_in in ('sqlite3', 'mcap'):
        source = write_recording(tmp_path / f'in_{storage_in}', scene, storage_in)
        for storage_out in ('sqlite3', 'mcap'):
            out = tmp_path / f'out_{storage_in}_{storage_out}'
            replay(source, out, mode=mode, storage=storage_out)
            outputs[storage_in, storage_out] = read_all(out)
    reference = outputs['mcap', 'mcap']
    assert set(reference) == set(OUTPUT_TOPICS)
    assert len(reference['/hac/odometry']) > 30
    for key, topics in outputs.items():
        assert topics == reference, key


def test_online_replay_logs_each_output_at_its_header_stamp(walk_bag, tmp_path):
    from rosbags.highlevel import AnyReader

    out = tmp_path / 'out'
    params = HacParams(converged_max_rel_sigma=QUICK_CONVERGENCE)  # converged at min_samples
    summary = replay(walk_bag, out, params, mode='online')
    seen = {t: 0 for t in OUTPUT_TOPICS}
    with AnyReader([out]) as reader:
        for conn, log_ns, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            seen[conn.topic] += 1
            if hasattr(msg, 'header'):
                stamp = msg.header.stamp.sec * NS + msg.header.stamp.nanosec
                assert stamp == log_ns, conn.topic
            if conn.topic == '/hac/odometry':
                assert msg.header.frame_id == params.odom_frame
                assert msg.child_frame_id == 'camera'
            if conn.topic in ('/hac/pose', '/hac/cloud', '/hac/human_joints'):
                assert msg.header.frame_id == params.metric_frame
    input_stamps = set(walking_scene(frames=80).stamps_ns.tolist())
    assert seen['/hac/odometry'] > 0 and seen['/hac/scale'] == seen['/hac/human_joints']
    # online: nothing metric before min_samples frames; diagnostics once per second of stamps
    assert seen['/hac/odometry'] == 80 - params.min_samples
    assert seen['/diagnostics'] == 8
    assert summary.status.frames == 80 and summary.frames_per_s > 0
    with AnyReader([out]) as reader:
        logged = {t for c, t, _ in reader.messages() if c.topic != '/diagnostics'}
    assert logged <= input_stamps


def test_offline_publishes_every_frame_with_one_scale(walk_bag, tmp_path):
    from rosbags.highlevel import AnyReader

    summary = replay(walk_bag, tmp_path / 'out')
    assert summary.mode == 'offline' and summary.offline is not None
    scales = []
    with AnyReader([tmp_path / 'out']) as reader:
        for conn, _, raw in reader.messages([c for c in reader.connections
                                             if c.topic in ('/hac/scale', '/hac/odometry')]):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == '/hac/scale':
                scales.append(msg.data)
    assert len(scales) == 80  # every frame, from the first one
    assert len(set(scales)) == 1
    assert scales[0] == pytest.approx(summary.offline.segments[0].median)
    assert scales[0] == pytest.approx(2.5, rel=0.02)  # the scene's true scale


def test_params_file_is_read_and_flags_override_it(walk_bag, tmp_path):
    params_file = tmp_path / 'hac.yaml'
    params_file.write_text('hac_node:\n  ros__parameters:\n    pose_topic: /elsewhere\n'
                           '    min_samples: 25\n    metric_frame: map_metric2\n'
                           '    odom_frame: odom_metric\n')
    bad = hac('replay', str(walk_bag), '-o', str(tmp_path / 'a'), '--params', str(params_file))
    assert bad.returncode == 2 and '/elsewhere' in bad.stderr
    good = hac('replay', str(walk_bag), '-o', str(tmp_path / 'b'), '--params', str(params_file),
               '--pose-topic', '/slam/pose', '--mode', 'online')
    assert good.returncode == 0, good.stderr
    topics = read_all(tmp_path / 'b')
    assert len(topics['/hac/odometry']) == 80 - 25  # min_samples from the file
    assert b'odom_metric' in topics['/hac/odometry'][0][1]
    assert b'map_metric2' in topics['/hac/pose'][0][1]


def test_copy_inputs_carries_every_input_topic_unchanged(walk_bag, tmp_path):
    replay(walk_bag, tmp_path / 'out', mode='online', copy_inputs=True)
    source, copied = read_all(walk_bag), read_all(tmp_path / 'out')
    for topic, items in source.items():
        assert copied[topic] == items, topic
    assert set(OUTPUT_TOPICS) <= set(copied)


def test_a_ros1_bag_gives_the_same_outputs(walk_bag, tmp_path):
    from rosbags.convert import convert
    from rosbags.typesys import Stores, get_typestore

    ros1 = tmp_path / 'walk.bag'
    convert([walk_bag], ros1, dst_storage='', dst_version=None, compress=None, compress_mode='',
            default_typestore=get_typestore(Stores.ROS2_JAZZY),
            typestore=get_typestore(Stores.ROS1_NOETIC), exclude_topics=[], include_topics=[],
            exclude_msgtypes=[], include_msgtypes=[])
    replay(ros1, tmp_path / 'from_ros1', mode='online', copy_inputs=True)
    replay(walk_bag, tmp_path / 'from_ros2', mode='online')
    from_ros1, from_ros2 = read_all(tmp_path / 'from_ros1'), read_all(tmp_path / 'from_ros2')
    for topic in OUTPUT_TOPICS:  # CameraInfo (K -> k) and headers (seq) are converted too
        assert from_ros1[topic] == from_ros2[topic], topic
    for topic, items in read_all(walk_bag).items():  # copied inputs become ROS 2 Jazzy messages
        assert from_ros1[topic] == items, topic


def test_odometry_pose_type_is_read_from_the_recording(tmp_path):
    source = write_recording(tmp_path / 'odom', walking_scene(frames=40), pose_type='Odometry')
    found = hac('replay', str(source), '-o', str(tmp_path / 'a'))
    assert found.returncode == 0, found.stderr
    assert 'frames 40' in found.stdout
    right = hac('replay', str(source), '-o', str(tmp_path / 'b'), '--pose-type', 'Odometry')
    assert right.returncode == 0, right.stderr
    assert read_all(tmp_path / 'a') == read_all(tmp_path / 'b')


def test_pose_type_read_from_the_recording_and_a_wrong_override_is_an_error(tmp_path):
    scene = walking_scene(frames=40)
    odometry = write_recording(tmp_path / 'odom', scene, pose_type='Odometry')
    pose = write_recording(tmp_path / 'pose', scene, pose_type='PoseStamped')
    # the parameters' pose_type (the node's, e.g. config/hac.yaml) does not stop a mixed set
    for source in (odometry, pose):
        for node_type in ('PoseStamped', 'Odometry'):
            summary = replay(source, tmp_path / f'{source.name}_{node_type}',
                             HacParams(pose_type=node_type))
            assert summary.status.frames == 40
    with pytest.raises(ArgumentError, match=r'nav_msgs/msg/Odometry.* \(use pose_type Odometry'):
        replay(odometry, tmp_path / 'wrong', pose_type='PoseStamped')
    with pytest.raises(ArgumentError, match=r' \(use pose_type PoseStamped, or no pose_type'):
        replay(pose, tmp_path / 'wrong', pose_type='Odometry')
    _assert_clean_error(hac('replay', str(pose), '-o', str(tmp_path / 'wrong'), '--pose-type',
                            'Odometry'),
                        '(use --pose-type PoseStamped, or no --pose-type: it is read from the '
                        'recording)')
    assert not (tmp_path / 'wrong').exists()


def test_summary_names_frames_scale_fallback_rejections_resets_and_speed(walk_bag, tmp_path):
    result = hac('replay', str(walk_bag), '-o', str(tmp_path / 'out'))
    assert result.returncode == 0, result.stderr
    for text in ('frames 80', 'people 80', 'final scale', 'fallback rate', 'rejected:', 'resets 0',
                 'frames/s', 'segment 0'):
        assert text in result.stdout, text
    assert 'Traceback' not in result.stderr
    assert '\r' not in result.stderr  # no progress bar when stderr is not a terminal


def test_the_library_draws_no_bar_it_advances_the_display_it_is_given(walk_bag, tmp_path):
    """Progress is the caller's: replay() advances a given display pass by pass to its total
    (offline: estimate, then write; online: one pass) and prints nothing by itself."""
    passes: list[tuple[str, int, int]] = []

    @contextlib.contextmanager
    def display(total: int, label: str) -> Iterator[Any]:
        done = []
        yield SimpleNamespace(update=done.append)
        passes.append((label, total, sum(done)))

    replay(walk_bag, tmp_path / 'offline', progress=display)
    replay(walk_bag, tmp_path / 'online', mode='online', progress=display)
    assert [label for label, _, _ in passes] == ['estimate', 'write', 'replay']
    assert all(total > 0 and done == total for _, total, done in passes), passes


def test_the_command_shows_a_bar_on_a_terminal_and_not_with_no_progress(walk_bag, tmp_path):
    """hac replay draws the bar (hac_ros.cli.terminal) when stderr is a terminal."""
    def stderr_on_a_terminal(*flags: str) -> str:
        controller, terminal = pty.openpty()
        fcntl.ioctl(terminal, termios.TIOCSWINSZ, struct.pack('HHHH', 24, 100, 0, 0))  # 100 wide
        process = subprocess.Popen(
            [sys.executable, '-m', 'hac_ros.cli', 'replay', str(walk_bag), '-o',
             str(tmp_path / f'out{len(flags)}'), *flags], cwd=REPO, stdout=subprocess.DEVNULL,
            stderr=terminal)
        os.close(terminal)  # the child holds it: reading ends when the child has exited
        chunks = []
        try:
            while True:
                try:
                    chunk = os.read(controller, 65536)
                except OSError:  # EIO: the terminal's last writer is gone
                    break
                if not chunk:
                    break
                chunks.append(chunk)
        finally:
            os.close(controller)
        assert process.wait(timeout=120) == 0
        return b''.join(chunks).decode(errors='replace')

    shown = stderr_on_a_terminal()
    assert 'estimate' in shown and 'write' in shown and 'msg' in shown, shown
    assert 'estimate' not in stderr_on_a_terminal('--no-progress')


def test_notices_are_printed_once_on_stderr(tmp_path):
    scene = walking_scene(frames=60)
    scene.joints_world[10:20] = np.nan  # ten frames of HMR output that saw nobody
    source = write_recording(tmp_path / 'nan', scene)
    result = hac('replay', str(source), '-o', str(tmp_path / 'out'))  # offline: two passes
    assert result.returncode == 0, result.stderr
    assert result.stderr.count('too_little_seen') == 1
    assert 'too_little_seen 10' in result.stdout
    line, = [line for line in result.stderr.splitlines() if 'too_little_seen' in line]
    assert line.startswith('hac replay: warning: t+')


def test_the_library_logs_its_notices_and_prints_nothing(tmp_path, caplog, capfd):
    scene = walking_scene(frames=60)
    scene.joints_world[10:20] = np.nan
    source = write_recording(tmp_path / 'nan', scene, camera_info=False)
    with caplog.at_level(logging.INFO, logger='hac_ros'):
        replay(source, tmp_path / 'out')
    notices = [(r.name, r.levelname, r.getMessage()) for r in caplog.records]
    assert ('hac_ros.replay.replayer', 'INFO', 'no camera/camera_info in the recording: joints are '
            'judged in view by the map cone alone') in notices
    broken = [n for n in notices if 'too_little_seen' in n[2]]
    assert len(broken) == 1 and broken[0][:2] == ('hac_ros.replay.replayer', 'WARNING')
    assert capfd.readouterr() == ('', '')
