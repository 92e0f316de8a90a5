"""The simulated people in another HMR model's joint layout (``joint_layout``: coco17, h36m17).

The simulator moves SMPL-24 skeletons (:mod:`hac_ros.simulate.motions`); an HMR model of another
layout sees the same body, so its joints are placed on that body: the limbs' joints where SMPL's
are (a COCO or H36M ankle is SMPL's ankle, about 9 cm above the sole in stance, as in the real CMU
walk), the face and the top of the head at fixed offsets in the person's own frame (forward from
the hips and the body axis). Nothing here is read by the core: the core's ankle height above the
sole (:mod:`hac_ros.core.layouts`) is a constant of its own, and the simulator's ankle height
follows from each person's drawn sole height.
"""
from __future__ import annotations

import numpy as np

from hac_ros.core.errors import HacError
from hac_ros.core.layouts import BUILT_IN

# (SMPL-24 joint, offset (forward, left, up) metres) per joint of each layout, in layout order
_COCO17 = [(15, (0.10, 0.0, -0.03)),  # nose
           (15, (0.08, 0.03, 0.0)), (15, (0.08, -0.03, 0.0)),  # left, right eye
           (15, (0.0, 0.075, -0.01)), (15, (0.0, -0.075, -0.01)),  # left, right ear
           (16, (0, 0, 0)), (17, (0, 0, 0)), (18, (0, 0, 0)), (19, (0, 0, 0)),
           (20, (0, 0, 0)), (21, (0, 0, 0)),
           (1, (0.0, 0.03, -0.02)), (2, (0.0, -0.03, -0.02)),  # hips: a little wider and lower
           (4, (0, 0, 0)), (5, (0, 0, 0)), (7, (0, 0, 0)), (8, (0, 0, 0))]
_H36M17 = [(0, (0, 0, 0)), (2, (0, 0, 0)), (5, (0, 0, 0)), (8, (0, 0, 0)),
           (1, (0, 0, 0)), (4, (0, 0, 0)), (7, (0, 0, 0)),
           (6, (0, 0, 0)),  # spine
           (12, (0.0, 0.0, -0.06)),  # thorax
           (15, (0.09, 0.0, -0.04)),  # neck/nose
           (15, (0.0, 0.0, 0.11)),  # top of the head
           (16, (0, 0, 0)), (18, (0, 0, 0)), (20, (0, 0, 0)),
           (17, (0, 0, 0)), (19, (0, 0, 0)), (21, (0, 0, 0))]
_TABLES = {'coco17': _COCO17, 'h36m17': _H36M17}


def to_layout(joints_smpl: np.ndarray, name: str) -> np.ndarray:
    """SMPL-24 joints (..., 24, 3), metres, world frame (z up) -> the layout's (..., K, 3), same
    frame. ``smpl24`` returns the input."""
    if name == 'smpl24':
        return joints_smpl
    if name not in _TABLES:
        raise HacError(f'the simulator writes smpl24, coco17 or h36m17, not {name!r}')
    table = _TABLES[name]
    assert len(table) == BUILT_IN[name].joints_per_person
    j = np.asarray(joints_smpl, dtype=float)
    up = j[..., 12, :] - j[..., 0, :]
    left = j[..., 1, :] - j[..., 2, :]
    up = up / np.linalg.norm(up, axis=-1, keepdims=True)
    left = left - (left * up).sum(-1, keepdims=True) * up
    left = left / np.linalg.norm(left, axis=-1, keepdims=True)
    forward = np.cross(left, up)
    source = np.array([s for s, _ in table])
    offsets = np.array([o for _, o in table], dtype=float)  # (K, 3): forward, left, up
    return (j[..., source, :] + offsets[:, 0:1] * forward[..., None, :]
            + offsets[:, 1:2] * left[..., None, :] + offsets[:, 2:3] * up[..., None, :])
