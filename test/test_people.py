"""People from pixels with the real thing: MediaPipe (the [people] extra), Debian's opencv-doc
images of real people, the real `hac people`, `hac import` and replay, and the harness of real
rclpy nodes over real DDS (localhost, this process's own domain: conftest.py) that
test_people_node.py and test_people_faults.py use. In CI a missing input fails; elsewhere these
tests skip naming the install command (conftest.missing)."""
from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import OPENCV_DATA

from hac_ros.cli import main as hac
from hac_ros.core.layouts.blazepose33 import HIPS, LAYOUT
from hac_ros.people.lifting import Camera

REPO = Path(__file__).resolve().parents[1]
K = np.array([[525.0, 0.0, 319.5], [0.0, 525.0, 239.5], [0.0, 0.0, 1.0]])  # assumed, 640 x 480
CAMERA = '525,525,319.5,239.5'
FLOOR_SLAM = 2.0  # the floor this many SLAM units below the static camera (optical y)
WAIT_S = 60.0  # what a loaded machine may need; the tests wait for events, not for time


def wait_for(predicate: Callable[[], bool], timeout: float = WAIT_S) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


@pytest.fixture(scope='module')
def model(people_extra):
    from hac_ros.people.model import PoseModel

    pose_model = PoseModel()
    yield pose_model
    pose_model.close()


def implied_scale(people: list[np.ndarray], floor_slam: float) -> float:
    """The scale the lifted feet imply over a floor ``floor_slam`` SLAM units below a camera that
    looks along it (optical y = down): each person's lowest contact (heel, foot index or ankle),
    moved down to the sole by the layout's height, stands on the floor; metres per SLAM unit,
    the median over the people."""
    ratios = []
    for joints in people:
        if not np.isfinite(joints[list(LAYOUT.contact)]).all():
            continue  # feet not seen: no contact (the man cut by the image's edge)
        legs = [np.linalg.norm(joints[h] - joints[k]) + np.linalg.norm(joints[k] - joints[a])
                for h, k, a in LAYOUT.legs]
        lowest = max(LAYOUT.contact, key=lambda j: joints[j, 1])
        sole_y = joints[lowest, 1] + LAYOUT.sole_height_rel[lowest] * max(legs)
        ratios.append(sole_y / floor_slam)
    return float(np.median(ratios))


# ---------------------------------------------------------------------------- the model
def test_the_shipped_models_find_the_people_in_the_images(model, opencv_images):
    """The Tasks API on the models the wheel ships: both players of basketball2.png, the one of
    basketball1.png and Messi; every person's hips inside the image."""
    found = {name: model.detect(rgb) for name, rgb in opencv_images.items()}
    assert [len(found[n]) for n in ('basketball1.png', 'basketball2.png', 'messi5.jpg')] == [
        1, 2, 1]
    for name, people in found.items():
        height, width = opencv_images[name].shape[:2]
        for person in people:
            hips = person.pixels[list(HIPS)].mean(axis=0)
            assert 0 <= hips[0] < width and 0 <= hips[1] < height
            assert person.world.shape == (33, 3) and np.ptp(person.world[:, 1]) > 0.8  # metres


def test_the_tasks_path_matches_the_legacy_graph(model, opencv_images):
    """The shipped models run through the Tasks API (metadata added, bundled in memory) give the
    landmarks MediaPipe's own legacy graph (mp.solutions.pose) gives, within 1 px median."""
    import mediapipe as mp

    compared = 0
    with mp.solutions.pose.Pose(static_image_mode=True, model_complexity=1) as legacy:
        for name, rgb in opencv_images.items():
            result = legacy.process(rgb)
            if result.pose_landmarks is None:
                continue
            height, width = rgb.shape[:2]
            theirs = np.array([(p.x * width, p.y * height)
                               for p in result.pose_landmarks.landmark])
            ours = min((p.pixels for p in model.detect(rgb)),
                       key=lambda px: np.median(np.linalg.norm(px - theirs, axis=1)))
            assert np.median(np.linalg.norm(ours - theirs, axis=1)) < 1.0, name
            compared += 1
    assert compared == len(opencv_images)


def test_a_task_file_runs_as_model_path(model, opencv_images, tmp_path):
    """model_path: a .task file (here the shipped models written as one) gives the same
    landmarks as the models in memory."""
    from hac_ros.people.model import PoseModel, write_task_file

    task = write_task_file(tmp_path / 'pose_landmarker_full.task')
    own = PoseModel(model_path=str(task), person_detector='none')
    try:
        rgb = opencv_images['basketball2.png']
        a = sorted(model.detect(rgb), key=lambda p: p.pixels[0, 0])
        b = sorted(own.detect(rgb), key=lambda p: p.pixels[0, 0])
        assert len(a) == len(b) == 2
        for x, y in zip(a, b):
            np.testing.assert_allclose(x.pixels, y.pixels, atol=1e-3)
            np.testing.assert_allclose(x.world, y.world, atol=1e-6)
    finally:
        own.close()
    with pytest.raises(Exception, match='model_path'):
        PoseModel(model_path=str(tmp_path / 'missing.task'))


