"""``hac play VIDEO|IMAGE_DIR --camera ...``: a video or a folder of images played as a camera over
real DDS (localhost, this process's domain: conftest.py), as ROS's image_publisher does.

Frames of Debian's opencv-doc vtest.avi (pedestrians, 768 x 576, 10 fps): every frame arrives
with its CameraInfo, stamped start + i / fps (the stamps running on over --loop), the pixels as
they are; the command's mistakes exit 2 naming the option; and hac_people_node, fed by
``hac play``, finds the people in them. In CI a missing input fails; elsewhere these tests skip
naming the install command (conftest.missing)."""
from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from conftest import OPENCV_DATA
from rclpy.context import Context
from test_play import Listener, wait_for

from hac_ros.cli import main as hac
from hac_ros.core.basics.errors import ArgumentError
from hac_ros.ros.camera_source import CAMERA_INFO_TOPIC, COMPRESSED_TOPIC, IMAGE_TOPIC
from hac_ros.ros.player import Player
from msg_adapters import stamp_to_ns

REPO = Path(__file__).resolve().parents[1]
VIDEO = OPENCV_DATA / 'vtest.avi'
FRAMES = 12  # of vtest.avi, written as PNGs
WIDTH, HEIGHT, VIDEO_FPS = 768, 576, 10.0
CAMERA = '700,700,384,288'  # assumed intrinsics of vtest.avi
K = np.array([[700.0, 0.0, 384.0], [0.0, 700.0, 288.0], [0.0, 0.0, 1.0]])
NS = 1_000_000_000
WAIT_S = 60.0
TOPICS = {IMAGE_TOPIC: 'sensor_msgs/msg/Image', CAMERA_INFO_TOPIC: 'sensor_msgs/msg/CameraInfo'}


@pytest.fixture(scope='module')
def clip(opencv_images, tmp_path_factory) -> tuple[Path, list[np.ndarray]]:
    """The first FRAMES frames of vtest.avi as PNGs in a folder, and as (H, W, 3) RGB."""
    import cv2

    folder = tmp_path_factory.mktemp('vtest') / 'frames'
    folder.mkdir()
    video = cv2.VideoCapture(str(VIDEO))
    frames = []
    for i in range(FRAMES):
        ok, bgr = video.read()
        assert ok
        cv2.imwrite(str(folder / f'{i:04d}.png'), bgr)
        frames.append(np.ascontiguousarray(bgr[:, :, ::-1]))
    video.release()
    return folder, frames


@pytest.fixture
def context():
    context = Context()
    rclpy.init(context=context)
    yield context
    rclpy.shutdown(context=context)


def stamps_of(messages: list[Any]) -> list[int]:
    return [stamp_to_ns(m.header.stamp) for m in messages]


def expected_stamps(start: float, fps: float, count: int) -> list[int]:
    return [round(start * NS) + round(i * NS / fps) for i in range(count)]


def test_a_folder_plays_every_frame_with_its_camera_info(clip, context):
    """--fps and --start: frame i stamped start + i / fps; the pixels as they are (rgb8), each
    with a CameraInfo of the frames' size and K (hac import's 6-number form), same header."""
    folder, frames = clip
    listener = Listener(TOPICS)
    try:
        with Player(folder, rate=10.0, camera=CAMERA + f',{WIDTH},{HEIGHT}', fps=5.0,
                    start=1000.0, wait_s=WAIT_S, context=context) as player:
            assert [t.name for t in player.plan] == [CAMERA_INFO_TOPIC, IMAGE_TOPIC]
            stats = player.run()
        assert stats.published == {IMAGE_TOPIC: FRAMES, CAMERA_INFO_TOPIC: FRAMES}
        images, infos = listener.received[IMAGE_TOPIC], listener.received[CAMERA_INFO_TOPIC]
        assert wait_for(lambda: len(images) == len(infos) == FRAMES)
        stamps = expected_stamps(1000.0, 5.0, FRAMES)
        assert stamps_of(images) == stamps_of(infos) == stamps
        for msg, rgb in zip(images, frames):
            assert (msg.encoding, msg.width, msg.height, msg.header.frame_id) == (
                'rgb8', WIDTH, HEIGHT, 'camera_optical')
            np.testing.assert_array_equal(np.frombuffer(bytes(msg.data), np.uint8).reshape(
                rgb.shape), rgb)
        for info in infos:
            assert (info.width, info.height, info.header.frame_id) == (WIDTH, HEIGHT,
                                                                       'camera_optical')
            np.testing.assert_allclose(np.reshape(info.k, (3, 3)), K)
            assert info.distortion_model == 'plumb_bob' and not np.any(info.d)
    finally:
        listener.close()


