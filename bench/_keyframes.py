"""A scene at keyframe rate: the SLAM poses and the joints frames at the keyframes a SLAM would
choose, by camera motion (issue 37: not every Nth frame).

A keyframe-based SLAM (ORB-SLAM, DSO) publishes a pose per keyframe and inserts a keyframe when
its view has changed enough since the reference keyframe: ORB-SLAM when it tracks fewer than 90 %
of the reference keyframe's map points, which happens as the camera translates by a share of the
scene's depth or turns by a share of its field of view. The rule here, in the SLAM's own units (so
scale-free, as the SLAM's), judged from the last keyframe:

- the camera centre moved more than :data:`PARALLAX` times the median depth of the map points the
  last keyframe saw (its reference depth), or
- it turned by more than :data:`ANGLE_DEG`, or
- :data:`MAX_GAP_S` passed (a SLAM also inserts keyframes while it looks at a changing scene from
  one place), or a new map frame began (a re-initialisation's first pose is a keyframe).

The constants give 0.8-1.5 Hz on the simulated handheld scenes (walk 1.5 Hz, drift 1.2 Hz, stairs
0.8 Hz), the rate of the real ORB-SLAM keyframes of the composites (fr2_desk 1.3 Hz, freiburg1_xyz
1.7 Hz), whose cameras move five times slower than the simulated ones. The joints frames are kept
at the keyframes' stamps (an HMR run on the keyframes' images), the maps at their own stamps.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

PARALLAX = 0.15  # translation since the last keyframe over its median depth of map points in view
ANGLE_DEG = 15.0  # rotation since the last keyframe
MAX_GAP_S = 2.0  # a keyframe at least this often
MIN_POINTS_IN_VIEW = 10  # map points in view needed for a reference depth


def keyframe_stamps(scene: Any) -> np.ndarray:
    """The stamps (int ns) of the poses a keyframe SLAM would keep (module docstring).

    scene: a bench/_accuracy_runs.Scene (events in processing order; K, width, height).
    """
    maps = [(stamp, payload[0]) for stamp, kind, payload in scene.events if kind == 'map']
    cos_max = np.cos(np.radians(ANGLE_DEG))
    keep: list[int] = []
    last: tuple[int, np.ndarray, np.ndarray, str] | None = None
    depth: float | None = None
    for stamp, kind, payload in scene.events:
        if kind != 'pose':
            continue
        R_wc, c, frame_id = payload[0], payload[1], payload[2]
        latest = [points for map_stamp, points in maps if map_stamp <= stamp]
        if last is not None and frame_id == last[3]:
            if depth is None and latest:  # the reference depth once there is a map
                depth = _median_depth(latest[-1], last[1], last[2], scene)
            moved = float(np.linalg.norm(c - last[2]))
            turned = (np.trace(last[1].T @ R_wc) - 1.0) / 2.0 < cos_max
            if not (turned or stamp - last[0] > MAX_GAP_S * 1e9
                    or (depth is not None and moved > PARALLAX * depth)):
                continue
        keep.append(stamp)
        last = (stamp, R_wc, c, frame_id)
        depth = _median_depth(latest[-1], R_wc, c, scene) if latest else None
    return np.array(keep, dtype=np.int64)


def _median_depth(points_map: np.ndarray, R_wc: np.ndarray, c: np.ndarray, scene: Any
                  ) -> float | None:
    """Median distance (SLAM units) from the camera to the map points in its image, or None."""
    cam = (np.asarray(points_map) - c) @ R_wc
    z = cam[:, 2]
    front = cam[z > 1e-9]
    u = scene.K[0, 0] * front[:, 0] / front[:, 2] + scene.K[0, 2]
    v = scene.K[1, 1] * front[:, 1] / front[:, 2] + scene.K[1, 2]
    inside = front[(u >= 0) & (u < scene.width) & (v >= 0) & (v < scene.height)]
    if len(inside) < MIN_POINTS_IN_VIEW:
        return None
    return float(np.median(np.linalg.norm(inside, axis=1)))


def at_keyframes(scene: Any) -> Any:
    """``scene`` with its poses and joints frames at the keyframes only (maps kept), the truth
    cut to match."""
    stamps = keyframe_stamps(scene)
    keys = set(stamps.tolist())
    events, joints_world, person_ids = [], [], []
    k = 0
    for event in scene.events:
        stamp, kind, _ = event
        if kind == 'joints':
            if stamp in keys:
                joints_world.append(scene.joints_world[k])
                person_ids.append(scene.person_ids[k])
            k += 1
        if kind == 'map' or stamp in keys:
            events.append(event)
    index = np.searchsorted(scene.pose_stamps_ns, stamps)
    return replace(scene, events=events, pose_stamps_ns=scene.pose_stamps_ns[index],
                   true_scale=scene.true_scale[index], joints_world=joints_world,
                   person_ids=person_ids, gt_R_wc=scene.gt_R_wc[index], gt_c=scene.gt_c[index])
