"""``hac people VIDEO|IMAGE_DIR``: metric people from a video or a folder of images, as the joints
file ``hac import --joints`` takes (docs/people.md, "Offline: `hac people`").

Each frame goes through the same model and lifting as ``hac_people_node``
(:class:`~hac_ros.people.frontend.PeopleFromImages`); the file holds ``stamps`` (T,) float seconds
and ``joints`` (T, P, 33, 3) metres in the camera optical frame, ``blazepose33`` order, an all-NaN
block where a person is absent (P: the most people in one frame). Frame i is stamped ``start + i /
fps`` seconds, or with the i-th stamp of a stamps file (the first column of each line, ``#``
comments skipped: a TUM trajectory of the same frames works), so that the joints meet the
trajectory's poses exactly.
"""
from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hac_ros.core.basics.errors import ArgumentError, HacError, InputError
from hac_ros.core.layouts.blazepose33 import LAYOUT
from hac_ros.people.extra import require
from hac_ros.people.frontend import PeopleFromImages, size_matches
from hac_ros.people.images import IMAGE_SUFFIXES
from hac_ros.people.lifting import Camera
from hac_ros.people.params import PeopleParams
from hac_ros.progress import Progress, progress_pass
from hac_ros.recording.atomic import staged_output
from msg_adapters.camera_info import principal_point_problem


@dataclass
class PeopleResult:
    """What ``hac people`` wrote: the file, its frames, the people in them, and the people the
    lifting dropped by reason."""

    path: Path
    frames: int
    width: int
    height: int
    people: int = 0
    frames_with_people: int = 0
    most_people: int = 0
    from_crops: int = 0
    too_small: int = 0  # frames smaller than the person detector's window
    unseen: int = 0  # landmarks written NaN: not seen
    dropped: Counter[str] = field(default_factory=Counter)

    def text(self) -> str:
        dropped = ', '.join(f'{n} {reason}' for reason, n in sorted(self.dropped.items()))
        return (f'wrote {self.path}: {self.frames} frames ({self.width} x {self.height}), '
                f'{self.people} people in {self.frames_with_people} of them (at most '
                f'{self.most_people} in one, {self.from_crops} from the person detector\'s '
                f'crops; {self.unseen} landmarks not seen, NaN); joint_layout blazepose33'
                + (f'; dropped: {dropped}' if dropped else '')
                + (f'; {self.too_small} frames too small for the person detector (no '
                   'person of person_min_height_px fits: only the landmarker looked)'
                   if self.too_small else ''))


CAMERA_FORMS = ('fx,fy,cx,cy[,k1,k2,p1,p2] (pixels; plumb_bob distortion) or '
                'fx,fy,cx,cy,width,height (hac import\'s form)')


def parse_camera(text: str) -> tuple[np.ndarray, np.ndarray, tuple[int, int] | None]:
    """``fx,fy,cx,cy[,k1,k2,p1,p2]`` (pixels; plumb_bob) or ``hac import``'s
    ``fx,fy,cx,cy,width,height`` → (K (3, 3), D (4,) or (0,), (width, height) or None: the size
    the images must have)."""
    from hac_ros.files.readers import parse_camera as parse_sized

    parts = text.replace(',', ' ').split()
    if len(parts) == 6:
        K, width, height = parse_sized(text)
        return K, np.zeros(0), (width, height)
    try:
        values = [float(p) for p in parts]
        if len(values) not in (4, 8):
            raise ValueError(f'{len(values)} values')
    except ValueError as exc:
        raise ArgumentError(f'{{camera}} {text!r}: expected {CAMERA_FORMS} ({exc})',
                            'camera') from exc
    fx, fy, cx, cy = values[:4]
    if not (all(math.isfinite(v) for v in values) and fx > 0 and fy > 0):
        raise ArgumentError(f'{{camera}} {text!r}: fx and fy must be positive, all finite',
                            'camera')
    return (np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]), np.array(values[4:]),
            None)


