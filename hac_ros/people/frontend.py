"""Images to metric people: the pose model (:mod:`hac_ros.people.model`), then each person lifted
to metres in the camera frame (:mod:`hac_ros.people.lifting`), then only the landmarks seen kept
(:func:`seen_landmarks`: the others NaN). Shared by ``hac_people_node`` and ``hac people``.

**Seen landmarks.** BlazePose gives all 33 landmarks of every person, in view or not: it completes
the body it expects. A landmark is published only when it is seen: its visibility and presence at
least ``landmark_min_visibility``, its pixel inside the image. The feet (ankles, heels, foot
indices) go together: when one of them is not seen, none is. A person cut by the image's bottom
edge gets legs drawn inside the image, on the shirt, with a confident side and a doubtful one
(basketball2.png's man on the right: 0.68-0.82 on one foot, 0.14-0.21 on the other, against 0.68
and more on every foot of the people seen whole in the opencv-doc images): his feet are never
published, so hac_node takes no contact from him.
"""
from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from hac_ros.core.layouts.blazepose33 import HIPS, LAYOUT, SHOULDERS
from hac_ros.people.lifting import Camera, Lifted, lift_person
from hac_ros.people.model import Landmarks, PoseModel

JOINTS = LAYOUT.joints_per_person
FEET = tuple(sorted({*LAYOUT.contact, *LAYOUT.feet}))  # ankles, heels, foot indices: together


def seen_landmarks(person: Landmarks, camera: Camera, min_visibility: float) -> np.ndarray:
    """(33,) bool: which of ``person``'s landmarks are seen (module docstring): visibility and
    presence at least ``min_visibility``, the pixel inside the ``camera``'s image, and the feet
    all or none."""
    presence = person.presence if person.presence is not None else np.ones(len(person.pixels))
    px = person.pixels
    seen = ((person.visibility >= min_visibility) & (presence >= min_visibility)
            & np.isfinite(px).all(axis=1)
            & (px[:, 0] >= 0) & (px[:, 0] < camera.width)
            & (px[:, 1] >= 0) & (px[:, 1] < camera.height))
    if not seen[list(FEET)].all():
        seen[list(FEET)] = False
    return seen


@dataclass
class Frame:
    """One image's people: ``joints_cam`` (P, 33, 3) metres, camera optical frame, in the
    ``blazepose33`` order; ``lifted`` their fits; ``dropped`` the people the model found but the
    lifting refused, by reason (:data:`hac_ros.people.reasons.PEOPLE_DROPPED`); ``unseen`` the
    landmarks published as NaN (not seen), summed over the people; ``model_s`` the wall
    seconds spent in the model, ``lift_s`` in the lifting; ``too_small`` when no person of
    ``person_min_height_px`` fits in the image (:meth:`~hac_ros.people.model.PoseModel.too_small`,
    whichever detector runs): only the landmarker's own detector looked."""

    joints_cam: np.ndarray
    lifted: list[Lifted] = field(default_factory=list)
    dropped: Counter[str] = field(default_factory=Counter)
    from_crop: int = 0
    unseen: int = 0
    too_small: bool = False
    model_s: float = 0.0
    lift_s: float = 0.0


class PeopleFromImages:
    """The model, the lifting and the seen landmarks, one image at a time; ``min_visibility``:
    :func:`seen_landmarks`' threshold (``landmark_min_visibility``). Not thread-safe."""

    def __init__(self, model: PoseModel, min_visibility: float = 0.3) -> None:
        self.model = model
        self.min_visibility = min_visibility

    def process(self, rgb: np.ndarray, camera: Camera) -> Frame:
        """rgb: (H, W, 3) uint8 of ``camera`` (its size must be the camera's: the caller checks,
        :func:`size_matches`)."""
        start = time.perf_counter()
        found = self.model.detect(rgb)
        frame = lift_found(found, camera, self.min_visibility)
        frame.model_s = time.perf_counter() - start - frame.lift_s
        frame.too_small = self.model.too_small(rgb.shape[1], rgb.shape[0])
        return frame

def lift_found(found: list[Landmarks], camera: Camera, min_visibility: float) -> Frame:
    """The people the model ``found`` in one image of ``camera``, lifted to metres with its K and
    distortion, their unseen landmarks NaN (:func:`seen_landmarks` with ``min_visibility``).
    ``hac video`` lifts them so once the reconstruction has settled the camera."""
    start = time.perf_counter()
    seen: list[np.ndarray] = []
    frame = Frame(joints_cam=np.zeros((0, JOINTS, 3)))
    for person in found:
        result = lift_person(person.pixels, person.visibility, person.world, camera,
                             hips=HIPS, shoulders=SHOULDERS)
        if isinstance(result, str):
            frame.dropped[result] += 1
            continue
        frame.lifted.append(result)
        frame.from_crop += int(person.from_crop)
        seen.append(seen_landmarks(person, camera, min_visibility))
    if frame.lifted:
        frame.joints_cam = np.stack([lifted.joints_cam for lifted in frame.lifted])
        unseen = ~np.stack(seen)
        frame.joints_cam[unseen] = np.nan
        frame.unseen = int(unseen.sum())
    frame.lift_s = time.perf_counter() - start
    return frame


def size_matches(rgb: np.ndarray, camera: Camera) -> bool:
    """The image is the size the camera's CameraInfo says."""
    return (rgb.shape[1], rgb.shape[0]) == (camera.width, camera.height)
