"""The stages of ``hac video`` before the calibration, each kept in the cache so that an
interrupted run resumes (docs/video.md, "Stages and the cache"): the keyframes, the people found in
them (and their masks), the reconstruction, and the inputs of ``hac import``.

A stage's directory appears in the cache whole, once the stage is done (written beside it and
renamed, :func:`hac_ros.recording.atomic.staged_output`), so a stage found there is complete.
"""
from __future__ import annotations

import json
import logging
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hac_ros.core.basics.errors import ArgumentError, InputError
from hac_ros.people.lifting import Camera
from hac_ros.people.model import Landmarks, PoseModel
from hac_ros.people.params import PeopleParams
from hac_ros.progress import Progress, progress_pass
from hac_ros.recording.atomic import staged_output
from hac_ros.video.keyframes import MotionKeyframes

log = logging.getLogger(__name__)

# a person's mask: their landmarks' box grown by these shares of its width (each side) and height
# (above: the head's top; below: the soles, so that the floor around the feet keeps its points)
MASK_MARGIN = (0.15, 0.12, 0.03)
POSED = ('covered', 'pose', 'duplicate')  # person detector outcomes whose person has a pose
STILL = 0.01  # the most median corner shift (share of the width) of a camera that never moved


@dataclass
class Keyframes:
    """The keyframes in a stage directory: ``names`` (N,) their image files there, ``index`` (N,)
    their frame numbers, ``stamps`` (N,) seconds, ``why``, ``frames`` in the video, ``fps``,
    ``width``, ``height`` pixels, ``most_motion`` the largest median corner shift seen between
    keyframes (share of the width)."""

    folder: Path
    names: list[str]
    index: list[int]
    stamps: list[float]
    why: list[str]
    frames: int
    fps: float
    width: int
    height: int
    most_motion: float

    @classmethod
    def load(cls, folder: Path) -> Keyframes:
        data = json.loads((folder / 'keyframes.json').read_text())
        return cls(folder=folder, **data)

    def save(self, folder: Path) -> None:
        data = {key: value for key, value in vars(self).items() if key != 'folder'}
        (folder / 'keyframes.json').write_text(json.dumps(data, indent=1))


def choose_keyframes(source: Path, target: Path, fps: float | None, start: float,
                     rate_hz: float | None, motion: float, progress: Progress | None
                     ) -> Keyframes:
    """Reads every frame of ``source`` once and writes the keyframes (PNG) into ``target``
    (:mod:`hac_ros.video.keyframes`). ``fps``: the video's when None (a folder needs it)."""
    from hac_ros.people.offline import FrameSource

    frames = FrameSource(source)
    rate = fps if fps is not None else frames.fps
    if rate is None or not math.isfinite(rate) or rate <= 0:
        frames.close()
        raise ArgumentError(f'{{fps}} is needed for {frames.path} (a folder of images, or a video '
                            'that does not say its rate): frames per second', 'fps')
    cv2 = frames.cv2
    chooser = MotionKeyframes(rate, motion=motion, rate_hz=rate_hz)
    names: list[str] = []
    size: tuple[int, int] | None = None
    last: np.ndarray | None = None
    with staged_output(target) as staged:
        staged.mkdir()
        try:
            with progress_pass(progress, frames.count, 'keyframes') as bar:
                for i, rgb in enumerate(frames.frames()):
                    if size is None:
                        size = (rgb.shape[1], rgb.shape[0])
                    elif (rgb.shape[1], rgb.shape[0]) != size:
                        raise InputError(f'{frames.path}: frame {i} is {rgb.shape[1]} x '
                                         f'{rgb.shape[0]}, the first {size[0]} x {size[1]}: one '
                                         'camera, one size')
                    if chooser.add(rgb):
                        names.append(_write(cv2, staged, i, rgb))
                        last = None
                    else:
                        last = rgb
                    if bar is not None:
                        bar.update(1)
        finally:
            frames.close()
        if size is None:
            raise InputError(f'{frames.path}: no frame')
        choice = chooser.finish()
        if last is not None:  # the last frame, kept by finish()
            names.append(_write(cv2, staged, int(choice.index[-1]), last))
        kept = Keyframes(staged, names, [int(i) for i in choice.index],
                         [start + int(i) / rate for i in choice.index], choice.why,
                         choice.frames, rate, size[0], size[1], chooser.most_motion)
        kept.save(staged)
    kept.folder = target
    log.info('keyframes: %d of %d frames (%s)', len(names), kept.frames,
             ', '.join(f'{n} {why}' for why, n in Counter(kept.why).items()))
    return kept


def _write(cv2: object, folder: Path, index: int, rgb: np.ndarray) -> str:
    name = f'frame_{index:06d}.png'
    if not cv2.imwrite(str(folder / name), rgb[:, :, ::-1]):  # type: ignore[attr-defined]
        raise InputError(f'{folder / name}: cannot be written (disk full?)')
    return name


