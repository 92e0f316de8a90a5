"""One person's scale sample (docs/method.md, steps 1–5): contact, reference distance, ratio.

:func:`person_sample` is pure: it reads the map, the ground plane and the current estimate and
returns the sample (or why there is none); the :class:`~hac_ros.core.calibrator.Calibrator`
keeps the counts, the estimator and the ground model. Joints are metres in the camera optical
frame; poses are camera-to-map (R_wc (3, 3), c_map (3,) SLAM units); scales are metres per SLAM
unit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hac_ros.core.bodies.contact import (
    candidate_joints,
    combine_ratios,
    contact_seen,
    in_view,
    sole_points,
)
from hac_ros.core.geometry.plane import Plane
from hac_ros.core.geometry.reference import MapIndex
from hac_ros.core.layouts import JointLayout
from hac_ros.core.rules.params import ContactMode, HacParams, ReferenceMode


@dataclass
class Sample:
    """A person's sample: scale (metres per SLAM unit), source ('map' or 'ground') and the point
    on the surface that gave it (metres, camera optical frame); or, with ``reason`` set, why there
    is none ('behind_camera', 'contact_unseen', 'no_map', 'no_reference'; the scale NaN).
    ``floor_scale``: what the ground plane alone says for that point (its ray's floor
    intersection; NaN without one)."""

    scale: float
    source: str = ''
    contact_cam: np.ndarray | None = None
    reason: str = ''
    floor_scale: float = math.nan


def no_sample(reason: str) -> Sample:
    """The result for a person without a sample, and why."""
    return Sample(math.nan, reason=reason)


@dataclass
class Scene:
    """What a sample is measured against: the map (or None), the ground plane (SLAM map frame,
    or None), down (the plane's normal, else the bodies' rough down; None while unknown), whether
    that floor is trusted (found in the map, or its normal refined by contacts:
    ``GroundModel.trusted``), the intrinsics (K (3, 3) pixels or None,
    image width and height), the estimate now (None before convergence) and cos of the cone's half
    angle."""

    map: MapIndex | None
    plane: Plane | None
    normal: np.ndarray | None
    trusted: bool
    K: np.ndarray | None
    image_size: tuple[int, int]
    scale: float | None
    cos_min: float


def person_sample(params: HacParams, layout: JointLayout, scene: Scene, R_wc: np.ndarray,
                  c_map: np.ndarray, joints: np.ndarray) -> Sample:
    """The sample of one person (joints (K, 3) metres, camera optical frame, some in front of the
    camera; NaN rows not seen), or :func:`no_sample` with the reason there is none."""
    if scene.map is None and scene.plane is None:
        return no_sample('no_map')
    if scene.normal is None and params.contact_mode == ContactMode.LOWEST_GRAVITY:
        return no_sample('no_down')  # the lowest joint needs down (hac_ros.core.geometry.down_vote)
    candidates = candidate_joints(params.contact_mode, layout, joints, R_wc, scene.normal)
    if not candidates:
        return no_sample('behind_camera' if contact_seen(params.contact_mode, layout, joints)
                         else 'contact_unseen')
    visible = in_view(joints[candidates], scene.K, *scene.image_size)
    # the points on the surface the candidates touch (metres, camera frame): the joints
    # themselves, or moved down onto the sole (sole_correction)
    points = joints[candidates]
    if params.sole_correction and scene.normal is not None:  # down unknown: the joints as they are
        points = sole_points(layout, joints, candidates, R_wc.T @ scene.normal)
        if not np.isfinite(points).all():
            return no_sample('contact_unseen')  # no leg seen whole: no height above the sole
    plane = scene.plane
    ratios = [math.nan] * len(candidates)  # d_A / d_S of each candidate, metres per SLAM unit
    floor_ratios = [math.nan] * len(candidates)  # the same with the ground plane's d_S
    from_map = [False] * len(candidates)
    for k, point in enumerate(points):
        distance_metric = math.sqrt(float(point @ point))
        direction_map = R_wc @ (point / distance_metric)
        plane_distance = plane.ray_distance(c_map, direction_map) if plane is not None else math.nan
        floor_ratios[k] = distance_metric / plane_distance
        if (visible[k] and scene.map is not None
                and params.reference_mode != ReferenceMode.FLOOR_PLANE):
            d_slam = _map_distance(params, scene, c_map, direction_map, distance_metric)
            if d_slam is not None and _plausible(params, scene, d_slam, distance_metric,
                                                 plane_distance):
                ratios[k], from_map[k] = distance_metric / d_slam, True
                continue
        if math.isfinite(plane_distance):
            ratios[k] = distance_metric / plane_distance
    finite = [k for k, r in enumerate(ratios) if math.isfinite(r)]
    if not finite:
        return no_sample('no_map' if scene.map is None and plane is None else 'no_reference')
    chosen = 0
    if len(ratios) > 1 and params.contact_mode == ContactMode.MAX_RATIO:
        chosen = max(finite, key=ratios.__getitem__)  # the first of equals, as nanargmax
    return Sample(combine_ratios(params.contact_mode, ratios),
                  'map' if from_map[chosen] else 'ground', points[chosen],
                  floor_scale=floor_ratios[chosen])


def _map_distance(params: HacParams, scene: Scene, c_map: np.ndarray, direction_map: np.ndarray,
                  distance_metric: float) -> float | None:
    """d_S along the ray (docs/method.md, step 3); once a scale exists only within
    ``ray_window_rel`` of the distance it predicts."""
    window = None
    if scene.scale is not None and params.ray_window_rel > 0.0:
        expected = distance_metric / scene.scale
        w = 1.0 + params.ray_window_rel
        window = (expected / w, expected * w)
    assert scene.map is not None
    hit = scene.map.query(c_map, direction_map, mode=params.reference_mode, cos_min=scene.cos_min,
                          min_points=params.cone_min_points, window=window)
    return None if hit is None else hit.distance


def _plausible(params: HacParams, scene: Scene, d_slam: float, distance_metric: float,
               plane_distance: float) -> bool:
    """Can this map hit be the surface the joint touches? (documented in docs/method.md)

    1. Not beyond the ground plane: a ray cannot pass through the floor, so a hit further than
       the ray's floor intersection (by more than ``plausibility_rel_tol``) is a far surface seen
       past the person, or a wrong plane: fall back to the plane.
    2. Once a scale exists: its metric distance must agree with the joint's own distance within
       ``plausibility_rel_tol`` (an occluder in front of the foot is much nearer, a far wall
       behind a gap much further).
    3. Before a scale exists, once the floor is trusted (found in the map, or its normal refined
       by contact joints), a hit much nearer than the floor is suspect too (an occluder such as
       a table top, a stair step): the floor decides until rule 2 can judge. The body-axis floor
       alone is too rough for this: a forward lean of a few degrees moves a grazing ray's floor
       point a lot (on the real-data composite, using it here took the scale error from 4.7 % to
       43 %).
    """
    tol = params.plausibility_rel_tol
    scale = scene.scale
    if math.isfinite(plane_distance):
        if d_slam > plane_distance * (1.0 + tol):
            return False
        # before a scale: a hit well above a trusted floor may be an occluder
        if scale is None and scene.trusted and d_slam * (1.0 + tol) < plane_distance:
            return False
    return scale is None or abs(scale * d_slam - distance_metric) <= tol * distance_metric
