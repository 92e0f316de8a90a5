"""Contact joint selection (docs/method.md, step 1).

The paper takes the lowest joint along the camera's y axis (y points down): ``argmax_i J_i.y``
(``lowest``, kept as the paper's rule). That rule breaks when the camera rolls or pitches, so
``lowest_gravity`` takes the lowest joint along the scene's down (the ground normal, or before it
the bodies' votes: :mod:`hac_ros.core.geometry.down_vote`); without either it has no candidate. The
authors' code instead computes a scale for every joint and keeps the per-frame maximum ratio
(``max_ratio``): a joint can never lie behind the surface its ray hits, so every ratio is at most
the true scale and the largest is the contact. ``feet``, ``pelvis`` and ``head`` are the paper's
fixed-joint ablations (Tab. 1). Which joint is which is the
:class:`~hac_ros.core.layouts.JointLayout`'s (``joint_layout``).
"""
from __future__ import annotations

import math

import numpy as np

from hac_ros.core.basics.numeric import median_of
from hac_ros.core.layouts import JointLayout
from hac_ros.core.rules.params import ContactMode


def candidate_joints(mode: str, layout: JointLayout, joints_cam: np.ndarray, R_wc: np.ndarray,
                     normal_map: np.ndarray | None) -> list[int]:
    """Indices of the joints whose rays are queried for one person.

    joints_cam: (K, 3) metres, camera optical frame, the person in front of the camera; a NaN
    joint is not seen and never a candidate (its depth is not > 0). R_wc: (3, 3) camera to map.
    normal_map: (3,) down, unit, map frame (the ground normal or the bodies' rough down), or None
    (``lowest_gravity`` then has no candidate).
    Only joints in front of the camera (z > 0) among the layout's contact candidates are
    candidates. Plain Python over the joints: numpy's per-call cost dominates at this size.
    """
    depth = joints_cam[:, 2].tolist()
    fixed = layout.fixed_joints(mode)
    if fixed is not None:
        return [j for j in fixed if depth[j] > 0.0]
    allowed = layout.contact or range(len(depth))
    if mode == ContactMode.MAX_RATIO:
        return [j for j in allowed if depth[j] > 0.0]
    if mode == ContactMode.LOWEST_GRAVITY:
        if normal_map is None:
            return []
        height_down = (joints_cam @ (R_wc.T @ normal_map)).tolist()  # along gravity, camera-centred
    else:  # 'lowest': the paper's camera-y rule
        height_down = joints_cam[:, 1].tolist()
    best, lowest = -1, -math.inf
    for j in allowed:
        # the first of equals, as argmax
        if depth[j] > 0.0 and (best < 0 or height_down[j] > lowest):
            best, lowest = j, height_down[j]
    return [best] if best >= 0 else []


def contact_seen(mode: str, layout: JointLayout, joints_cam: np.ndarray) -> bool:
    """Whether the contact can be told from the joints seen (finite; joints_cam (K, 3), NaN rows
    not seen). A fixed-joint mode needs one of its joints seen. The other modes take the lowest
    (or the largest ratio) among the layout's contact candidates (every joint when the layout
    names none): an unseen candidate may be the contact, so every candidate must be seen; with a
    layout whose candidates are all joints, one unseen joint is enough to give no contact."""
    fixed = layout.fixed_joints(mode)
    if fixed is not None:
        return bool(np.isfinite(joints_cam[list(fixed)]).all(axis=1).any())
    allowed = layout.contact or range(len(joints_cam))
    return bool(np.isfinite(joints_cam[list(allowed)]).all())


def sole_points(layout: JointLayout, joints_cam: np.ndarray, candidates: list[int],
                down_cam: np.ndarray) -> np.ndarray:
    """The candidates' contact points on the surface: each joint moved along ``down_cam`` by its
    height above the sole (the layout's ``sole_height_rel`` times the person's leg length).

    joints_cam: (K, 3) metres, camera optical frame; down_cam: (3,) unit, camera frame, pointing
    down (the ground normal). Returns (len(candidates), 3) metres, camera optical frame.
    """
    points = joints_cam[candidates]
    heights = [layout.sole_height_rel.get(j, 0.0) for j in candidates]
    if not any(heights):
        return points
    return points + (leg_length(layout, joints_cam) * np.asarray(heights))[:, None] * down_cam


def leg_lengths(layout: JointLayout, joints: np.ndarray) -> list[float]:
    """Each leg's length, metres: thigh plus shank (bone lengths: whatever the pose), in the
    layout's leg order (empty for a layout without legs). joints: (K, 3) metres, any frame."""
    return [math.dist(joints[h].tolist(), joints[k].tolist())
            + math.dist(joints[k].tolist(), joints[a].tolist()) for h, k, a in layout.legs]


def leg_length(layout: JointLayout, joints: np.ndarray) -> float:
    """The person's leg length, metres: the longer seen leg's (0 for a layout without legs; NaN
    when no leg is seen whole: a joint of each NaN)."""
    seen = [leg for leg in leg_lengths(layout, joints) if math.isfinite(leg)]
    if not layout.legs:
        return 0.0
    return max(seen) if seen else math.nan


def combine_ratios(mode: str, ratios: list[float]) -> float:
    """One person's scale from the per-joint ratios d_A / d_S (metres per SLAM unit, NaN: none).

    max_ratio: the maximum (authors' code); fixed multi-joint sets (feet): the median; one joint:
    it.
    """
    if len(ratios) == 1:
        return float(ratios[0])
    finite = [r for r in ratios if math.isfinite(r)]
    if not finite:
        return float('nan')
    if mode == ContactMode.MAX_RATIO:
        return max(finite)
    return median_of(finite)


def in_view(joints_cam: np.ndarray, K: np.ndarray | None, width: int, height: int) -> list[bool]:
    """Which joints (M, 3) project inside the image (all in front of it without intrinsics).

    A plain loop: M is a person's few candidate joints, where numpy's per-call cost dominates.
    """
    if K is None:
        return [z > 0.0 for z in joints_cam[:, 2].tolist()]
    (fx, skew, cx), (_, fy, cy) = K[:2].tolist()
    out = []
    for x, y, z in joints_cam.tolist():
        if z <= 0.0:
            out.append(False)
            continue
        u = (fx * x + skew * y) / z + cx
        v = fy * y / z + cy
        out.append(0.0 <= u < width and 0.0 <= v < height)
    return out
