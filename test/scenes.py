"""Constructed scenes with known answers for the core tests (no noise unless asked).

World: z up, metres, floor z = 0. A level camera 1.5 m high follows a person walking along x.
The person's foot joints stand at the height above the sole the core assumes for them
(SOLE_M: hac_ros.core.bodies.contact's prior for this skeleton), so that the surface a contact joint
touches is exactly the floor below it.
The SLAM map frame is the first camera's optical frame and the SLAM unit is ``1 / true_scale``
metres: ``p_slam = R_c0ᵀ (p_world − c0) / true_scale``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hac_ros.core.basics.numeric import NS
from hac_ros.core.bodies.contact import leg_length
from hac_ros.core.layouts import SMPL24

# A standing SMPL-24 skeleton, world metres, pelvis above the origin, facing -y (towards the camera)
STANDING = np.array([
    [0.00, 0.00, 0.93],  # 0 pelvis
    [0.09, 0.00, 0.86], [-0.09, 0.00, 0.86],  # 1 l_hip, 2 r_hip
    [0.00, 0.01, 1.05],  # 3 spine1
    [0.10, 0.00, 0.46], [-0.10, 0.00, 0.46],  # 4 l_knee, 5 r_knee
    [0.00, 0.01, 1.18],  # 6 spine2
    [0.10, 0.02, 0.08], [-0.10, 0.02, 0.08],  # 7 l_ankle, 8 r_ankle
    [0.00, 0.01, 1.26],  # 9 spine3
    [0.11, -0.10, 0.00], [-0.11, -0.10, 0.00],  # 10 l_foot, 11 r_foot (on the floor)
    [0.00, 0.00, 1.45],  # 12 neck
    [0.07, 0.00, 1.38], [-0.07, 0.00, 1.38],  # 13, 14 collars
    [0.00, -0.02, 1.62],  # 15 head
    [0.18, 0.00, 1.40], [-0.18, 0.00, 1.40],  # 16, 17 shoulders
    [0.22, 0.00, 1.12], [-0.22, 0.00, 1.12],  # 18, 19 elbows
    [0.24, -0.03, 0.86], [-0.24, -0.03, 0.86],  # 20, 21 wrists
    [0.25, -0.05, 0.78], [-0.25, -0.05, 0.78],  # 22, 23 hands
])
# the feet stand at their sole height above the floor (10, 11 are the foot joints)
SOLE_M = SMPL24.sole_height_rel[10] * leg_length(SMPL24, STANDING)
STANDING = STANDING + [0.0, 0.0, SOLE_M]

# converged_max_rel_sigma for the tests of other things than convergence on clips of a few
# seconds: the estimate's own uncertainty takes about 8 s of a 30 Hz walk to fall under the
# default (1 %; docs/method.md, "The estimator"); under this bound it converges in a second or
# two, as those tests assume (test_estimator.py and test_relock.py test convergence itself).
QUICK_CONVERGENCE = 0.05


def look_at(camera: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Camera-to-world rotation of an optical camera at ``camera`` looking at ``target`` (z up
    world)."""
    z = target - camera
    z = z / np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


@dataclass
class Scene:
    true_scale: float
    stamps_ns: np.ndarray  # (T,)
    R_wc_world: np.ndarray  # (T, 3, 3)
    c_world: np.ndarray  # (T, 3) metres
    joints_world: np.ndarray  # (T, 24, 3) metres
    R0: np.ndarray = field(default_factory=lambda: np.eye(3))
    c0: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def to_slam(self, p_world: np.ndarray) -> np.ndarray:
        return (np.asarray(p_world) - self.c0) @ self.R0 / self.true_scale

    @property
    def R_wc_slam(self) -> np.ndarray:
        return np.einsum('ji,tjk->tik', self.R0, self.R_wc_world)

    @property
    def c_slam(self) -> np.ndarray:
        return self.to_slam(self.c_world)

    @property
    def joints_cam(self) -> np.ndarray:
        """(T, 24, 3) metres, camera optical frame."""
        return np.einsum('tji,tkj->tki', self.R_wc_world, self.joints_world - self.c_world[:, None, :])

    def contact_world(self) -> np.ndarray:
        """(T, 3): where each frame's lowest joint touches the floor (the floor point below it)."""
        idx = np.argmin(self.joints_world[:, :, 2], axis=1)
        return self.joints_world[np.arange(len(idx)), idx] * [1.0, 1.0, 0.0]

    def with_backdrop(self, points_slam: np.ndarray) -> np.ndarray:
        """``points_slam`` (N, 3) with a room behind the camera (a box of points 26-36 m behind
        it, floor to 3 m): a map of three dimensions whose points never fall in a ray's cone, for
        tests whose map is a few exact points (one point alone is a degenerate map)."""
        rng = np.random.default_rng(0)
        box = rng.uniform([-10.0, -40.0, 0.0], [10.0, -30.0, 3.0], (400, 3))
        return np.vstack([np.asarray(points_slam).reshape(-1, 3), self.to_slam(box)])

    def floor_points_slam(self, half_size: float = 6.0, step: float = 0.25) -> np.ndarray:
        g = np.arange(-half_size, half_size + 1e-9, step)
        xx, yy = np.meshgrid(g, g + 2.0)
        return self.to_slam(np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], axis=1))


def walking_scene(frames: int = 40, true_scale: float = 2.5, rate: float = 10.0,
                  camera_height: float = 1.5, stride: float = 0.05) -> Scene:
    """A person walking along +x, feet alternating between the floor and a 10 cm swing; a level
    camera 4 m away following them. The lowest joint of every frame stands SOLE_M above the floor
    (the stance foot)."""
    stamps = (np.arange(frames) * NS / rate).astype(np.int64) + NS
    joints = np.empty((frames, 24, 3))
    R = np.empty((frames, 3, 3))
    c = np.empty((frames, 3))
    for t in range(frames):
        x = stride * t
        body = STANDING + [x, 0.0, 0.0]
        swing = 11 if t % 2 else 10  # the other foot is on the floor
        body[swing] += [0.0, 0.0, 0.10]
        body[swing - 3] += [0.0, 0.0, 0.10]  # its ankle
        joints[t] = body
        c[t] = [x + 0.3 * np.sin(t / 7.0), -4.0, camera_height]
        target = np.array([c[t, 0], 0.0, camera_height])  # level: looks horizontally
        R[t] = look_at(c[t], target)
    return Scene(true_scale, stamps, R, c, joints, R0=R[0].copy(), c0=c[0].copy())
