"""A video or a folder of images played as a camera by ``hac play`` (:mod:`hac_ros.ros.player`),
the way ROS's image_publisher does: what the input is (:func:`input_kind`), and its frames as
``sensor_msgs`` Image (or JPEG CompressedImage) and CameraInfo messages (:class:`CameraFrames`).
Frame i is stamped ``start + i / fps`` (the video's rate, or ``fps``), as ``hac people`` stamps
it, counted over every pass of a loop. OpenCV (the ``[people]`` extra) reads the frames, imported
only when a video or a folder is played.
"""
from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from hac_ros.core.basics.errors import ArgumentError, HacError, InputError
from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.printable import printable
from msg_adapters import rclpy_types

# a video or a folder of images, played as a camera (CameraFrames)
RECORDING, VIDEO, IMAGES = 'recording', 'video', 'folder of images'
RECORDING_SUFFIXES = ('.bag', '.mcap', '.db3')  # a file read as a recording
STORAGE_SUFFIXES = ('.db3', '.mcap')  # a folder holding one is a recording (maybe cut off)
# a file of these is a video even where OpenCV is missing (to say it is needed); another file is
# one when OpenCV opens it
VIDEO_SUFFIXES = ('.avi', '.mp4', '.m4v', '.mkv', '.mov', '.webm', '.mpg', '.mpeg', '.wmv',
                  '.flv', '.ogv', '.3gp', '.ts', '.mjpeg', '.mjpg', '.h264', '.h265', '.gif')
IMAGE_TOPIC = '/camera/image_raw'
COMPRESSED_TOPIC = '/camera/image_raw/compressed'
CAMERA_INFO_TOPIC = '/camera/camera_info'
IMAGE_MSGTYPE = 'sensor_msgs/msg/Image'
COMPRESSED_MSGTYPE = 'sensor_msgs/msg/CompressedImage'
CAMERA_INFO_MSGTYPE = 'sensor_msgs/msg/CameraInfo'
COMPRESSED_FORMAT = 'rgb8; jpeg compressed bgr8'  # compressed_image_transport's form for rgb8
CAMERA_DEPTH = 10  # as hac_people_node subscribes (reliable, depth 10)
DEFAULT_FRAME_ID = 'camera_optical'
DEFAULT_START_S = 1.0  # frame 0's stamp: a ROS stamp of 0 means "not set" (stamp_zero)
CAMERA_FORMS = ('fx,fy,cx,cy[,k1,k2,p1,p2] (pixels; plumb_bob distortion) or '
                'fx,fy,cx,cy,width,height')
MAX_STAMP_S = 2**31 - 1  # builtin_interfaces/Time's int32 seconds


def input_kind(path: str | Path) -> str:
    """What ``path`` is: :data:`VIDEO` (a file OpenCV reads; a file with a video's suffix even
    where OpenCV is missing, so that the caller can say it is needed), :data:`IMAGES` (a folder
    with neither ``metadata.yaml`` nor a storage file), else :data:`RECORDING` (as before: a rosbag2
    folder, a .mcap, .db3 or .bag file, or a path that does not exist)."""
    path = Path(path)
    if path.is_dir():
        if (path / 'metadata.yaml').exists() or any(
                p.suffix.lower() in STORAGE_SUFFIXES for p in path.iterdir()):
            return RECORDING
        return IMAGES
    if not path.is_file() or path.suffix.lower() in RECORDING_SUFFIXES:
        return RECORDING
    if path.suffix.lower() in VIDEO_SUFFIXES:
        return VIDEO
    return VIDEO if _opencv_opens(path) else RECORDING


def _opencv_opens(path: Path) -> bool:
    from hac_ros.people.offline import FrameSource

    try:
        source = FrameSource(path)
    except HacError:  # not a video, or no OpenCV
        return False
    source.close()
    return True


def _open_frames(path: Path, kind: str) -> Any:
    """hac_ros.people.offline.FrameSource of ``path``; errors say what ``path`` was taken for."""
    from hac_ros.people.images import IMAGE_SUFFIXES
    from hac_ros.people.offline import FrameSource

    if kind == IMAGES and not any(p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()
                                  for p in path.iterdir()):
        raise ArgumentError(f'{printable(path)}: neither a recording (no metadata.yaml) nor a '
                            f'folder of images (none of {", ".join(IMAGE_SUFFIXES)} in it)')
    try:
        return FrameSource(path)
    except ArgumentError as exc:
        raise ArgumentError(f'{printable(path)}: not a {kind} OpenCV can read, nor a recording '
                            f'({exc})') from exc
    except HacError as exc:  # the [people] extra is missing (ExtraMissing, said as it is)
        raise type(exc)(f'{printable(path)} is a {kind}: playing it as a camera needs OpenCV: '
                        f'{exc}') from exc


