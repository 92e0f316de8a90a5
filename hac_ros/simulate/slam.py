"""A monocular SLAM model: what a SLAM front end would publish, from the true cameras and world.

- The map frame is the camera frame of the first pose of a segment (a re-initialisation starts a
  new segment: a new map frame, a new scale, an empty map) and the unit is ``1 / scale`` metres.
- Poses are integrated from the true motion divided by the scale of the moment (so a drifting scale
  drifts like a real SLAM), with a little noise and a slow random-walk drift.
- Map points are the world's textured landmarks, created when a keyframe first sees them (in the
  image, within range, not occluded by the world, not on a person — masked), placed with the pose
  and scale of that moment and a depth-proportional noise; the whole map so far is republished every
  ``map_period_s``. When the scale drifts, landmarks seen again are re-placed in the scale of the
  moment (tracking keeps the local map consistent with the current pose; old, unseen parts keep
  the old scale).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from hac_ros.core.basics.numeric import NS
from hac_ros.simulate.camera import project
from hac_ros.simulate.world import World

POSE_NOISE_M = 0.003  # metric position noise of every pose
POSE_NOISE_RAD = np.radians(0.1)
POSE_DRIFT_M_PER_SQRT_S = 0.002  # random-walk drift of the position
POINT_NOISE_M = 0.004  # plus POINT_NOISE_REL of the depth at creation
POINT_NOISE_REL = 0.004
MAX_RANGE_M = 10.0
KEYFRAME_EVERY = 5  # frames between the keyframes that create map points
PERSON_MASK_PAD_PX = 12


@dataclass
class MapMessage:
    """One published map: stamp_ns, points_slam (N, 3) SLAM units in the map frame, frame_id."""

    stamp_ns: int
    points_slam: np.ndarray
    frame_id: str


@dataclass
class SlamOutput:
    """R_wc (T, 3, 3) camera-to-map; c (T, 3) SLAM units; frame_ids (T); maps; scale (T,) m/unit."""

    R_wc: np.ndarray
    c: np.ndarray
    frame_ids: list[str]
    maps: list[MapMessage]
    scale: np.ndarray


def _rot(axis_angle: np.ndarray) -> np.ndarray:
    return Rotation.from_rotvec(axis_angle).as_matrix()


def run_slam(world: World, landmarks: np.ndarray, stamps_ns: np.ndarray, R_world: np.ndarray,
             c_world: np.ndarray, people_world: list[np.ndarray], K: np.ndarray,
             size: tuple[int, int],
             scale_fn: Callable[[int], float], segments: list[int], rng: np.random.Generator,
             map_period_s: float = 2.0) -> SlamOutput:
    """Simulate the SLAM outputs.

    landmarks: (L, 3) world metres; R_world/c_world: true camera-to-world poses (T, ...);
    people_world: per frame (P, 24, 3) world joints (for masking); scale_fn(i) -> metres per SLAM
    unit at frame i; segments: frame indices where a segment (map) starts, the first being 0.
    """
    T = len(stamps_ns)
    width, height = size
    starts = sorted(set(segments) | {0})
    seg_of = np.searchsorted(starts, np.arange(T), side='right') - 1
    scale = np.array([scale_fn(i) for i in range(T)], dtype=float)
    # --- poses: integrate the true motion in the segment's frame with the scale of the moment
    R_slam = np.empty((T, 3, 3))
    c_slam = np.empty((T, 3))
    drift = np.zeros((T, 3))  # metric random walk of the published position, per frame
    dt = np.diff(stamps_ns, prepend=stamps_ns[0]) / NS
    for i in range(T):
        s0 = starts[seg_of[i]]
        R0 = R_world[s0]
        if i == s0:
            c_slam[i] = 0.0
        else:
            drift[i] = drift[i - 1] + rng.normal(0.0, POSE_DRIFT_M_PER_SQRT_S * np.sqrt(dt[i]), 3)
            c_slam[i] = c_slam[i - 1] + R0.T @ (c_world[i] - c_world[i - 1]) / scale[i]
        R_slam[i] = _rot(rng.normal(0.0, POSE_NOISE_RAD, 3)) @ (R0.T @ R_world[i])
    noise = rng.normal(0.0, POSE_NOISE_M, (T, 3))
    c_noisy = c_slam.copy()
    for i in range(T):
        if i != starts[seg_of[i]]:
            c_noisy[i] = c_slam[i] + R_world[starts[seg_of[i]]].T @ (noise[i] + drift[i]) / scale[i]
    # --- map points: created by keyframes, fixed afterwards
    L = len(landmarks)
    created = np.full(L, -1)
    keyframes = [i for i in range(T) if i % KEYFRAME_EVERY == 0 or i in starts]
    point_noise = rng.normal(0.0, 1.0, (L, 3))
    maps: list[MapMessage] = []
    next_map = stamps_ns[0] + int(0.3e9)
    points_slam = np.zeros((L, 3))
    placed_scale = np.zeros(L)
    for i in range(T):
        if i in starts and i > 0:
            created[:] = -1  # a re-initialised SLAM starts an empty map
            next_map = stamps_ns[i] + int(0.3e9)
        if i in keyframes:
            seen = _visible(world, landmarks, R_world[i], c_world[i], people_world[i], K, width,
                            height)
            # new landmarks, and (scale drift) landmarks seen again since the scale moved: a SLAM's
            # local map follows the scale its tracking drifts to
            new = seen & ((created < 0) | (np.abs(placed_scale / scale[i] - 1.0) > 1e-9))
            if new.any():
                s0 = starts[seg_of[i]]
                R0 = R_world[s0]
                depth = np.linalg.norm(landmarks[new] - c_world[i], axis=1)
                sigma = POINT_NOISE_M + POINT_NOISE_REL * depth
                metric = landmarks[new] + point_noise[new] * sigma[:, None]
                # placed relative to the (drifted) SLAM camera of this moment, in its SLAM units
                points_slam[new] = c_slam[i] + (drift[i] + metric - c_world[i]) @ R0 / scale[i]
                created[new] = np.where(created[new] < 0, i, created[new])
                placed_scale[new] = scale[i]
        if stamps_ns[i] >= next_map:
            have = created >= 0
            if have.any():
                maps.append(MapMessage(int(stamps_ns[i]), points_slam[have].copy(),
                                       _frame_id(seg_of[i])))
            next_map += int(map_period_s * NS)
    frame_ids = [_frame_id(s) for s in seg_of]
    return SlamOutput(R_slam, c_noisy, frame_ids, maps, scale)


def _frame_id(segment: int) -> str:
    return 'map' if segment == 0 else f'map_{segment}'


def _visible(world: World, landmarks: np.ndarray, R: np.ndarray, c: np.ndarray,
             people: np.ndarray, K: np.ndarray, width: int, height: int) -> np.ndarray:
    """(L,) bool: landmarks this camera sees (in the image, in range, unoccluded, not behind a
    person)."""
    cam = (landmarks - c) @ R
    px, front = project(cam, K)
    dist = np.linalg.norm(landmarks - c, axis=1)
    ok = front & (px[:, 0] >= 0) & (px[:, 0] < width) & (px[:, 1] >= 0) & (px[:, 1] < height) \
        & (dist < MAX_RANGE_M)
    idx = np.flatnonzero(ok)
    if idx.size:
        rays = (landmarks[idx] - c) / dist[idx, None]
        hit = world.raycast(c, rays)
        ok[idx] = hit >= dist[idx] - 0.02
    for person in people:  # the SLAM masks people out: nothing behind their silhouette
        pj = (person - c) @ R
        ppx, pfront = project(pj, K)
        if not pfront.any():
            continue
        lo = ppx[pfront].min(axis=0) - PERSON_MASK_PAD_PX
        hi = ppx[pfront].max(axis=0) + PERSON_MASK_PAD_PX
        inside = ((px[:, 0] >= lo[0]) & (px[:, 0] <= hi[0])
                  & (px[:, 1] >= lo[1]) & (px[:, 1] <= hi[1]))
        ok &= ~(inside & (cam[:, 2] > pj[pfront, 2].min() - 0.3))
    return ok