def check_camera(text: str, K: np.ndarray, size: tuple[int, int] | None, width: int,
                 height: int, where: Path) -> None:
    """ArgumentError naming ``camera`` when the size given is not the frames' (``width`` x
    ``height`` of ``where``) or K's principal point is not inside them."""
    if size is not None and size != (width, height):
        raise ArgumentError(f'{{camera}} {text!r}: says {size[0]} x {size[1]}, the frames of '
                            f'{where} are {width} x {height}', 'camera')
    problem = principal_point_problem(K, width, height)
    if problem:
        raise ArgumentError(f'{{camera}} {text!r}: {problem}', 'camera')


def read_stamps(path: str | Path) -> np.ndarray:
    """The first column of each line of a text file (seconds; ``#`` comments and blank lines
    skipped): (N,) float64."""
    path = Path(path)
    if not path.is_file():
        raise ArgumentError(f'{{stamps}} {path} is not a file', 'stamps')
    stamps = []
    for number, line in enumerate(path.read_text(encoding='utf-8', errors='replace')
                                  .splitlines(), 1):
        line = line.strip()
        if not line or line.startswith('#'):
            continue
        try:
            stamps.append(float(line.replace(',', ' ').split()[0]))
        except ValueError as exc:
            raise ArgumentError(f'{{stamps}} {path} line {number}: {line[:40]!r} does not start '
                                'with a stamp in seconds', 'stamps') from exc
    values = np.array(stamps, dtype=float)
    if not len(values) or not np.isfinite(values).all() or (np.diff(values) <= 0).any():
        raise ArgumentError(f'{{stamps}} {path}: expected increasing finite stamps in seconds, '
                            'one per frame', 'stamps')
    return values


