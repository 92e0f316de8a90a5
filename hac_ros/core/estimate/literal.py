"""The authors' method as their public code does it (docs/method.md): the literal reference.

Per frame and person, every joint's ray is cast against every map point: the points whose direction
from the camera centre lies within a cone of cos > 0.999 (about 2.6°) of the ray, ``d_S`` the
median of their distances; the joint's ratio ``||J|| / d_S``; the frame's scale is the **largest**
ratio over the joints (a joint never lies behind the surface its ray hits, so the largest is the
contact). The sequence scale is the median over the frames
(:func:`hac_ros.core.estimate.estimator.sequence_scale`); world joints ``R_wc J + s c`` and
camera centres ``s c``, in the SLAM map's axes. No ground plane, no gate, no window: the reference
our estimator is measured against (bench/accuracy.py) and ``calibrate(..., literal=True)``.

Pure numpy. Poses camera-to-map: ``R_wc`` (3, 3), ``c_map`` (3,) SLAM units; joints (K, 3) metres
in the camera optical frame; map points (N, 3) SLAM units, map frame.
"""
from __future__ import annotations

import math

import numpy as np

AUTHORS_COS = 0.999  # the cone of the authors' code: cos > 0.999


def max_ratio(points_map: np.ndarray, R_wc: np.ndarray, c_map: np.ndarray,
              joints_cam: np.ndarray, cos_min: float = AUTHORS_COS) -> float:
    """One person's per-frame scale (metres per SLAM unit): the largest ``||J_j|| / d_S,j`` over
    the joints in front of the camera whose cone holds a map point; NaN when none does."""
    points = np.asarray(points_map, dtype=float)
    joints = np.asarray(joints_cam, dtype=float)
    v = points - c_map
    dist = np.linalg.norm(v, axis=1)
    depth = np.linalg.norm(joints, axis=1)
    rays = (joints / depth[:, None]) @ R_wc.T  # (K, 3) unit, map frame
    inside = (v @ rays.T) > cos_min * dist[:, None]  # (N, K)
    best = math.nan
    for j in range(len(joints)):
        if joints[j, 2] > 0.0 and inside[:, j].any():
            ratio = float(depth[j]) / float(np.median(dist[inside[:, j]]))
            best = ratio if not ratio <= best else best  # NaN best: the first ratio
    return best


def world_joints(joints_cam: np.ndarray, R_wc: np.ndarray, c_map: np.ndarray,
                 scale: float) -> np.ndarray:
    """Joints (..., K, 3) metres, camera optical frame -> ``R_wc J + s c`` (metres, the SLAM map's
    axes scaled by ``scale``)."""
    return np.asarray(joints_cam, dtype=float) @ np.asarray(R_wc).T + scale * np.asarray(c_map)
