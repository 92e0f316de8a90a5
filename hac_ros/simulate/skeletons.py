"""The simulated people in an HMR model's joint layout (``joint_layout``).

The simulator moves SMPL-24 skeletons (:mod:`hac_ros.simulate.motions`); an HMR model of another
layout sees the same body, so its joints are placed on that body as the layout's module says
(:attr:`~hac_ros.core.layouts.base.JointLayout.sim_placement`: an SMPL-24 joint and an offset
forward, left and up in the person's own frame, from the hips and the body axis). The core never
reads these placements: a layout's heights above the sole (what the core assumes) are constants of
their own, and the simulator's follow from each person's drawn sole height.
"""
from __future__ import annotations

import numpy as np

from hac_ros.core.basics.errors import HacError
from hac_ros.core.layouts import BUILT_IN, SMPL24


def simulated_layouts() -> tuple[str, ...]:
    """The built-in layouts the simulator can write (those with a placement)."""
    return tuple(name for name, layout in BUILT_IN.items() if layout.sim_placement)


def to_layout(joints_smpl: np.ndarray, name: str) -> np.ndarray:
    """SMPL-24 joints (..., 24, 3), metres, world frame (z up) -> the layout's (..., K, 3), same
    frame. ``smpl24`` returns the input."""
    if name == SMPL24.name:
        return joints_smpl
    if name not in simulated_layouts():
        raise HacError(f'the simulator writes {", ".join(simulated_layouts())}, not {name!r}')
    table = BUILT_IN[name].sim_placement
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
