"""An HMR-like predictor: the true joints seen from the true camera, with HMR's kinds of error.

- joint noise of a few centimetres;
- a per-recording depth bias: HMR is consistently too near or too far for a whole video, so the
  person's root translation is scaled along its ray by (1 + bias) while the body keeps its size;
- occasional outlier frames (a wrong depth and a scrambled pose);
- a person is predicted only when in view, but all their joints are predicted, in view or not.
"""
from __future__ import annotations

import numpy as np

from hac_ros.simulate.camera import project

JOINT_NOISE_M = 0.02
OUTLIER_RATE = 0.02
OUTLIER_DEPTH = 0.3  # an outlier frame's depth is off by up to this fraction
OUTLIER_NOISE_M = 0.10
MIN_JOINTS_IN_VIEW = 4
DEFAULT_BIAS_RANGE = 0.04  # |bias| drawn up to this when not given


def draw_bias(rng: np.random.Generator) -> float:
    return float(rng.uniform(-DEFAULT_BIAS_RANGE, DEFAULT_BIAS_RANGE))


def in_view(joints_cam: np.ndarray, K: np.ndarray, width: int, height: int) -> bool:
    """A person is detected when enough joints project into the image in front of the camera."""
    px, front = project(joints_cam, K)
    inside = front & (px[:, 0] >= 0) & (px[:, 0] < width) & (px[:, 1] >= 0) & (px[:, 1] < height)
    return bool(inside.sum() >= MIN_JOINTS_IN_VIEW and joints_cam[0, 2] > 0.3)


def predict(joints_world: np.ndarray, R_wc: np.ndarray, c: np.ndarray, bias: float,
            rng: np.random.Generator) -> tuple[np.ndarray, bool]:
    """One person's predicted joints (24, 3), metres, camera optical frame; and whether it is an outlier.

    joints_world: (24, 3) true joints, world frame; R_wc, c: the true camera (camera-to-world).
    """
    cam = (joints_world - c) @ R_wc
    pred = cam + rng.normal(0.0, JOINT_NOISE_M, cam.shape)
    outlier = bool(rng.random() < OUTLIER_RATE)
    depth = 1.0 + bias
    if outlier:
        depth *= 1.0 + rng.uniform(-OUTLIER_DEPTH, OUTLIER_DEPTH)
        pred += rng.normal(0.0, OUTLIER_NOISE_M, cam.shape)
    root = pred[0].copy()
    return pred - root + root * depth, outlier
