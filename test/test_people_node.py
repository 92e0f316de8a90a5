"""hac_people_node over real DDS (test_people.py's Graph: real rclpy nodes, MediaPipe, Debian's
opencv-doc images): camera images through it into hac_node, whose scale is the one the lifted
feet imply; bad images counted under their reasons, never a crash; the rate cap by stamp;
compressed images decoded or their fault named."""
from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from test_people import FLOOR_SLAM, Graph, K, floor_points, implied_scale, people_of, wait_for


# ---------------------------------------------------------------------------- over DDS
@pytest.mark.parametrize('transport', ['raw', 'compressed'])
def test_people_node_feeds_hac_node_over_dds(people_extra, opencv_images, transport):
    """Camera images (Image, or CompressedImage JPEG) → hac_people_node → hac_node, with a static
    SLAM camera and a floor map FLOOR_SLAM units below it: every image gives joints with its
    stamp, hac_node takes them (no joints_* rejection), converges on accepted samples, and its
    scale is within 1 % of the one the lifted feet imply (the median over the people whose feet
    are seen: basketball2's man on the right, cut by the image's edge, has none, and hac_node
    counts him contact_unseen)."""
    from msg_adapters import intrinsics_to_camera_info, rt_to_pose_stamped, xyz_to_cloud

    graph = Graph({'image_transport': transport, 'max_rate_hz': 0.0},
                  {'joint_layout': 'blazepose33', 'input_qos': 'reliable',
                   'joints_backlog_max': 1000})
    try:
        types = graph.types
        graph.pub['cloud'].publish(xyz_to_cloud(floor_points(), 1_000_000_000, 'map', types))
        rng = np.random.default_rng(1)
        order = ['basketball1.png', 'basketball2.png'] * 10
        stamps = [2_000_000_000 + k * 200_000_000 for k in range(len(order))]
        graph.camera_info(stamps[0])
        for name, stamp in zip(order, stamps):
            graph.pub['camera_info'].publish(intrinsics_to_camera_info(
                K, 640, 480, stamp, 'camera_optical', types))
            graph.pub['pose'].publish(rt_to_pose_stamped(
                np.eye(3), rng.normal(0.0, 1e-5, 3), stamp, 'map', types))
            before = len(graph.received['joints'])
            graph.image(opencv_images[name], stamp, compressed=transport == 'compressed')
            assert wait_for(lambda b=before: len(graph.received['joints']) > b), \
                'hac_people_node did not answer an image'
        assert [int(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec)
                for m in graph.received['joints']] == stamps
        assert all(m.header.frame_id == 'camera_optical' for m in graph.received['joints'])
        people = [p for m in graph.received['joints'] for p in people_of(m)]
        assert len(people) == 30  # one person, then two, ten times
        assert wait_for(lambda: graph.received['scale'])
        hac_status = {}

        def hac_caught_up() -> bool:
            for msg in reversed(graph.received['diagnostics']):
                for status in msg.status:
                    values = {kv.key: kv.value for kv in status.values}
                    if 'samples' in values and int(values.get('frames', 0)) >= len(order):
                        hac_status.update(values)
                        return True
            return False
        assert wait_for(hac_caught_up), 'hac_node did not process every frame'
        assert not [k for k in hac_status if k.startswith('rejected.joints_')], hac_status
        assert int(hac_status['samples']) >= 10, sorted(hac_status.items())
        expected = implied_scale(people, FLOOR_SLAM)
        scale = graph.received['scale'][-1].data
        assert abs(scale / expected - 1) < 0.01, (scale, expected)
        assert wait_for(lambda: graph.status().get('images_processed') == str(len(order)))
    finally:
        graph.close()


