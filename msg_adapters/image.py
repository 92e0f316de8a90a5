"""``sensor_msgs/Image`` ↔ (H, W, 3) uint8 RGB, and ``CameraInfo``'s distortion.

Encodings read: ``rgb8``, ``bgr8``, ``mono8``, ``rgba8``, ``bgra8`` (each row ``step`` bytes,
padding ignored). Every malformed image raises :class:`ImageError`, a :class:`MessageError`
whose ``reason`` says which kind: ``wrong_encoding``, ``empty_image`` or ``corrupt_image``.
Compressed images need a decoder (OpenCV): ``hac_ros.people.images``.
"""
from __future__ import annotations

import operator
from typing import Any

import numpy as np

from msg_adapters.errors import MessageError
from msg_adapters.stamps import make_header
from msg_adapters.types import MessageTypes

# encoding -> (channels, the RGB channels' order in a pixel)
ENCODINGS = {'rgb8': (3, (0, 1, 2)), 'bgr8': (3, (2, 1, 0)), 'mono8': (1, (0, 0, 0)),
             'rgba8': (4, (0, 1, 2)), 'bgra8': (4, (2, 1, 0))}


class ImageError(MessageError):
    """An image that cannot be read; ``reason``: ``wrong_encoding``, ``empty_image`` or
    ``corrupt_image``."""

    def __init__(self, reason: str, text: str) -> None:
        super().__init__(text)
        self.reason = reason


def image_to_rgb(msg: Any) -> np.ndarray:
    """Image → (height, width, 3) uint8 RGB: a read-only view of the message's bytes for
    unpadded rgb8, a copy otherwise."""
    try:
        encoding, height, width = str(msg.encoding).lower(), msg.height, msg.width
        step, data = msg.step, msg.data
    except AttributeError as exc:
        raise ImageError('corrupt_image', f'Image: expected encoding, height, width, step and '
                         f'data ({exc})') from exc
    if encoding not in ENCODINGS:
        raise ImageError('wrong_encoding', f'Image: encoding {encoding!r} is not one of '
                         f'{", ".join(ENCODINGS)}')
    try:
        height, width, step = (operator.index(v) for v in (height, width, step))
    except TypeError as exc:
        raise ImageError('corrupt_image', f'Image: height, width and step must be integers '
                         f'({exc})') from exc
    if height <= 0 or width <= 0:
        raise ImageError('empty_image', f'Image: {width} x {height} pixels')
    channels, order = ENCODINGS[encoding]
    try:
        raw = np.frombuffer(memoryview(data).cast('B'), dtype=np.uint8)  # no copy
    except (TypeError, ValueError) as exc:
        raise ImageError('corrupt_image', f'Image: data is not bytes ({exc})') from exc
    if step < width * channels or len(raw) < step * (height - 1) + width * channels:
        raise ImageError('corrupt_image', f'Image: {len(raw)} bytes for {width} x {height} '
                         f'{encoding} with step {step}')
    rows = np.lib.stride_tricks.as_strided(raw, shape=(height, width, channels),
                                           strides=(step, channels, 1), writeable=False)
    if channels == 1:
        return np.repeat(rows, 3, axis=2)
    rgb = rows[:, :, :3] if order == (0, 1, 2) else rows[:, :, 2::-1]
    return np.ascontiguousarray(rgb)  # no copy for unpadded rgb8: a read-only view


def rgb_to_image(rgb: np.ndarray, stamp_ns: int, frame_id: str, types: MessageTypes,
                 encoding: str = 'rgb8') -> Any:
    """(H, W, 3) uint8 RGB → Image of ``encoding`` (rgb8, bgr8 or mono8: the mean of the three
    channels), rows unpadded."""
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise MessageError(f'rgb_to_image: expected (H, W, 3) uint8, got {rgb.shape} {rgb.dtype}')
    if encoding == 'mono8':
        pixels = rgb.mean(axis=2).round().astype(np.uint8)[:, :, None]
    elif encoding in ('rgb8', 'bgr8'):
        pixels = rgb if encoding == 'rgb8' else rgb[:, :, ::-1]
    else:
        raise MessageError(f'rgb_to_image: encoding rgb8, bgr8 or mono8, not {encoding!r}')
    height, width, channels = pixels.shape
    data = np.ascontiguousarray(pixels).reshape(-1)
    return types.get('sensor_msgs/msg/Image')(
        header=make_header(stamp_ns, frame_id, types), height=height, width=width,
        encoding=encoding, is_bigendian=0, step=width * channels,
        data=data if types.is_rosbags else data.tobytes())


def camera_info_distortion(msg: Any) -> tuple[str, np.ndarray]:
    """CameraInfo → (distortion_model, D (N,) float64); MessageError when D is not numbers."""
    try:
        model, d = str(msg.distortion_model), msg.d
        values = np.array(list(d), dtype=float)
    except (AttributeError, TypeError, ValueError) as exc:
        raise MessageError(f'CameraInfo: expected distortion_model and d as numbers ({exc})'
                           ) from exc
    return model, values
