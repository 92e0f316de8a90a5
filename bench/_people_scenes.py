"""Real images of people for the people benchmarks and tests: Debian's opencv-doc samples
(``apt-get install opencv-doc``; BSD-3-Clause / Apache-2.0, OpenCV's samples/data), and images
composed from them. Each image is (H, W, 3) uint8 RGB.
"""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

OPENCV_DATA = Path('/usr/share/doc/opencv-doc/examples/data')
STILLS = ('basketball1.png', 'basketball2.png', 'messi5.jpg')
VIDEO = 'vtest.avi'


def still(name: str) -> np.ndarray:
    import cv2

    bgr = cv2.imread(str(OPENCV_DATA / name))
    if bgr is None:
        raise FileNotFoundError(f'{OPENCV_DATA / name} (apt-get install opencv-doc)')
    return np.ascontiguousarray(bgr[:, :, ::-1])


def four_standing() -> np.ndarray:
    """640 x 480 with four people standing side by side, each about 370 px tall: the basketball
    player of basketball1.png and the left player of basketball2.png (160 px wide strips around
    each), and the two mirrored."""
    b1, b2 = still('basketball1.png'), still('basketball2.png')
    strips = [b1[:, 20:180], b2[:, 20:180], b1[:, ::-1][:, 460:620], b2[:, ::-1][:, 460:620]]
    return np.ascontiguousarray(np.hstack(strips))


def grid_of_stills() -> np.ndarray:
    """640 x 480: basketball1, basketball2, messi5 and basketball1 mirrored, each scaled to
    320 x 240 in a 2 x 2 grid: five people 130-190 px tall, one of them seen from behind with his
    legs out of the image."""
    import cv2

    b1, b2, messi = still('basketball1.png'), still('basketball2.png'), still('messi5.jpg')
    tiles = [cv2.resize(img, (320, 240), interpolation=cv2.INTER_AREA)
             for img in (b1, b2, messi, np.ascontiguousarray(b1[:, ::-1]))]
    return np.ascontiguousarray(np.vstack([np.hstack(tiles[:2]), np.hstack(tiles[2:])]))


def video_frames(step: int = 1, limit: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """(index, frame) of vtest.avi (768 x 576, 10 Hz, 795 frames: a static camera above a paved
    square, pedestrians 60-130 px tall), every ``step``-th."""
    import cv2

    video = cv2.VideoCapture(str(OPENCV_DATA / VIDEO))
    if not video.isOpened():
        raise FileNotFoundError(f'{OPENCV_DATA / VIDEO} (apt-get install opencv-doc)')
    index = 0
    try:
        while limit is None or index < limit:
            ok, bgr = video.read()
            if not ok:
                return
            if index % step == 0:
                yield index, np.ascontiguousarray(bgr[:, :, ::-1])
            index += 1
    finally:
        video.release()