def test_a_video_plays_at_its_own_rate_compressed_with_its_distortion(context):
    """vtest.avi itself (stopped after FRAMES frames): stamped i / 10 (its own rate) from 0, JPEG
    CompressedImage of the frame, CameraInfo with the 8-number plumb_bob D and --frame-id."""
    import cv2

    from hac_ros.people.images import compressed_to_rgb

    listener = Listener({COMPRESSED_TOPIC: 'sensor_msgs/msg/CompressedImage',
                         CAMERA_INFO_TOPIC: TOPICS[CAMERA_INFO_TOPIC]})
    stop = threading.Event()
    images = listener.received[COMPRESSED_TOPIC]
    try:
        with Player(VIDEO, rate=5.0, camera=CAMERA + ',-0.1,0.01,0.001,0.002', compressed=True,
                    frame_id='cam', wait_s=WAIT_S, context=context) as player:
            watcher = threading.Thread(target=lambda: wait_for(
                lambda: len(images) >= FRAMES) and stop.set())
            watcher.start()
            stats = player.run(stop)
            watcher.join()
            assert stats.stopped
            sent = stats.published[COMPRESSED_TOPIC]
            infos = listener.received[CAMERA_INFO_TOPIC]
            assert wait_for(lambda: len(images) == sent and len(infos) == sent)
        assert stamps_of(images) == stamps_of(infos) == expected_stamps(1.0, VIDEO_FPS, sent)
        video = cv2.VideoCapture(str(VIDEO))
        for msg in images[:3]:
            bgr = video.read()[1]
            assert msg.format == 'rgb8; jpeg compressed bgr8' and msg.header.frame_id == 'cam'
            assert np.abs(compressed_to_rgb(msg).astype(int) - bgr[:, :, ::-1]).mean() < 4
        video.release()
        np.testing.assert_allclose(infos[0].d, [-0.1, 0.01, 0.001, 0.002, 0.0])
    finally:
        listener.close()


def test_loop_runs_the_stamps_on(clip, context):
    """--loop: pass k's frame i is stamped start + (k N + i) / fps, never back in time."""
    folder, _ = clip
    listener = Listener({IMAGE_TOPIC: TOPICS[IMAGE_TOPIC]})
    images = listener.received[IMAGE_TOPIC]
    stop = threading.Event()
    try:
        with Player(folder, rate=20.0, loop=True, camera=CAMERA, fps=4.0, start=20.0,
                    topics=[IMAGE_TOPIC], wait_s=WAIT_S, context=context) as player:
            watcher = threading.Thread(target=lambda: wait_for(
                lambda: len(images) > 2 * FRAMES) and stop.set())
            watcher.start()
            stats = player.run(stop)
            watcher.join()
            sent = stats.published[IMAGE_TOPIC]
            assert wait_for(lambda: len(images) == sent)
        assert stats.loops >= 3 and sent > 2 * FRAMES
        assert stamps_of(images) == expected_stamps(20.0, 4.0, sent)
    finally:
        listener.close()


@pytest.mark.parametrize('args, needle', [
    (['{clip}', '--fps', '5'], '--camera is needed'),
    (['{video}'], '--camera is needed'),
    (['{clip}', '--camera', CAMERA], '--fps is needed'),
    (['{video}', '--camera', CAMERA + ',640,480'], '--camera \'700,700,384,288,640,480\': says '
     '640 x 480, the frames of'),
    (['{video}', '--camera', '700,700'], '--camera \'700,700\': expected'),
    (['{video}', '--camera', CAMERA, '--topics', '/camera/image_raw/compressed'],
     'not played from'),
    (['{bag}', '--camera', CAMERA], '--camera: for a video or a folder of images'),
])
def test_command_line_mistakes_exit_2_naming_the_option(clip, capsys, args, needle):
    paths = {'{clip}': str(clip[0]), '{video}': str(VIDEO),
             '{bag}': str(REPO / 'bags' / 'demo_walk')}
    assert hac(['play', *[paths.get(a, a) for a in args]]) == 2
    err = capsys.readouterr().err
    assert needle in err and 'Traceback' not in err and len(err.strip().splitlines()) == 1, err


def test_library_errors_name_the_argument(clip, context):
    with pytest.raises(ArgumentError, match=r'^camera is needed'):
        Player(clip[0], fps=5.0, context=context)
    with pytest.raises(ArgumentError, match=r'^fps 0.0: expected frames per second'):
        Player(clip[0], camera=CAMERA, fps=0.0, context=context)