class FrameSource:
    """The frames of a video (any file OpenCV reads) or of a folder of images (sorted by name)."""

    def __init__(self, source: str | Path) -> None:
        _, self.cv2 = require()
        self.path = Path(source)
        self.files: list[Path] = []
        self.video: Any = None
        if self.path.is_dir():
            self.files = sorted(p for p in self.path.iterdir()
                                if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
            if not self.files:
                raise ArgumentError(f'{{source}} {self.path}: no image in it (one of '
                                    f'{", ".join(IMAGE_SUFFIXES)})', 'source')
            self.count, self.fps = len(self.files), math.nan
        elif self.path.is_file():
            self.video = self.cv2.VideoCapture(str(self.path))
            if not self.video.isOpened():
                raise ArgumentError(f'{{source}} {self.path}: not a video OpenCV can read',
                                    'source')
            self.count = int(self.video.get(self.cv2.CAP_PROP_FRAME_COUNT))
            self.fps = float(self.video.get(self.cv2.CAP_PROP_FPS)) or math.nan
        else:
            raise ArgumentError(f'{{source}} {self.path} does not exist', 'source')

    def close(self) -> None:
        """Releases the video (a folder holds nothing open)."""
        if self.video is not None:
            self.video.release()

    def frames(self) -> Iterator[np.ndarray]:
        """Each frame as (H, W, 3) uint8 RGB, in order."""
        if self.video is not None:
            while True:
                ok, bgr = self.video.read()
                if not ok:
                    return
                yield np.ascontiguousarray(bgr[:, :, ::-1])
        for path in self.files:
            bgr = self.cv2.imread(str(path), self.cv2.IMREAD_COLOR)
            if bgr is None:
                raise InputError(f'{path}: not an image OpenCV can read')
            yield np.ascontiguousarray(bgr[:, :, ::-1])


def people_from_images(source: str | Path, camera: str, output: str | Path,
                       fps: float | None = None, start: float = 0.0,
                       stamps: str | Path | None = None, params: PeopleParams | None = None,
                       progress: Progress | None = None) -> PeopleResult:
    """Write ``output`` (.npz, refused when it exists) with the metric people of every frame of
    ``source`` (a video file or a folder of images).

    camera: ``fx,fy,cx,cy[,k1,k2,p1,p2]`` pixels (the image size is the frames'), or
    ``fx,fy,cx,cy,width,height`` (the size checked against the frames'); fps: frames per
    second (default: the video's; a folder needs it or ``stamps``); start: the first frame's stamp,
    seconds; stamps: a file of one stamp per frame instead; params: the model's parameters
    (``model_path``, ``max_people``, ``person_detector``, the confidences).
    """
    from hac_ros.people.model import PoseModel

    target = Path(output)
    if target.exists() or target.is_symlink():
        raise HacError(f'{target} already exists: not overwritten (remove it or choose another '
                       'name)')
    K, D, size = parse_camera(camera)
    params = params or PeopleParams()
    frames = FrameSource(source)
    if stamps is not None:
        given = read_stamps(stamps)
        if frames.video is None and len(given) != frames.count:
            raise ArgumentError(f'{{stamps}} {stamps}: {len(given)} stamps for {frames.count} '
                                'images; one per image', 'stamps')
    else:
        rate = fps if fps is not None else frames.fps
        if rate is None or not math.isfinite(rate) or rate <= 0:
            raise ArgumentError(f'{{fps}} is needed for {frames.path} (a folder of images, or a '
                                'video that does not say its rate): frames per second, or give '
                                '{stamps}', 'fps', 'stamps')
        if not math.isfinite(start):
            raise ArgumentError('{start} must be finite seconds', 'start')
        given = None
    people = PeopleFromImages(PoseModel.from_params(params), params.landmark_min_visibility)
    per_frame: list[np.ndarray] = []
    result: PeopleResult | None = None
    camera_of: Camera | None = None
    try:
        with progress_pass(progress, frames.count, 'people') as bar:
            for i, rgb in enumerate(frames.frames()):
                if camera_of is None:
                    check_camera(camera, K, size, rgb.shape[1], rgb.shape[0], frames.path)
                    camera_of = Camera(K=K, width=rgb.shape[1], height=rgb.shape[0], D=D)
                    result = PeopleResult(target, 0, camera_of.width, camera_of.height)
                if not size_matches(rgb, camera_of):
                    raise InputError(f'{frames.path}: frame {i} is {rgb.shape[1]} x '
                                     f'{rgb.shape[0]}, the first {camera_of.width} x '
                                     f'{camera_of.height}: one camera, one size')
                frame = people.process(rgb, camera_of)
                assert result is not None
                per_frame.append(frame.joints_cam)
                result.people += len(frame.lifted)
                result.frames_with_people += int(len(frame.lifted) > 0)
                result.from_crops += frame.from_crop
                result.too_small += int(frame.too_small)
                result.unseen += frame.unseen
                result.dropped.update(frame.dropped)
                if bar is not None:
                    bar.update(1)
    finally:
        people.model.close()
    if result is None:
        raise InputError(f'{frames.path}: no frame')
    result.frames = len(per_frame)
    if given is not None and len(given) < result.frames:
        raise ArgumentError(f'{{stamps}} {stamps}: {len(given)} stamps for {result.frames} '
                            'frames; one per frame', 'stamps')
    seconds = (given[:result.frames] if given is not None
               else start + np.arange(result.frames) / float(fps if fps is not None
                                                             else frames.fps))
    result.most_people = max((len(j) for j in per_frame), default=0)
    if not result.people:
        small = (f'; the frames are {result.width} x {result.height}: too small for the person '
                 f'detector (no person of {params.person_min_height_px:g} px fits its window)'
                 if result.too_small else '')
        raise InputError(f'{frames.path}: nobody found in {result.frames} frames; nothing to '
                         'write (dropped by the lifting: '
                         f'{dict(result.dropped) or "none"}){small}')
    joints = np.full((result.frames, result.most_people, LAYOUT.joints_per_person, 3), np.nan)
    for i, found in enumerate(per_frame):
        joints[i, :len(found)] = found
    with staged_output(target) as staged, open(staged, 'wb') as handle:
        np.savez(handle, stamps=seconds, joints=joints)
    return result
