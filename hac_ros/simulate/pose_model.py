"""A simulated pose model, as MediaPipe's BlazePose GHUM 3D answers for a person in an image: the
input of :mod:`hac_ros.people.lifting`, for its tests and benchmarks.

From a person's true joints in the camera (any layout, metres, optical frame) it makes the image
landmarks (the joints projected through the camera, lens distortion included, plus pixel noise)
and the metric landmarks in the model's own frame: centred on the root, in a frame that faces the
person (x from the right hip to the left, y down the body axis, z = x × y), at the size of the
model's body prior (``prior_scale``: a model that gives everyone one size places a tall person's
landmarks ``prior / true`` of their size). Pure numpy.
"""
from __future__ import annotations

import numpy as np

from hac_ros.core.layouts.base import JointLayout
from hac_ros.people.lifting import Camera, distort


def person_frame(joints: np.ndarray, layout: JointLayout, left_hip: int, right_hip: int
                 ) -> np.ndarray:
    """(3, 3) rows: the person-facing axes in the joints' frame (x right hip → left hip, y down
    the body axis, z = x × y)."""
    down = -layout.up_axis(joints)
    down = down / np.linalg.norm(down)
    across = joints[left_hip] - joints[right_hip]
    across = across - (across @ down) * down
    across = across / np.linalg.norm(across)
    return np.stack([across, down, np.cross(across, down)])


def landmarks(joints_cam: np.ndarray, camera: Camera, layout: JointLayout, left_hip: int,
              right_hip: int, rng: np.random.Generator, noise_px: float = 0.0,
              prior_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The pose model's answer for one person: (pixels (K, 2) of the distorted image, world
    (K, 3) metres in the person-facing frame, the root at the origin, scaled by
    ``prior_scale``). joints_cam: (K, 3) metres, camera optical frame, in front of the camera;
    noise_px: the standard deviation of the pixel noise (each axis)."""
    J = np.asarray(joints_cam, dtype=float)
    pixels = distort(J[:, :2] / J[:, 2:3], camera) + rng.normal(0.0, noise_px, (len(J), 2))
    axes = person_frame(J, layout, left_hip, right_hip)
    world = prior_scale * (J - layout.root_of(J)) @ axes.T
    return pixels, world