@dataclass
class People:
    """The people the model found in each keyframe (not lifted: the camera is not known yet):
    ``found[name]`` a list of :class:`~hac_ros.people.model.Landmarks`; ``boxes`` the masked
    boxes per keyframe (x0, y0, x1, y1 pixels)."""

    found: dict[str, list[Landmarks]] = field(default_factory=dict)
    boxes: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def count(self) -> int:
        return sum(len(found) for found in self.found.values())

    def save(self, path: Path) -> None:
        arrays: dict[str, np.ndarray] = {}
        for name, found in self.found.items():
            arrays[f'{name}/boxes'] = self.boxes[name]
            for j, person in enumerate(found):
                presence = (person.presence if person.presence is not None
                            else np.ones(len(person.pixels)))
                arrays[f'{name}/{j}'] = np.c_[person.pixels, person.visibility, presence,
                                              person.world, np.full(len(person.pixels),
                                                                    float(person.from_crop))]
        np.savez(path, **arrays)  # type: ignore[arg-type]

    @classmethod
    def load(cls, path: Path, names: list[str]) -> People:
        people = cls()
        with np.load(path) as data:
            for name in names:
                people.boxes[name] = data[f'{name}/boxes']
                found = []
                j = 0
                while f'{name}/{j}' in data:
                    a = data[f'{name}/{j}']
                    found.append(Landmarks(pixels=a[:, 0:2], visibility=a[:, 2], presence=a[:, 3],
                                           world=a[:, 4:7], from_crop=bool(a[0, 7])))
                    j += 1
                people.found[name] = found
        return people


def find_people(keyframes: Keyframes, target: Path, params: PeopleParams,
                progress: Progress | None) -> People:
    """The people in every keyframe (``hac people``'s model, ``params``), and a mask per keyframe
    in ``target/masks`` (``<image name>.png``: 0 on the people, 255 elsewhere), since people move
    and the map must not."""
    from hac_ros.people.extra import opencv

    cv2 = opencv()
    model = PoseModel.from_params(params)
    people = People()
    with staged_output(target) as staged:
        (staged / 'masks').mkdir(parents=True)
        try:
            with progress_pass(progress, len(keyframes.names), 'people') as bar:
                for name in keyframes.names:
                    bgr = cv2.imread(str(keyframes.folder / name), cv2.IMREAD_COLOR)
                    if bgr is None:
                        raise InputError(f'{keyframes.folder / name}: the cached keyframe does '
                                         'not read (remove the cache directory)')
                    rgb = np.ascontiguousarray(bgr[:, :, ::-1])
                    found = model.detect(rgb)
                    # the person detector's boxes with no pose in them: someone, unmeasured
                    boxes = [p.box() for p in found] + [box for box, outcome in model.last_boxes
                                                        if outcome not in POSED]
                    people.found[name] = found
                    people.boxes[name] = np.array(boxes, dtype=float).reshape(-1, 4)
                    mask = np.full(rgb.shape[:2], 255, np.uint8)
                    for box in people.boxes[name]:
                        x0, y0, x1, y1 = _grown(box, rgb.shape[1], rgb.shape[0])
                        mask[y0:y1, x0:x1] = 0
                    cv2.imwrite(str(staged / 'masks' / f'{name}.png'), mask)
                    if bar is not None:
                        bar.update(1)
        finally:
            model.close()
        people.save(staged / 'people.npz')
    log.info('people: %d in %d keyframes', people.count,
             sum(1 for found in people.found.values() if found))
    return people


def _grown(box: np.ndarray, width: int, height: int) -> tuple[int, int, int, int]:
    w, h = box[2:] - box[:2]
    side, above, below = MASK_MARGIN
    x0, y0 = np.maximum(np.floor(box[:2] - (side * w, above * h)), 0).astype(int)
    x1, y1 = np.minimum(np.ceil(box[2:] + (side * w, below * h)), (width, height)).astype(int)
    return int(x0), int(y0), int(x1), int(y1)


def lift_people(people: People, names: list[str], camera: Camera, min_visibility: float
                ) -> tuple[np.ndarray, Counter[str]]:
    """(N, P, 33, 3) metres, camera optical frame: the people of the keyframes ``names``, lifted
    with the reconstruction's ``camera``, NaN where not seen or absent; and the people the lifting
    dropped, by reason."""
    from hac_ros.people.frontend import JOINTS, lift_found

    frames = [lift_found(people.found.get(name, []), camera, min_visibility) for name in names]
    most = max((len(f.lifted) for f in frames), default=0)
    joints = np.full((len(names), most, JOINTS, 3), np.nan)
    dropped: Counter[str] = Counter()
    for i, frame in enumerate(frames):
        joints[i, :len(frame.lifted)] = frame.joints_cam
        dropped.update(frame.dropped)
    return joints, dropped