def test_the_default_frame_id_is_the_players():
    from hac_ros.cli.play import DEFAULT_FRAME_ID as CLI
    from hac_ros.ros.camera_source import DEFAULT_FRAME_ID

    assert CLI == DEFAULT_FRAME_ID == 'camera_optical'


def test_without_the_extra_a_video_or_folder_exits_2_naming_the_install_command(clip):
    block = "import sys; sys.modules['mediapipe'] = None; sys.modules['cv2'] = None\n"
    for source in (VIDEO, clip[0]):
        call = (f"from hac_ros.cli import main; sys.exit(main(['play', {str(source)!r}, "
                f"'--camera', {CAMERA!r}, '--fps', '5']))")
        run = subprocess.run([sys.executable, '-c', block + call], capture_output=True,
                             text=True, cwd=REPO, timeout=120)
        assert run.returncode == 2, run.stderr
        assert "[people] extra" in run.stderr and "pip install 'hac_ros[people]'" in run.stderr
        assert 'Traceback' not in run.stderr and len(run.stderr.strip().splitlines()) == 1


def test_hac_play_feeds_the_people_node(clip, tmp_path):
    """``hac play FOLDER --camera ...`` → hac_people_node (in this process) over DDS: it takes
    every image with its CameraInfo (none refused), and answers with joints of the played stamps
    and frame, people in them."""
    from test_people import Graph, people_of

    folder = tmp_path / 'four'
    folder.mkdir()
    for png in sorted(clip[0].iterdir())[:4]:
        (folder / png.name).write_bytes(png.read_bytes())
    graph = Graph({'max_rate_hz': 0.0})
    try:
        assert hac(['play', str(folder), '--camera', CAMERA, '--fps', '2', '--start', '50',
                    '--wait', str(WAIT_S)]) == 0
        played = expected_stamps(50.0, 2.0, 4)

        def settled() -> bool:
            status = graph.status()
            done = int(status.get('images_processed', 0)) + int(status.get('dropped.overload', 0))
            return (int(status.get('images_received', 0)) == 4 and done == 4
                    and len(graph.received['joints']) == int(status['images_processed']))
        assert wait_for(settled), graph.status()
        assert not [k for k in graph.status() if k.startswith('rejected.')], graph.status()
        joints = graph.received['joints']
        assert joints and set(stamps_of(joints)) <= set(played)
        assert all(m.header.frame_id == 'camera_optical' for m in joints)
        assert any(people_of(m) for m in joints)
    finally:
        graph.close()


@pytest.fixture(scope='module')
def sparse_clip(opencv_images, tmp_path_factory) -> Path:
    """Every 8th of vtest.avi's frames, 48 of them (38 s of the video), as PNGs in a folder."""
    import cv2

    folder = tmp_path_factory.mktemp('vtest_sparse') / 'frames'
    folder.mkdir()
    video = cv2.VideoCapture(str(VIDEO))
    for i in range(48 * 8):
        ok, bgr = video.read()
        assert ok
        if i % 8 == 0:
            cv2.imwrite(str(folder / f'{i:04d}.png'), bgr)
    video.release()
    return folder


def test_readme_chain_a_video_alone_gives_the_fixed_cameras_height(sparse_clip, tmp_path):
    """README's chain from a clone with nothing but a video: `hac play FOLDER --camera ...` →
    hac_people_node → hac_node with static_camera and joint_layout blazepose33, over DDS: hac_node
    converges and says the camera's height above the square (vtest.avi's camera is 5-6 m up with
    the assumed fx = 700: docs/accuracy.md, "A fixed camera")."""
    from test_people import Graph

    folder = sparse_clip
    graph = Graph({'max_rate_hz': 0.0}, {'static_camera': True, 'joint_layout': 'blazepose33',
                                         'input_qos': 'reliable', 'stale_after_s': 60.0})
    try:
        # 1.25 frames a second (every 8th of 10 Hz): the people node (about 1 CPU-s a frame)
        # takes most of them, the newest when it falls behind
        assert hac(['play', str(folder), '--camera', CAMERA, '--fps', '1.25', '--start', '10',
                    '--wait', str(WAIT_S)]) == 0

        def hac_status() -> dict[str, str]:
            for msg in reversed(graph.received['diagnostics']):
                for status in msg.status:
                    if not status.name.startswith('hac_people_node'):
                        return {kv.key: kv.value for kv in status.values}
            return {}
        assert wait_for(lambda: hac_status().get('converged') == 'true'), hac_status()
        values = hac_status()
        assert 'rejected.slam_frozen' not in values and 'no_poses' not in values['reasons']
        assert 4.0 < float(values['camera_height_m']) < 7.0, values
    finally:
        graph.close()