def test_a_mosaic_of_four_standing_people_finds_each(model, opencv_images):
    """Four people side by side at 640 x 480 (bench/_people_scenes.four_standing: the basketball
    players and their mirror images, each about 370 px tall): each found once, in their strip
    (two by the whole-image detector, two through the HOG crops)."""
    sys.path.insert(0, str(REPO / 'bench'))
    try:
        from _people_scenes import four_standing
    finally:
        sys.path.remove(str(REPO / 'bench'))
    found = model.detect(four_standing())
    strips = sorted(int(p.pixels[list(HIPS)].mean(axis=0)[0] // 160) for p in found)
    assert strips == [0, 1, 2, 3]


def test_far_small_people_are_found_through_the_person_detectors_crops(model, opencv_images):
    """vtest.avi (a static camera over a square, pedestrians 60-100 px tall): BlazePose finds
    nobody on the whole frame; the HOG person detector's crops, scaled up, give poses that lift."""
    import cv2

    from hac_ros.people.frontend import PeopleFromImages

    video = cv2.VideoCapture(str(OPENCV_DATA / 'vtest.avi'))
    for _ in range(61):
        ok, bgr = video.read()
    assert ok
    rgb = np.ascontiguousarray(bgr[:, :, ::-1])
    whole_only = [p for p in model.detect(rgb) if not p.from_crop]
    assert whole_only == []
    height, width = rgb.shape[:2]
    camera = Camera(K=np.array([[700.0, 0, width / 2], [0, 700.0, height / 2], [0, 0, 1]]),
                    width=width, height=height)
    frame = PeopleFromImages(model).process(rgb, camera)
    assert len(frame.lifted) >= 2 and frame.from_crop == len(frame.lifted)
    depth = frame.joints_cam[:, :, 2]
    assert (depth[np.isfinite(depth)] > 2.0).all()  # far: metres in front (NaN: not seen)


# ---------------------------------------------------------------------------- offline
def test_hac_people_then_import_and_replay_match_every_pose_exactly(people_extra, opencv_images,
                                                                     tmp_path):
    """`hac people` on a folder of images of a static camera (`--start`, `--fps`), a TUM
    trajectory of the same stamps and a floor map: `hac import` and the replay match every
    frame's joints to a pose exactly, and the people calibrate."""
    import cv2

    from hac_ros.files.params_file import load_params
    from hac_ros.files.tum import write_tum
    from hac_ros.replay.replayer import replay

    frames = tmp_path / 'frames'
    frames.mkdir()
    order = ['basketball1.png', 'basketball2.png'] * 12
    for i, name in enumerate(order):
        cv2.imwrite(str(frames / f'{i:04d}.png'), opencv_images[name][:, :, ::-1])
    start, fps = 1000.0, 5.0
    joints_file = tmp_path / 'joints.npz'
    assert hac(['people', str(frames), '--camera', CAMERA, '--fps', str(fps), '--start',
                str(start), '-o', str(joints_file), '--no-progress']) == 0
    saved = np.load(joints_file)
    assert saved['joints'].shape[1:] == (2, 33, 3)
    np.testing.assert_allclose(saved['stamps'], start + np.arange(len(order)) / fps)
    stamps_ns = np.round(saved['stamps'] * 1e9).astype(np.int64)
    rng = np.random.default_rng(0)
    centres = rng.normal(0.0, 1e-5, (len(order), 3))  # a static camera as a SLAM reports it
    write_tum(tmp_path / 'traj.txt', stamps_ns, centres, np.tile([0.0, 0.0, 0.0, 1.0],
                                                                 (len(order), 1)))
    np.save(tmp_path / 'map.npy', floor_points())
    rec = tmp_path / 'rec'
    assert hac(['import', '-o', str(rec), '--trajectory', str(tmp_path / 'traj.txt'), '--map',
                str(tmp_path / 'map.npy'), '--joints', str(joints_file), '--camera',
                CAMERA + ',640,480', '--joint-layout', 'blazepose33']) == 0
    summary = replay(rec, tmp_path / 'out', params=load_params(rec / 'params.yaml'))
    assert summary.status.pose_matches == {'exact': len(order)}
    people = [p for frame in saved['joints'] for p in frame if np.isfinite(p).all()]
    expected = implied_scale(people, FLOOR_SLAM)
    assert abs(summary.status.scale / expected - 1) < 0.01, (summary.status.scale, expected)


def test_hac_people_reads_a_video_and_a_stamps_file(people_extra, opencv_images, tmp_path):
    """A video's frames are stamped at its own rate from --start; --stamps takes one stamp per
    frame from a file's first column (a TUM trajectory works); a count that does not match is
    refused naming --stamps, nothing written."""
    import cv2

    video = tmp_path / 'clip.avi'
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*'MJPG'), 4.0, (640, 480))
    for name in ('basketball1.png', 'basketball2.png', 'basketball1.png'):
        writer.write(np.ascontiguousarray(opencv_images[name][:, :, ::-1]))
    writer.release()
    out = tmp_path / 'video.npz'
    assert hac(['people', str(video), '--camera', CAMERA, '--start', '10', '-o', str(out),
                '--person-detector', 'none', '--no-progress']) == 0
    saved = np.load(out)
    np.testing.assert_allclose(saved['stamps'], [10.0, 10.25, 10.5])
    assert [int(np.isfinite(f[:, 0, 0]).sum()) for f in saved['joints']] == [1, 2, 1]
    stamps = tmp_path / 'traj.txt'
    stamps.write_text('# timestamp tx ty tz qx qy qz qw\n'
                      + ''.join(f'{t} 0 0 0 0 0 0 1\n' for t in (3.5, 3.6, 3.8)))
    assert hac(['people', str(video), '--camera', CAMERA, '--stamps', str(stamps), '-o',
                str(tmp_path / 'stamped.npz'), '--person-detector', 'none',
                '--no-progress']) == 0
    np.testing.assert_allclose(np.load(tmp_path / 'stamped.npz')['stamps'], [3.5, 3.6, 3.8])
    stamps.write_text('3.5\n3.6\n')
    run = subprocess.run([sys.executable, '-m', 'hac_ros.cli', 'people', str(video), '--camera',
                          CAMERA, '--stamps', str(stamps), '-o', str(tmp_path / 'short.npz'),
                          '--person-detector', 'none', '--no-progress'],
                         capture_output=True, text=True, cwd=REPO, timeout=300)
    assert run.returncode == 2 and '--stamps' in run.stderr and 'Traceback' not in run.stderr
    assert not (tmp_path / 'short.npz').exists()


