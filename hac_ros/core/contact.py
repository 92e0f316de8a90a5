"""Contact joint selection (SPEC, method step 1).

The paper takes the lowest joint along the camera's y axis (y points down): ``argmax_i J_i.y``.
That rule breaks when the camera rolls or pitches, so ``lowest_gravity`` takes the lowest joint along
the ground normal once one is known. The authors' code instead computes a scale for every joint and
keeps the per-frame maximum ratio (``max_ratio``): a joint can never lie behind the surface its ray
hits, so every ratio is at most the true scale and the largest is the contact. ``feet``,
``pelvis`` and ``head`` are the paper's fixed-joint ablations (Tab. 1).
"""
from __future__ import annotations

import math

import numpy as np


PELVIS, NECK, HEAD = 0, 12, 15
LEFT_FOOT, RIGHT_FOOT = 10, 11
FIXED_JOINTS = {'feet': (LEFT_FOOT, RIGHT_FOOT), 'pelvis': (PELVIS,), 'head': (HEAD,)}


def candidate_joints(mode: str, joints_cam: np.ndarray, R_wc: np.ndarray,
                     normal_map: np.ndarray | None) -> list[int]:
    """Indices of the joints whose rays are queried for one person.

    joints_cam: (24, 3) metres, camera optical frame, finite, the person in front of the camera.
    R_wc: (3, 3) camera to map. normal_map: (3,) down-pointing ground normal in the map, or None.
    Only joints in front of the camera (z > 0) are candidates.
    """
    front = joints_cam[:, 2] > 0.0
    if mode in FIXED_JOINTS:
        return [j for j in FIXED_JOINTS[mode] if front[j]]
    if mode == 'max_ratio':
        return np.flatnonzero(front).tolist()
    if not front.any():
        return []
    if mode == 'lowest_gravity' and normal_map is not None:
        height_down = joints_cam @ (R_wc.T @ normal_map)  # along gravity, camera-centred
    else:  # 'lowest' (and lowest_gravity before a normal exists)
        height_down = joints_cam[:, 1]
    return [int(np.argmax(np.where(front, height_down, -np.inf)))]  # the first of equals


def combine_ratios(mode: str, ratios: list[float]) -> float:
    """One person's scale from the per-joint ratios d_A / d_S (metres per SLAM unit, NaN: none).

    max_ratio: the maximum (authors' code); fixed multi-joint sets (feet): the median; one joint: it.
    """
    if len(ratios) == 1:
        return float(ratios[0])
    finite = [r for r in ratios if math.isfinite(r)]
    if not finite:
        return float('nan')
    if mode == 'max_ratio':
        return max(finite)
    return float(np.median(finite))


def in_view(joints_cam: np.ndarray, K: np.ndarray | None, width: int, height: int) -> list[bool]:
    """Which joints (M, 3) project inside the image (all in front of it without intrinsics).

    joints_cam: metres, camera optical frame; K: (3, 3) pixels or None; width, height: pixels.
    """
    x, y, z = joints_cam.T
    front = z > 0.0
    if K is None:
        return front.tolist()
    (fx, skew, cx), (_, fy, cy) = K[:2]
    depth = np.where(front, z, 1.0)
    u = (fx * x + skew * y) / depth + cx
    v = fy * y / depth + cy
    return (front & (u >= 0.0) & (u < width) & (v >= 0.0) & (v < height)).tolist()