class CameraFrames:
    """A video's or a folder of images' frames as a camera's messages (the module docstring).

    camera: ``fx,fy,cx,cy[,k1,k2,p1,p2]`` or ``fx,fy,cx,cy,width,height`` pixels
    (:func:`hac_ros.people.offline.parse_camera`; the size, when given, must be the frames');
    fps: frames per second (default: the video's; a folder needs it); start: frame 0's stamp,
    seconds; frame_id: the headers'; compressed: a JPEG CompressedImage instead of an Image.
    ArgumentError naming ``camera``, ``fps`` or ``start``; without OpenCV, the [people] extra's
    ExtraMissing."""

    def __init__(self, path: str | Path, kind: str, *, camera: str | None,
                 fps: float | None = None, start: float = DEFAULT_START_S,
                 frame_id: str = DEFAULT_FRAME_ID, compressed: bool = False) -> None:
        self.path, self.kind = Path(path), kind
        if not camera:
            raise ArgumentError(f'{{camera}} is needed to play {printable(self.path)} (a {kind}): '
                                f'its intrinsics, {CAMERA_FORMS}', 'camera')
        from hac_ros.people.offline import check_camera, parse_camera

        self.K, self.D, size = parse_camera(camera)
        self.source = _open_frames(self.path, kind)
        try:
            self.fps = self._rate(fps)
            if not (math.isfinite(start) and 0.0 <= start <= MAX_STAMP_S):
                raise ArgumentError(f'{{start}} {start!r}: expected seconds >= 0 (a ROS stamp)',
                                    'start')
            self.start_ns = round(start * NS)
            self.frame_id, self.compressed = str(frame_id), bool(compressed)
            self.index = 0  # the next frame's, counted over every pass
            self._pass: Iterator[np.ndarray] | None = iter(self.source.frames())
            first = next(self._pass, None)
            if first is None:
                raise InputError(f'{printable(self.path)}: no frame OpenCV can read')
            self._first: np.ndarray | None = first
            self.height, self.width = (int(n) for n in first.shape[:2])
            check_camera(printable(camera), self.K, size, self.width, self.height,
                         Path(printable(self.path)))
        except BaseException:
            self.close()
            raise
        image = (COMPRESSED_TOPIC, COMPRESSED_MSGTYPE) if compressed else (IMAGE_TOPIC,
                                                                           IMAGE_MSGTYPE)
        # the CameraInfo before its image: a node has the camera when the image comes
        self.topics = dict([(CAMERA_INFO_TOPIC, CAMERA_INFO_MSGTYPE), image])

    def _rate(self, fps: float | None) -> float:
        if fps is not None:
            if not 0.0 < float(fps) < float('inf'):
                raise ArgumentError(f'{{fps}} {fps!r}: expected frames per second > 0', 'fps')
            return float(fps)
        if not (math.isfinite(self.source.fps) and self.source.fps > 0):
            what = ('a folder of images' if self.kind == IMAGES
                    else 'a video that does not say its rate')
            raise ArgumentError(f'{{fps}} is needed for {printable(self.path)} ({what}): frames '
                                'per second (frame i is stamped start + i / fps)', 'fps')
        return float(self.source.fps)

    def describe(self) -> str:
        return (f'a {self.kind} of {self.width} x {self.height} frames at {self.fps:g} fps, frame '
                f'i stamped {self.start_ns / NS:g} + i / {self.fps:g} s')

    def stamp_ns(self, index: int) -> int:
        """Frame ``index``'s stamp (counted over every pass), integer nanoseconds."""
        return self.start_ns + round(index * NS / self.fps)

    def _frames(self) -> Iterator[np.ndarray]:
        """One pass: the frames from the first (the video opened again after the first pass)."""
        if self._first is not None:
            first, self._first = self._first, None
            yield first
            assert self._pass is not None
            yield from self._pass
            return
        self.close()
        self.source = _open_frames(self.path, self.kind)
        yield from self.source.frames()

    def messages(self, topics: Sequence[str]) -> Iterator[tuple[int, list[tuple[str, Any]]]]:
        """One pass over the frames: (stamp ns, [(topic, message)] of ``topics`` among
        :attr:`topics`) per frame, stamps going on from the last pass's."""
        from hac_ros.people.images import rgb_to_jpeg
        from msg_adapters import intrinsics_to_camera_info, make_header
        from msg_adapters.image import rgb_to_image

        types = rclpy_types()
        d = [*self.D.tolist(), 0.0] if len(self.D) else None  # plumb_bob: k1 k2 t1 t2 k3
        for n, rgb in enumerate(self._frames()):
            if rgb.shape[:2] != (self.height, self.width):
                raise InputError(f'{printable(self.path)}: frame {n} is {rgb.shape[1]} x '
                                 f'{rgb.shape[0]}, the first {self.width} x {self.height}: one '
                                 'camera, one size')
            stamp = self.stamp_ns(self.index)
            if stamp // NS > MAX_STAMP_S:
                raise InputError(f'{printable(self.path)}: frame {self.index} would be stamped '
                                 f'{stamp / NS:.0f} s, beyond a ROS stamp\'s int32 seconds')
            self.index += 1
            out: list[tuple[str, Any]] = []
            for topic in topics:
                if topic == CAMERA_INFO_TOPIC:
                    msg = intrinsics_to_camera_info(self.K, self.width, self.height, stamp,
                                                    self.frame_id, types)
                    if d is not None:
                        msg.d = d
                elif topic == COMPRESSED_TOPIC:
                    msg = types.get(COMPRESSED_MSGTYPE)(
                        header=make_header(stamp, self.frame_id, types),
                        format=COMPRESSED_FORMAT, data=rgb_to_jpeg(rgb))
                else:
                    msg = rgb_to_image(rgb, stamp, self.frame_id, types)
                out.append((topic, msg))
            yield stamp, out

    def close(self) -> None:
        source = getattr(self, 'source', None)
        if source is not None:
            source.close()
