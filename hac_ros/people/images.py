"""Images as (H, W, 3) uint8 RGB: from ``sensor_msgs/Image`` (:mod:`msg_adapters.image`), from
``sensor_msgs/CompressedImage`` (JPEG decoded by simplejpeg, which reports corrupt data that
OpenCV's decoder only prints and decodes anyway; PNG by OpenCV), and from files and videos for
``hac people``. A message that cannot be read raises
:class:`~msg_adapters.image.ImageError` with its reason (``wrong_encoding``, ``empty_image``,
``corrupt_image``).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from hac_ros.people.extra import require
from msg_adapters.image import ImageError, image_to_rgb

COMPRESSED_FORMATS = ('jpeg', 'jpg', 'png')
JPEG_MAGIC = b'\xff\xd8'  # a JPEG's first bytes (SOI)
IMAGE_SUFFIXES = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff', '.webp', '.pgm', '.ppm')


def compressed_to_rgb(msg: Any) -> np.ndarray:
    """CompressedImage (``format`` names jpeg or png; image_transport's "bgr8; jpeg compressed
    bgr8" form too) → (H, W, 3) uint8 RGB."""
    _, cv2 = require()
    try:
        fmt, data = str(msg.format).lower(), msg.data
        raw = np.frombuffer(memoryview(data).cast('B'), dtype=np.uint8)
    except (AttributeError, TypeError, ValueError) as exc:
        raise ImageError('corrupt_image', f'CompressedImage: expected format and data bytes '
                         f'({exc})') from exc
    if fmt and not any(name in fmt for name in COMPRESSED_FORMATS):
        raise ImageError('wrong_encoding', f'CompressedImage: format {fmt!r} is not JPEG or PNG')
    if not len(raw):
        raise ImageError('empty_image', 'CompressedImage: no data')
    if raw[:2].tobytes() == JPEG_MAGIC:
        import simplejpeg

        try:
            return simplejpeg.decode_jpeg(raw, colorspace='RGB', strict=True)
        except ValueError as exc:  # strict: libjpeg's "Corrupt JPEG data" warnings too
            raise ImageError('corrupt_image', f'CompressedImage: a JPEG of {len(raw)} bytes '
                             f'that the decoder reports corrupt ({exc})') from exc
    bgr = cv2.imdecode(raw, cv2.IMREAD_COLOR)
    if bgr is None or not bgr.size:
        raise ImageError('corrupt_image', f'CompressedImage: {len(raw)} bytes that do not '
                         f'decode as {fmt or "an image"}')
    return np.ascontiguousarray(bgr[:, :, ::-1])


def message_to_rgb(msg: Any, compressed: bool) -> np.ndarray:
    """An Image or a CompressedImage → (H, W, 3) uint8 RGB."""
    return compressed_to_rgb(msg) if compressed else image_to_rgb(msg)


def rgb_to_jpeg(rgb: np.ndarray, quality: int = 95) -> bytes:
    """(H, W, 3) uint8 RGB → JPEG bytes (for a CompressedImage)."""
    _, cv2 = require()
    ok, data = cv2.imencode('.jpg', np.ascontiguousarray(rgb[:, :, ::-1]),
                            [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ImageError('corrupt_image', 'rgb_to_jpeg: OpenCV could not encode the image')
    return bytes(data)
