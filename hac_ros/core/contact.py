"""Contact joint selection (SPEC, method step 1).

The paper takes the lowest joint along the camera's y axis (y points down): ``argmax_i J_i.y``.
That rule breaks when the camera rolls or pitches, so ``lowest_gravity`` takes the lowest joint along
the ground normal once one is known. The authors' code instead computes a scale for every joint and
keeps the per-frame maximum ratio (``max_ratio``): a joint can never lie behind the surface its ray
hits, so every ratio is at most the true scale and the largest is the contact. ``feet``,
``pelvis`` and ``head`` are the paper's fixed-joint ablations (Tab. 1).
"""
from __future__ import annotations

import numpy as np

PELVIS, NECK, HEAD = 0, 12, 15
LEFT_FOOT, RIGHT_FOOT = 10, 11
FIXED_JOINTS = {'feet': (LEFT_FOOT, RIGHT_FOOT), 'pelvis': (PELVIS,), 'head': (HEAD,)}


def candidate_joints(mode: str, joints_cam: np.ndarray, R_wc: np.ndarray,
                     normal_map: np.ndarray | None) -> np.ndarray:
    """Indices of the joints whose rays are queried for one person.

    joints_cam: (24, 3) metres, camera optical frame, finite, the person in front of the camera.
    R_wc: (3, 3) camera to map. normal_map: (3,) down-pointing ground normal in the map, or None.
    Only joints in front of the camera (z > 0) are candidates.
    """
    in_front = joints_cam[:, 2] > 0.0
    if mode in FIXED_JOINTS:
        idx = np.array(FIXED_JOINTS[mode])
        return idx[in_front[idx]]
    if mode == 'max_ratio':
        return np.flatnonzero(in_front)
    if mode == 'lowest_gravity' and normal_map is not None:
        height_down = joints_cam @ (R_wc.T @ normal_map)  # along gravity, camera-centred
    else:  # 'lowest' (and lowest_gravity before a normal exists)
        height_down = joints_cam[:, 1]
    height_down = np.where(in_front, height_down, -np.inf)
    best = int(np.argmax(height_down))
    return np.array([best]) if in_front[best] else np.array([], dtype=int)


def combine_ratios(mode: str, ratios: np.ndarray) -> float:
    """One person's scale from the per-joint ratios d_A / d_S (metres per SLAM unit).

    max_ratio: the maximum (authors' code); fixed multi-joint sets (feet): the median; one joint: it.
    """
    ratios = ratios[np.isfinite(ratios)]
    if ratios.size == 0:
        return float('nan')
    if mode == 'max_ratio':
        return float(ratios.max())
    return float(np.median(ratios))


def in_view(joints_cam: np.ndarray, K: np.ndarray | None, width: int, height: int) -> np.ndarray:
    """(24,) bool: which joints project inside the image (all in front of it without intrinsics)."""
    in_front = joints_cam[:, 2] > 0.0
    if K is None:
        return in_front
    z = np.where(in_front, joints_cam[:, 2], 1.0)
    u = K[0, 0] * joints_cam[:, 0] / z + K[0, 1] * joints_cam[:, 1] / z + K[0, 2]
    v = K[1, 1] * joints_cam[:, 1] / z + K[1, 2]
    return in_front & (u >= 0) & (u < width) & (v >= 0) & (v < height)