def test_num_threads_pins_the_node_process(people_extra):
    """hac_people_node with num_threads 1 runs on one core (MediaPipe's Python API has no thread
    option: the process is pinned), and ends cleanly on SIGINT."""
    import os
    import signal

    allowed = sorted(os.sched_getaffinity(0))
    if len(allowed) < 2:
        pytest.skip('this process has one core: there is nothing to pin')
    process = subprocess.Popen([sys.executable, '-m', 'hac_ros.ros.people_node', '--ros-args', '-p',
                                'num_threads:=1', '-p', 'person_detector:=none'],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    status = Path(f'/proc/{process.pid}/status')

    def cpus() -> str:
        found = [line.split(':')[1].strip() for line in status.read_text().splitlines()
                 if line.startswith('Cpus_allowed_list')]
        return found[0] if found else ''
    try:
        assert wait_for(lambda: process.poll() is None and cpus() == str(allowed[0])), cpus()
    finally:
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=120)
    assert process.returncode == 0, err


def floor_points() -> np.ndarray:
    """A floor map in SLAM units: a 0.04-unit grid on the plane FLOOR_SLAM below the camera
    (optical y down), in front of it, in its view."""
    x, z = np.meshgrid(np.arange(-3.0, 3.0, 0.04), np.arange(0.5, 8.0, 0.04))
    return np.c_[x.ravel(), np.full(x.size, FLOOR_SLAM), z.ravel()]


# ---------------------------------------------------------------------------- without the extra
def test_without_the_extra_the_commands_exit_2_naming_the_install_command(tmp_path):
    """MediaPipe absent (blocked in sys.modules, as an interpreter without it): `hac people` and
    `hac_people_node` exit 2 with the install command; hac_node's help still works."""
    block = "import sys; sys.modules['mediapipe'] = None; sys.modules['cv2'] = None\n"
    for call in ("from hac_ros.cli import main; sys.exit(main(['people', 'x', '--camera', "
                 "'1,1,1,1', '-o', 'y.npz']))",
                 "from hac_ros.ros.people_node import main; sys.exit(main(['hac_people_node']))"):
        run = subprocess.run([sys.executable, '-c', block + call], capture_output=True,
                             text=True, cwd=tmp_path, timeout=300)
        assert run.returncode == 2, run.stderr
        assert "pip install 'hac_ros[people]'" in run.stderr, run.stderr
        assert 'Traceback' not in run.stderr


