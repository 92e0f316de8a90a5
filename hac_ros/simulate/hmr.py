"""An HMR-like predictor: the true joints seen from the true camera, with HMR's kinds of error.

Measured HMR models (4D-Humans, WHAM, TRAM) place the body well in the image but poorly in depth:

- joint noise of a few centimetres (:data:`JOINT_NOISE_M`);
- a per-frame depth error of the whole person along the camera's viewing ray, about 5 cm
  (:data:`DEPTH_NOISE_M`), the body keeping its size;
- a depth bias: for a whole video a model is consistently too near or too far by a few percent, and
  that bias wanders slowly (:class:`DepthBias`: a mean drawn per recording plus a correlated
  wander, an Ornstein–Uhlenbeck process of :data:`BIAS_WANDER` sigma and
  :data:`BIAS_CORRELATION_S` correlation time);
- occasional outlier frames (a wrong depth and a scrambled pose);
- a person is predicted only when in view, but all their joints are predicted, in view or not.
"""
from __future__ import annotations

import math

import numpy as np

from hac_ros.core.layouts import JointLayout
from hac_ros.simulate.camera import project

JOINT_NOISE_M = 0.02
DEPTH_NOISE_M = 0.05  # per-frame depth error of the person (its root), metres
OUTLIER_RATE = 0.02
OUTLIER_DEPTH = 0.3  # an outlier frame's depth is off by up to this fraction
OUTLIER_NOISE_M = 0.10
MIN_JOINTS_IN_VIEW = 4
DEFAULT_BIAS_RANGE = 0.04  # the mean bias is drawn up to this when not given
BIAS_WANDER = 0.01  # stationary sigma of the bias's slow wander around its mean
BIAS_CORRELATION_S = 5.0  # correlation time of the wander, seconds


def draw_bias(rng: np.random.Generator) -> float:
    return float(rng.uniform(-DEFAULT_BIAS_RANGE, DEFAULT_BIAS_RANGE))


class DepthBias:
    """The depth bias of one recording at each frame: ``mean`` plus a slow wander (0 when clean).

    stamps_s: (T,) frame times, seconds. With ``mean`` 0 and ``wander`` False the recording is clean
    (no bias at all; the per-frame depth noise remains).
    """

    def __init__(self, mean: float, stamps_s: np.ndarray, rng: np.random.Generator,
                 wander: bool = True) -> None:
        self.mean = float(mean)
        t = np.asarray(stamps_s, dtype=float)
        x = np.zeros(len(t))
        if wander and len(t):
            x[0] = rng.normal(0.0, BIAS_WANDER)
            for i in range(1, len(t)):  # an exact Ornstein-Uhlenbeck step over any dt
                a = math.exp(-(t[i] - t[i - 1]) / BIAS_CORRELATION_S)
                x[i] = a * x[i - 1] + math.sqrt(1.0 - a * a) * rng.normal(0.0, BIAS_WANDER)
        self.values = self.mean + x  # (T,) relative depth error of each frame

    def __getitem__(self, i: int) -> float:
        return float(self.values[i])


def in_view(joints_cam: np.ndarray, K: np.ndarray, width: int, height: int,
            layout: JointLayout) -> bool:
    """A person is detected when enough joints project into the image in front of the camera."""
    px, front = project(joints_cam, K)
    inside = front & (px[:, 0] >= 0) & (px[:, 0] < width) & (px[:, 1] >= 0) & (px[:, 1] < height)
    return bool(inside.sum() >= MIN_JOINTS_IN_VIEW and layout.root_of(joints_cam)[2] > 0.3)


def predict(joints_world: np.ndarray, R_wc: np.ndarray, c: np.ndarray, bias: float,
            rng: np.random.Generator, layout: JointLayout) -> tuple[np.ndarray, bool]:
    """One person's predicted joints (K, 3), metres, camera optical frame; and whether it is an
    outlier.

    joints_world: (K, 3) true joints, world frame; R_wc, c: the true camera (camera-to-world);
    bias: this frame's relative depth bias (:class:`DepthBias`). The person's root is moved along
    its viewing ray by ``bias`` of its depth plus :data:`DEPTH_NOISE_M` of noise; the body keeps
    its size and shape. The root is the layout's (SMPL-24's pelvis, COCO-17's mid-hips).
    """
    cam = (joints_world - c) @ R_wc
    pred = cam + rng.normal(0.0, JOINT_NOISE_M, cam.shape)
    outlier = bool(rng.random() < OUTLIER_RATE)
    root = layout.root_of(pred).copy()
    depth = float(np.linalg.norm(root))
    new_depth = depth * (1.0 + bias) + rng.normal(0.0, DEPTH_NOISE_M)
    if outlier:
        new_depth *= 1.0 + rng.uniform(-OUTLIER_DEPTH, OUTLIER_DEPTH)
        pred += rng.normal(0.0, OUTLIER_NOISE_M, cam.shape)
    new_depth = max(new_depth, 0.1 * depth)  # never behind the camera
    return pred - root + root * (new_depth / max(depth, 1e-9)), outlier
