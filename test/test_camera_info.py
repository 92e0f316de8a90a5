"""CameraInfo to the K of the images on the topic: REP-104's ROI and binning, the rectified
camera (P), and the principal-point check that catches a K made for another image size."""
from __future__ import annotations

import numpy as np
import pytest

import msg_adapters as ma
from msg_adapters import MessageError

K_FULL = np.array([[525.0, 0.0, 319.5], [0.0, 525.0, 239.5], [0.0, 0.0, 1.0]])


def camera_info(K=K_FULL, width=640, height=480, binning=(0, 0), roi=(0, 0, 0, 0), P=None):
    """A rosbags CameraInfo of a 640 x 480 sensor; roi (x_offset, y_offset, width, height)."""
    t = ma.rosbags_types()
    msg = ma.intrinsics_to_camera_info(np.asarray(K, dtype=float), width, height, 0, 'cam', t)
    msg.binning_x, msg.binning_y = binning
    msg.roi.x_offset, msg.roi.y_offset, msg.roi.width, msg.roi.height = roi
    if P is not None:
        msg.p = np.asarray(P, dtype=float).reshape(12)
    return msg


def test_a_plain_camera_info_gives_its_k_and_size():
    K, width, height = ma.camera_info_to_intrinsics(camera_info())
    assert (width, height) == (640, 480)
    np.testing.assert_array_equal(K, K_FULL)


def test_binning_and_roi_are_applied_as_image_geometry_does():
    # 2 x 2 binning: a 320 x 240 image, focal and principal point halved
    K, width, height = ma.camera_info_to_intrinsics(camera_info(binning=(2, 2)))
    assert (width, height) == (320, 240)
    np.testing.assert_allclose(K[:2], [[262.5, 0, 159.75], [0, 262.5, 119.75]])
    # a 400 x 300 ROI at (100, 80): the principal point moves by the offset, the focal stays
    K, width, height = ma.camera_info_to_intrinsics(camera_info(roi=(100, 80, 400, 300)))
    assert (width, height) == (400, 300)
    np.testing.assert_allclose(K[:2], [[525, 0, 219.5], [0, 525, 159.5]])
    # both: the ROI first, then the binning (REP-104)
    K, width, height = ma.camera_info_to_intrinsics(camera_info(binning=(2, 2),
                                                                roi=(100, 80, 400, 300)))
    assert (width, height) == (200, 150)
    np.testing.assert_allclose(K[:2], [[262.5, 0, 109.75], [0, 262.5, 79.75]])


def test_rectified_takes_the_projection_not_k():
    P = np.c_[[[510.0, 0, 322], [0, 512, 236], [0, 0, 1]], np.zeros(3)]
    K, _, _ = ma.camera_info_to_intrinsics(camera_info(P=P), rectified=True)
    np.testing.assert_array_equal(K, P[:, :3])
    K, _, _ = ma.camera_info_to_intrinsics(camera_info(P=P))
    np.testing.assert_array_equal(K, K_FULL)


@pytest.mark.parametrize('kwargs, text', [
    ({'K': np.diag([525.0, 525.0, 1.0])}, 'principal point cx = 0'),  # cx = cy = 0
    ({'width': 320, 'height': 240}, 'principal point cx = 319.5'),  # the 640 x 480 K on 320 x 240
    ({'K': [[525, 0, 319.5], [0, 525, 470], [0, 0, 1]]}, 'principal point cy = 470'),
    ({'roi': (600, 0, 100, 480)}, 'does not fit the 640 x 480 sensor'),
    ({'roi': (0, 0, 100, 0)}, 'roi 100 x 0'),
])
def test_a_k_that_does_not_fit_the_image_is_a_message_error(kwargs, text):
    with pytest.raises(MessageError, match=text):
        ma.camera_info_to_intrinsics(camera_info(**kwargs))
