"""Maps that cannot hold a floor: points at one point, on one line, or on one plane that is not
the floor (docs/method.md, "Degenerate maps").

A SLAM's map is a cloud of three dimensions: the floor, walls, furniture. A map whose points lie
at a point or on a line (a wrapper that projected its points, a broken field layout) holds no
surface a ray can meet, and a map on one plane holds one surface only: a floor-only map (a ground
robot in an empty hall, a camera looking down at the floor) calibrates, a wall-only one cannot
(every contact ray meets the wall behind the person, or nothing). Such maps are refused
(``map_degenerate``) like garbage ones, so they never calibrate, nor reset anything as a map that
"no longer overlaps" the last.

:func:`map_shape` judges the map's shape from the principal spreads (standard deviations) of its
evenly strided sample, scale-free: ``point`` when the largest spread is under POINT_SPREAD_REL of
the points' distance from the camera; ``line`` when the second is under FLAT_SPREAD_REL of the
largest; ``plane`` when the smallest is under FLAT_SPREAD_REL of the second; else ``solid``. A
plane is then judged as a floor (:func:`plane_problem`): the camera path must not lie on it (a
camera is above its floor by more than PLANE_CAMERA_MIN_REL of the points' median distance), and
once PLANE_JUDGE_BODIES bodies give their axis, its normal must be within PLANE_TILT_MAX_DEG of it:
a wall is 90 degrees off, a floor a few (the first bodies alone, leaning and with HMR's noise, can
be 30 degrees off: a tighter bound refused real floors).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hac_ros.core.basics.numeric import median_of

POINT_SPREAD_REL = 1e-4  # largest spread / distance from the camera below this: a point
FLAT_SPREAD_REL = 0.02  # a spread below this fraction of the next larger one: flat that way
PLANE_CAMERA_MIN_REL = 0.02  # the camera above a plane map by at least this of the median depth
PLANE_TILT_MAX_DEG = 60.0  # a plane map's normal from the bodies' axis: beyond, not a floor
PLANE_JUDGE_BODIES = 30  # bodies whose axis judges a plane map's tilt (5 can be 30 degrees off)


@dataclass(frozen=True)
class MapShape:
    """``kind``: 'solid', 'plane', 'line' or 'point'. For a plane: ``normal`` (3,) unit, map frame
    (either sign) and ``offset`` (normal · p on the plane, SLAM units); NaN elsewhere."""

    kind: str
    normal: np.ndarray
    offset: float


@dataclass(frozen=True)
class Principal:
    """A sample's principal axes: ``centroid`` (3,), SLAM units, map frame; ``spread`` (3,) the
    standard deviations along them, ascending, SLAM units; ``axes`` (3, 3) their unit directions
    as columns, in the same order."""

    centroid: np.ndarray
    spread: np.ndarray
    axes: np.ndarray


def principal(sample_map: np.ndarray) -> Principal:
    """The principal axes of ``sample_map`` (N, 3), N >= 1, SLAM units, map frame."""
    centroid = sample_map.mean(axis=0)
    centred = sample_map - centroid
    eigval, eigvec = np.linalg.eigh(centred.T @ centred / len(sample_map))
    return Principal(centroid, np.sqrt(np.clip(eigval, 0.0, None)), eigvec)


def map_shape(sample_map: np.ndarray, camera_map: np.ndarray | None,
              axes: Principal | None = None) -> MapShape:
    """The shape of a map from ``sample_map`` (N, 3) SLAM units, map frame (an evenly strided
    sample); camera_map: (3,) the camera centre, SLAM units (None: the map frame's origin);
    ``axes``: the sample's :func:`principal` axes, if already known (the map index keeps them)."""
    nan3 = np.full(3, math.nan)
    if len(sample_map) < 3:
        return MapShape('point', nan3, math.nan)
    axes = principal(sample_map) if axes is None else axes
    centroid, spread = axes.centroid, axes.spread
    origin = np.zeros(3) if camera_map is None else np.asarray(camera_map, dtype=np.float64)
    distance = median_of(np.linalg.norm(sample_map - origin, axis=1))
    if spread[2] <= POINT_SPREAD_REL * max(distance, float(np.linalg.norm(centroid)), 1e-300):
        return MapShape('point', nan3, math.nan)
    if spread[1] < FLAT_SPREAD_REL * spread[2]:
        return MapShape('line', nan3, math.nan)
    if spread[0] < FLAT_SPREAD_REL * spread[1]:
        normal = axes.axes[:, 0]
        return MapShape('plane', normal, float(normal @ centroid))
    return MapShape('solid', nan3, math.nan)


def plane_problem(shape: MapShape, sample_map: np.ndarray, camera_map: np.ndarray | None,
                  body_axis_map: np.ndarray | None) -> str:
    """Why a ``plane`` map cannot be the floor ('' when it can, or is not yet judged): the camera
    on it (``camera_map`` (3,), SLAM units; None: not judged), or its normal tilted from
    ``body_axis_map`` (3,) unit, either sign (None: not judged yet)."""
    if shape.kind != 'plane':
        return ''
    if camera_map is not None:
        height = abs(float(shape.normal @ camera_map) - shape.offset)
        depth = median_of(np.linalg.norm(sample_map - camera_map, axis=1))
        if height < PLANE_CAMERA_MIN_REL * depth:
            return 'its plane passes through the camera'
    if body_axis_map is not None:
        tilt = tilt_deg(shape.normal, body_axis_map)
        if tilt > PLANE_TILT_MAX_DEG:
            return f'its plane is tilted {tilt:.0f} degrees from the bodies\' up axis'
    return ''


def tilt_deg(normal: np.ndarray, axis: np.ndarray) -> float:
    """The angle between a plane's ``normal`` and an ``axis`` (both (3,), unit, one frame; either
    sign), degrees: 0 when the axis is perpendicular to the plane."""
    return math.degrees(math.acos(min(1.0, abs(float(normal @ axis)))))
