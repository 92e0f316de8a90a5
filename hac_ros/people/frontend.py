"""Images to metric people: the pose model (:mod:`hac_ros.people.model`), then each person lifted
to metres in the camera frame (:mod:`hac_ros.people.lifting`). Shared by ``hac_people_node`` and
``hac people``.
"""
from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from hac_ros.core.layouts.blazepose33 import HIPS, LAYOUT, SHOULDERS
from hac_ros.people.lifting import Camera, Lifted, lift_person
from hac_ros.people.model import HOG_WINDOW, PoseModel

JOINTS = LAYOUT.joints_per_person


@dataclass
class Frame:
    """One image's people: ``joints_cam`` (P, 33, 3) metres, camera optical frame, in the
    ``blazepose33`` order; ``lifted`` their fits; ``dropped`` the people the model found but the
    lifting refused, by reason (:data:`hac_ros.people.lifting.REASONS`); ``model_s`` the wall
    seconds spent in the model, ``lift_s`` in the lifting; ``too_small`` when the image is smaller
    than the person detector's window (:data:`hac_ros.people.model.HOG_WINDOW`, whichever
    detector runs): only the landmarker's own detector looked, and people that small are
    beyond what the front end finds."""

    joints_cam: np.ndarray
    lifted: list[Lifted] = field(default_factory=list)
    dropped: Counter[str] = field(default_factory=Counter)
    from_crop: int = 0
    too_small: bool = False
    model_s: float = 0.0
    lift_s: float = 0.0


class PeopleFromImages:
    """The model and the lifting, one image at a time. Not thread-safe."""

    def __init__(self, model: PoseModel) -> None:
        self.model = model

    def process(self, rgb: np.ndarray, camera: Camera) -> Frame:
        """rgb: (H, W, 3) uint8 of ``camera`` (its size must be the camera's: the caller checks,
        :func:`size_matches`)."""
        start = time.perf_counter()
        found = self.model.detect(rgb)
        lifted_at = time.perf_counter()
        frame = Frame(joints_cam=np.zeros((0, JOINTS, 3)), model_s=lifted_at - start,
                      too_small=too_small(rgb))
        for person in found:
            result = lift_person(person.pixels, person.visibility, person.world, camera,
                                 hips=HIPS, shoulders=SHOULDERS)
            if isinstance(result, str):
                frame.dropped[result] += 1
                continue
            frame.lifted.append(result)
            frame.from_crop += int(person.from_crop)
        if frame.lifted:
            frame.joints_cam = np.stack([lifted.joints_cam for lifted in frame.lifted])
        frame.lift_s = time.perf_counter() - lifted_at
        return frame


def too_small(rgb: np.ndarray) -> bool:
    """The image (H, W, 3) is smaller than the person detector's window, width x height."""
    return rgb.shape[1] < HOG_WINDOW[0] or rgb.shape[0] < HOG_WINDOW[1]


def size_matches(rgb: np.ndarray, camera: Camera) -> bool:
    """The image is the size the camera's CameraInfo says."""
    return (rgb.shape[1], rgb.shape[0]) == (camera.width, camera.height)
