"""hac_people_node against a hostile camera, with the real thing (MediaPipe, OpenCV's HOG, real
rclpy nodes over DDS, Debian's opencv-doc images): images smaller than the person detector,
stamps of zero or going backwards, CameraInfo that does not fit the image (REP-104 binning and
ROI, a rectified camera, a principal point outside), corrupt JPEG; and the story its log tells."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from logcapture import NodeLog
from test_people import Graph, K, model, wait_for  # noqa: F401 (model: a fixture)

from hac_ros.cli import main as hac

pytest.importorskip('rclpy')

REPO = Path(__file__).resolve().parents[1]
SMALL_SIZES = ((16, 16), (80, 60), (200, 80))  # width x height: below HOG's 64 x 128 window
TOO_SMALL = ((16, 16), (80, 60))  # no 60 px person fits, even scaled for HOG (1.76x)


def camera_info_msg(types, width, height, stamp_ns=1, K_full=None, **fields):
    """A CameraInfo of a ``width`` x ``height`` camera, principal point at the centre."""
    from msg_adapters import intrinsics_to_camera_info

    if K_full is None:
        K_full = np.array([[0.8 * width, 0, width / 2], [0, 0.8 * width, height / 2], [0, 0, 1]])
    msg = intrinsics_to_camera_info(K_full, width, height, stamp_ns, 'camera_optical', types)
    for name, value in fields.items():
        setattr(msg, name, value)
    return msg


def noise(width, height, seed=0):
    return np.random.default_rng(seed).integers(0, 255, (height, width, 3), dtype=np.uint8)


def test_images_smaller_than_the_person_detector_never_reach_it(people_extra):
    """OpenCV's HOG kills the process (SIGSEGV) on an image smaller than its 64 x 128 window:
    the model never gives it one, at the scale it searches (a crash here would end this test
    run). 200 x 80 is searched (scaled 1.76x for people of 60 px), 80 x 60 cannot hold one."""
    from hac_ros.people.model import PoseModel

    for min_height, sizes in ((60.0, SMALL_SIZES + ((1, 1), (37, 73), (36, 72))),
                              (200.0, ((200, 80), (121, 243), (122, 243), (768, 576)))):
        model = PoseModel(person_detector='hog', person_min_height_px=min_height)
        try:
            for width, height in sizes:
                model.detect(noise(width, height))
                assert model.last_too_small == model.too_small(width, height)
                too_small = (width * model.hog_zoom < 64 or height * model.hog_zoom < 128)
                assert model.last_too_small == too_small, (width, height)
        finally:
            model.close()
    model = PoseModel(person_detector='hog')
    try:
        assert [model.too_small(*size) for size in SMALL_SIZES] == [True, True, False]
    finally:
        model.close()


def test_small_images_are_processed_counted_and_warned_over_dds(people_extra):
    graph = Graph({'person_detector': 'hog', 'max_rate_hz': 0.0})
    try:
        for k, (width, height) in enumerate(SMALL_SIZES):
            graph.pub['camera_info'].publish(camera_info_msg(graph.types, width, height))
            assert wait_for(lambda w=width, h=height: graph.status().get(
                'camera_info', '').startswith(f'{w} x {h}'))
            graph.image(noise(width, height, k), 10**9 * (k + 1))
            assert wait_for(lambda n=k + 1: graph.status().get('images_processed') == str(n))
        assert wait_for(lambda: len(graph.received['joints']) == 3)
        status = graph.status()
        assert status['image_too_small'] == str(len(TOO_SMALL))
        assert 'rejected' not in ' '.join(status)
        warned = [s.message for m in graph.received['diagnostics'] for s in m.status
                  if s.name.startswith('hac_people_node') and s.level == b'\x01']
        assert any('image_too_small' in text for text in warned), warned
    finally:
        graph.close()


def test_hac_people_on_small_frames_says_why_nobody_was_found(people_extra, tmp_path, capsys):
    import cv2

    folder = tmp_path / 'thermal'
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f'{i:03d}.png'), noise(80, 60, i))
    code = hac(['people', str(folder), '--camera', '64,64,40,30', '--fps', '9',
                '-o', str(tmp_path / 'people.npz')])
    err = capsys.readouterr().err
    assert code != 0 and 'nobody found in 3 frames' in err
    assert 'too small for the person detector' in err
    code = hac(['people', str(folder), '--camera', '64,64,0,0', '--fps', '9',
                '-o', str(tmp_path / 'people.npz')])
    err = capsys.readouterr().err
    assert code == 2 and '--camera' in err and 'principal point cx = 0' in err


def test_stamps_of_zero_or_going_back_are_counted_and_capped_by_arrival(people_extra,
                                                                       opencv_images):
    """A driver without a clock stamps every image 0: each is processed (the rate cap counts
    arrival time; they arrive at least 0.25 s apart, over max_rate_hz 10's 0.1 s) and counted
    stamp_zero, the status WARN. Stamps going back 1/60 s each are counted too; every image is
    accounted for."""
    graph = Graph({'person_detector': 'none', 'max_rate_hz': 10.0})
    try:
        graph.camera_info(1)
        rgb = opencv_images['basketball1.png']
        for n in range(1, 6):
            graph.image(rgb, 0)
            assert wait_for(lambda n=n: graph.status().get('images_received') == str(n))
            # the next image arrives at least this much later than this one: over 0.1 s
            wait_for(lambda: False, timeout=0.25)
        assert wait_for(lambda: graph.status().get('images_processed') == '5'), graph.status()
        status = graph.status()
        assert status['stamp_zero'] == '5' and 'dropped.rate_cap' not in status
        assert all(m.header.stamp.sec == 0 for m in graph.received['joints'])
        warned = [s.message for m in graph.received['diagnostics'] for s in m.status
                  if s.name.startswith('hac_people_node') and s.level == b'\x01']
        assert any('stamp_zero' in text for text in warned), warned
        backwards = [100 * 10**9 - k * 10**9 // 60 for k in range(6)]
        for stamp in backwards:
            graph.image(rgb, stamp)
        assert wait_for(lambda: int(graph.status().get('images_received', 0))
                        + int(graph.status().get('dropped.lost', 0)) == 11)
        assert wait_for(lambda: graph.status().get('stamp_backwards') == '5')

        def accounted(status: dict[str, str]) -> int:
            return sum(int(status.get(key, 0)) for key in (
                'images_processed', 'dropped.overload', 'dropped.rate_cap', 'dropped.lost')) - 5

        assert wait_for(lambda: accounted(graph.status()) == 6), graph.status()
    finally:
        graph.close()


def test_a_camera_info_that_does_not_fit_is_named_invalid(people_extra, opencv_images):
    graph = Graph({'person_detector': 'none'})
    try:
        graph.pub['camera_info'].publish(camera_info_msg(
            graph.types, 640, 480, K_full=np.diag([525.0, 525.0, 1.0])))  # cx = cy = 0
        assert wait_for(lambda: graph.status().get('camera_info', '').startswith('invalid:'))
        status = graph.status()
        assert 'principal point cx = 0' in status['camera_info']
        assert wait_for(lambda: 'is invalid' in graph.status().get('message', '')
                        or 'camera_info_invalid' in graph.status().get('message', ''))
        graph.image(opencv_images['basketball1.png'], 10**9)
        assert wait_for(lambda: graph.status().get('rejected.no_camera_info') == '1')
        assert graph.received['joints'] == []
        # 2 x 2 binning of the 640 x 480 sensor: a 320 x 240 image is the camera's size
        graph.pub['camera_info'].publish(camera_info_msg(graph.types, 640, 480, K_full=K,
                                                         binning_x=2, binning_y=2))
        assert wait_for(lambda: graph.status().get('camera_info', '').startswith('320 x 240'))
        half = opencv_images['basketball1.png'][::2, ::2].copy()
        graph.image(half, 2 * 10**9)
        assert wait_for(lambda: len(graph.received['joints']) == 1)
        assert 'rejected.camera_info_size_mismatch' not in graph.status()
    finally:
        graph.close()


def test_binning_gives_the_same_people_as_the_full_image(people_extra, opencv_images, model):
    """basketball1 at 640 x 480 with K, and decimated 2 x 2 with the binned CameraInfo's K:
    the same people at the same depth (the K of the binned image is what image_geometry gives)."""
    import msg_adapters as ma
    from hac_ros.people.frontend import PeopleFromImages
    from hac_ros.people.lifting import Camera

    types = ma.rosbags_types()
    people = PeopleFromImages(model)
    depths = []
    for binning, rgb in ((1, opencv_images['basketball1.png']),
                         (2, opencv_images['basketball1.png'][::2, ::2].copy())):
        info = camera_info_msg(types, 640, 480, K_full=K, binning_x=binning, binning_y=binning)
        K_image, width, height = ma.camera_info_to_intrinsics(info)
        frame = people.process(rgb, Camera(K=K_image, width=width, height=height))
        assert len(frame.lifted) == 1
        depths.append(float(np.median(frame.joints_cam[0, :, 2])))
    assert abs(depths[1] / depths[0] - 1) < 0.05, depths


def test_rectified_images_use_the_projection(people_extra):
    from hac_ros.people.params import PeopleParams, rectified

    assert not rectified(PeopleParams())
    assert rectified(PeopleParams(image_topic='/cam/image_rect'))
    assert rectified(PeopleParams(image_topic='cam/image_rect_color'))
    assert not rectified(PeopleParams(image_topic='cam/image_rect', rectified='false'))
    assert rectified(PeopleParams(rectified='true'))
    graph = Graph({'person_detector': 'none', 'rectified': 'true'})
    try:
        P = np.c_[[[500.0, 0, 321], [0, 501, 238], [0, 0, 1]], np.zeros(3)].reshape(12)
        graph.pub['camera_info'].publish(camera_info_msg(
            graph.types, 640, 480, K_full=K, p=P.tolist(), distortion_model='plumb_bob',
            d=[0.1, -0.2, 0.0, 0.0, 0.0]))
        assert wait_for(lambda: 'fx 500.0 fy 501.0 cx 321.0 cy 238.0' in graph.status().get(
            'camera_info', ''))
        assert 'rectified: P' in graph.status()['camera_info']
    finally:
        graph.close()


def test_a_corrupt_jpeg_is_counted_never_published(people_extra, opencv_images):
    from hac_ros.people.images import compressed_to_rgb, rgb_to_jpeg
    from msg_adapters.image import ImageError
    from msg_adapters.stamps import make_header

    data = rgb_to_jpeg(opencv_images['basketball1.png'])
    # 100 bytes flipped halfway (a flip the decoder cannot notice decodes as garbage: only what
    # the decoder reports can be counted), and an end-of-image marker inside the data
    half = len(data) // 2
    flipped = data[:half] + bytes(b ^ 0x5A for b in data[half:half + 100]) + data[half + 100:]
    marker = data[:3000] + b'\xff\xd9' + data[3000:]
    for corrupt in (flipped, marker, data[:-2], data[:len(data) // 2]):
        with pytest.raises(ImageError) as error:
            compressed_to_rgb(SimpleNamespace(format='jpeg', data=corrupt))
        assert error.value.reason == 'corrupt_image'
    assert compressed_to_rgb(SimpleNamespace(format='jpeg', data=data)).shape == (480, 640, 3)
    graph = Graph({'person_detector': 'none', 'image_transport': 'compressed'})
    try:
        graph.camera_info(1)
        graph.pub['compressed'].publish(graph.types.get('sensor_msgs/msg/CompressedImage')(
            header=make_header(10**9, 'camera_optical', graph.types), format='jpeg',
            data=flipped))
        assert wait_for(lambda: graph.status().get('rejected.corrupt_image') == '1')
        graph.image(opencv_images['basketball1.png'], 2 * 10**9, compressed=True)
        assert wait_for(lambda: len(graph.received['joints']) == 1)
        assert graph.received['joints'][0].header.stamp.sec == 2
    finally:
        graph.close()


def test_the_log_tells_the_story(people_extra, opencv_images, capfd):
    """The CameraInfo taken, the first image, the first person, the status line, the camera
    stopping and coming back: each one line at INFO (WARN for the stop), as docs/people.md's
    "The log" shows them, line for line."""
    doc = (REPO / 'docs' / 'people.md').read_text()
    block = doc[doc.index('## The log'):].split('```')[1]
    shown = [line.split(': ', 1)[1] for line in block.strip().splitlines()]
    log = NodeLog(capfd)
    graph = Graph({'log_period_s': 1.0})  # the defaults otherwise (stale_after_s 2)
    try:
        graph.camera_info(1)
        graph.image(opencv_images['basketball1.png'], 5 * 10**9)
        assert log.wait_for(lambda t: 'images received 1 = processed 1' in t, 60), log.text
        assert log.wait_for(lambda t: 'no image on /camera/image_raw for 2 s' in t, 60)
        graph.image(opencv_images['basketball1.png'], 6 * 10**9)
        assert log.wait_for(lambda t: 'images on /camera/image_raw again' in t, 60), log.text
        for line in shown:
            assert line in log.text, (line, log.text)
    finally:
        graph.close()


def test_small_people_on_vtest_are_found_and_nobody_invented(people_extra, opencv_images):
    """vtest.avi, every 80th frame, labelled by hand (test/data/vtest_people_labels.json: a person
    counts when at least 60 px tall and 80 % in view): the default person detector finds at least
    80 % of them, and at least 90 % of what it finds is one of them (bench/people_recall.py's
    matching: landmark box IoU >= 0.3, one to one; people labelled ignore are neutral)."""
    import json
    import sys

    sys.path.insert(0, str(REPO / 'bench'))
    from _people_scenes import video_frames
    from people_recall import LABELS, score

    from hac_ros.people.model import PoseModel

    truth = json.loads(LABELS.read_text())
    model = PoseModel()  # the defaults: person_detector hog, person_min_height_px 60
    try:
        totals = {'counted': 0, 'matched': 0, 'found': 0, 'neutral': 0}
        for index, rgb in video_frames(int(truth['step'])):
            if str(index) in truth['frames']:
                counts = score([p.box() for p in model.detect(rgb)], truth['frames'][str(index)])
                for key in totals:
                    totals[key] += counts[key]
    finally:
        model.close()
    assert totals['counted'] >= 50
    assert totals['matched'] / totals['counted'] >= 0.8, totals
    assert totals['matched'] / (totals['found'] - totals['neutral']) >= 0.9, totals


def test_a_person_cut_by_the_image_edge_publishes_no_feet(people_extra, opencv_images, model):
    """basketball2.png: BlazePose draws the legs of the man on the right, cut at the thighs by the
    image's bottom edge, inside the image on his shirt. His feet are not seen (NaN); the whole
    player keeps his. Given to hac_node's core over a floor, the man gives no contact
    (contact_unseen) and the player a sample."""
    from test_people import floor_points

    from hac_ros.core.basics.outputs import SampleOut
    from hac_ros.core.calibrator import Calibrator
    from hac_ros.core.rules.params import HacParams
    from hac_ros.people.frontend import FEET, PeopleFromImages
    from hac_ros.people.lifting import Camera

    frame = PeopleFromImages(model).process(opencv_images['basketball2.png'],
                                            Camera(K=K, width=640, height=480))
    assert len(frame.joints_cam) == 2
    player, cut = sorted(frame.joints_cam, key=lambda j: float(np.nanmean(j[:, 0])))
    assert np.isfinite(player).all()
    assert np.isnan(cut[list(FEET)]).all()
    assert np.isfinite(cut[[0, 11, 12, 23, 24]]).all()  # his face, shoulders and hips are seen
    assert frame.unseen >= len(FEET)
    cal = Calibrator(HacParams(joint_layout='blazepose33', cone_min_points=1))
    cal.add_camera_info(K, 640, 480)
    cal.add_map(10**9, floor_points(), 'map')
    outs = []
    rng = np.random.default_rng(1)  # a static camera, its SLAM pose jittering (never frozen)
    for k in range(12):
        stamp = (2 + k) * 10**9
        outs += cal.add_pose(stamp, np.eye(3), rng.normal(0.0, 1e-5, 3), 'map')
        outs += cal.add_joints(stamp, np.stack([player, cut]).reshape(-1, 3), 'camera')
    outs += cal.flush()
    samples = [o for o in outs if isinstance(o, SampleOut)]
    assert cal.rejected['contact_unseen'] == 12
    assert {o.person for o in samples if o.source == 'contact_unseen'} == {1}
    assert {o.person for o in samples if np.isfinite(o.scale)} == {0}  # once down is known