# ---------------------------------------------------------------------------- over DDS
class Graph:
    """hac_people_node (``people`` parameters), optionally hac_node (``hac`` parameters), and a
    camera/SLAM stand-in node that publishes images, CameraInfo, poses and the map and records
    what comes back, in a fresh rclpy Context spun by one thread."""

    def __init__(self, people: dict[str, Any], hac: dict[str, Any] | None = None) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.parameter import Parameter
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        from hac_ros.ros.people_node import PeopleNode
        from hac_ros.ros.spin_thread import SpinThread
        from msg_adapters import rclpy_types

        self.types = rclpy_types()
        self.context = Context()
        rclpy.init(context=self.context)
        self.nodes = [PeopleNode(context=self.context, parameter_overrides=[
            Parameter(k, value=v) for k, v in people.items()])]
        if hac is not None:
            from hac_ros.ros.node import HacNode

            self.nodes.append(HacNode(context=self.context, parameter_overrides=[
                Parameter(k, value=v) for k, v in hac.items()]))
        self.io = rclpy.create_node('hac_test_camera', context=self.context)
        reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        kinds = {'image': ('camera/image_raw', 'sensor_msgs/msg/Image', reliable),
                 'compressed': ('camera/image_raw/compressed',
                                'sensor_msgs/msg/CompressedImage', reliable),
                 'camera_info': ('camera/camera_info', 'sensor_msgs/msg/CameraInfo', reliable),
                 'pose': ('slam/pose', 'geometry_msgs/msg/PoseStamped', reliable),
                 'cloud': ('slam/cloud', 'sensor_msgs/msg/PointCloud2', latched)}
        self.pub = {k: self.io.create_publisher(self.types.get(t), name, q)
                    for k, (name, t, q) in kinds.items()}
        self.received: dict[str, list[Any]] = {'joints': [], 'scale': [], 'diagnostics': []}
        for key, topic, msgtype in (('joints', 'hmr/joints', 'geometry_msgs/msg/PoseArray'),
                                    ('scale', 'hac/scale', 'std_msgs/msg/Float64'),
                                    ('diagnostics', '/diagnostics',
                                     'diagnostic_msgs/msg/DiagnosticArray')):
            self.io.create_subscription(self.types.get(msgtype), topic,
                                        lambda m, k=key: self.received[k].append(m), reliable)
        self.executor = SingleThreadedExecutor(context=self.context)
        for node in [*self.nodes, self.io]:
            self.executor.add_node(node)
        self.spinner = SpinThread(self.executor)
        image_kind = 'compressed' if people.get('image_transport') == 'compressed' else 'image'
        wanted = [image_kind, 'camera_info'] + (['pose', 'cloud'] if hac is not None else [])
        assert wait_for(lambda: all(self.pub[k].get_subscription_count() > 0 for k in wanted)
                        and self.io.count_publishers('hmr/joints') > 0), 'DDS discovery failed'

    def close(self) -> None:
        import rclpy

        self.spinner.close()
        for node in self.nodes:
            node.destroy_node()
        self.io.destroy_node()
        rclpy.shutdown(context=self.context)

    def image(self, rgb: np.ndarray, stamp_ns: int, compressed: bool = False,
              encoding: str = 'rgb8') -> None:
        from hac_ros.people.images import rgb_to_jpeg
        from msg_adapters.image import rgb_to_image
        from msg_adapters.stamps import make_header

        if compressed:
            msg = self.types.get('sensor_msgs/msg/CompressedImage')(
                header=make_header(stamp_ns, 'camera_optical', self.types), format='jpeg',
                data=rgb_to_jpeg(rgb))
            self.pub['compressed'].publish(msg)
        else:
            self.pub['image'].publish(rgb_to_image(rgb, stamp_ns, 'camera_optical', self.types,
                                                   encoding))

    def camera_info(self, stamp_ns: int) -> None:
        """Publish the 640 x 480 CameraInfo of K and wait until hac_people_node has it (its status
        stops saying there is none): an image sent at once on its own topic may otherwise arrive
        first and be refused (no_camera_info)."""
        from msg_adapters import intrinsics_to_camera_info

        self.pub['camera_info'].publish(intrinsics_to_camera_info(K, 640, 480, stamp_ns,
                                                                  'camera_optical', self.types))
        assert wait_for(lambda: self.status().get('camera_info', 'none') != 'none'), \
            'hac_people_node did not get the CameraInfo'

    def status(self, people_only: bool = True) -> dict[str, str]:
        """The key-values of the last /diagnostics status of hac_people_node."""
        for msg in reversed(self.received['diagnostics']):
            for status in msg.status:
                if status.name.startswith('hac_people_node'):
                    return {kv.key: kv.value for kv in status.values} | {
                        'level': str(status.level[0]), 'message': status.message}
        return {}


def people_of(msg: Any) -> list[np.ndarray]:
    from msg_adapters import pose_array_to_joints

    return list(pose_array_to_joints(msg, 33))