def test_bad_input_is_counted_under_its_reason_never_a_crash(people_extra, opencv_images):
    """No CameraInfo yet, a wrong encoding, an empty image, bytes that do not match the size, a
    CameraInfo of another size, then a burst faster than the node: each counted under its reason
    in /diagnostics (WARN naming it), nothing published for them, the newest of the burst taken,
    and every image received accounted for."""
    from msg_adapters.image import rgb_to_image

    graph = Graph({'max_rate_hz': 0.0, 'person_detector': 'none'})
    try:
        types = graph.types
        rgb = opencv_images['basketball1.png']
        stamp = iter(range(5_000_000_000, 10**11, 100_000_000))
        graph.image(rgb, next(stamp))  # before any CameraInfo
        assert wait_for(lambda: graph.status().get('rejected.no_camera_info') == '1')
        assert graph.status()['camera_info'] == 'none'
        graph.camera_info(next(stamp))
        bad = rgb_to_image(rgb, next(stamp), 'camera_optical', types)
        bad.encoding = '16UC1'
        empty = rgb_to_image(rgb, next(stamp), 'camera_optical', types)
        empty.height = empty.width = empty.step = 0
        empty.data = b''
        short = rgb_to_image(rgb, next(stamp), 'camera_optical', types)
        short.data = bytes(short.data)[:1000]
        small = rgb_to_image(rgb[:240, :320].copy(), next(stamp), 'camera_optical', types)
        for msg, reason in ((bad, 'wrong_encoding'), (empty, 'empty_image'),
                            (short, 'corrupt_image'), (small, 'camera_info_size_mismatch')):
            graph.pub['image'].publish(msg)  # one at a time: a newer image would replace it
            assert wait_for(lambda r=reason: graph.status().get(f'rejected.{r}') == '1'), reason
        assert graph.received['joints'] == []
        warn = [m.status[0] for m in graph.received['diagnostics']
                if m.status[0].name.startswith('hac_people_node') and m.status[0].level == b'\x01']
        assert any('wrong_encoding' in s.message for s in warn)
        # a burst: published back to back, faster than the model; the newest is always taken
        burst = [next(stamp) for _ in range(8)]
        for s in burst:
            graph.image(rgb, s)
        assert wait_for(lambda: graph.received['joints']
                        and graph.received['joints'][-1].header.stamp.sec * 10**9
                        + graph.received['joints'][-1].header.stamp.nanosec == burst[-1])
        # each image is received by the node, or lost by the middleware before it (counted)
        assert wait_for(lambda: int(graph.status().get('images_received', 0))
                        + int(graph.status().get('dropped.lost', 0)) == 13), graph.status()
        status = graph.status()
        rejected = sum(int(v) for k, v in status.items() if k.startswith('rejected.'))
        processed = int(status['images_processed'])
        overload = int(status.get('dropped.overload', 0))
        lost = int(status.get('dropped.lost', 0))
        assert rejected == 5 and processed + overload + lost == 8 and overload >= 1
        assert processed == len(graph.received['joints'])
    finally:
        graph.close()


def test_the_rate_cap_skips_images_by_stamp(people_extra, opencv_images):
    """max_rate_hz 2 over images stamped 0.1 s apart: one in five is processed, the others are
    counted under dropped.rate_cap; a stamp that jumps back (a replay started again) is counted
    stamp_backwards and capped by arrival time: it arrives over 0.5 s after the last one taken,
    so it passes."""

    graph = Graph({'max_rate_hz': 2.0, 'person_detector': 'none'})
    try:
        graph.camera_info(1)
        stamps = [10_000_000_000 + k * 100_000_000 for k in range(10)] + [1_000_000_000]
        for s in stamps:
            if s == stamps[-1]:
                wait_for(lambda: False, timeout=0.6)  # a lower bound: a slow host adds to it
            before = int(graph.status().get('images_received', 0))
            graph.image(opencv_images['basketball1.png'], s)
            # one at a time: the slot never holds two, so only the cap decides
            assert wait_for(lambda b=before: int(graph.status().get('images_received', 0)) > b
                            and graph.status().get('images_processed', '0')
                            == str(len(graph.received['joints'])))
        assert wait_for(lambda: len(graph.received['joints']) == 3)
        assert [m.header.stamp.sec for m in graph.received['joints']] == [10, 10, 1]
        assert graph.status()['dropped.rate_cap'] == '8'
        assert graph.status()['stamp_backwards'] == '1'
    finally:
        graph.close()


def test_compressed_images_decode_or_name_their_fault(people_extra, opencv_images):
    """CompressedImage: JPEG and PNG (image_transport's "bgr8; jpeg compressed bgr8" format too)
    decode to RGB; another format, no bytes or bytes that do not decode raise ImageError with the
    reason the node counts."""
    import cv2

    from hac_ros.people.images import compressed_to_rgb, rgb_to_jpeg
    from msg_adapters import rclpy_types
    from msg_adapters.image import ImageError
    from msg_adapters.stamps import make_header

    types = rclpy_types()
    rgb = opencv_images['messi5.jpg']

    def message(fmt: str, data: bytes) -> Any:
        return types.get('sensor_msgs/msg/CompressedImage')(
            header=make_header(1, 'camera_optical', types), format=fmt, data=data)

    png = bytes(cv2.imencode('.png', rgb[:, :, ::-1])[1])
    np.testing.assert_array_equal(compressed_to_rgb(message('png', png)), rgb)
    decoded = compressed_to_rgb(message('bgr8; jpeg compressed bgr8', rgb_to_jpeg(rgb)))
    assert decoded.shape == rgb.shape and np.abs(decoded.astype(int) - rgb).mean() < 4
    for fmt, data, reason in (('theora', png, 'wrong_encoding'), ('jpeg', b'', 'empty_image'),
                              ('jpeg', png[:200], 'corrupt_image')):
        with pytest.raises(ImageError) as error:
            compressed_to_rgb(message(fmt, data))
        assert error.value.reason == reason
