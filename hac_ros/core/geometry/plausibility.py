"""Values no SLAM and no HMR model produces: maps, bodies and outputs judged before they are used.

Every rule is scale-free or metric, never in SLAM units (a SLAM unit can be a millimetre or a
kilometre):

- **a map** (``cloud_implausible``) is judged on its points' distances from the camera (the last
  SLAM pose; the map's own median point before the first pose), relative to their median: a SLAM
  triangulates points at depths within a few orders of magnitude of each other, while bytes
  decoded with the wrong layout or byte order give values spread over dozens of decades. A map
  with more than :data:`CLOUD_IMPLAUSIBLE_SHARE` of its points beyond :data:`CLOUD_DEPTH_DECADES`
  decades of the median is refused, whatever its unit;
- **a person** (``joints_not_metres``) whose joints spread (box diagonal) over more than
  :data:`BODY_SPAN_MAX_M` or less than :data:`BODY_SPAN_MIN_M` metres is not in metres, and the
  likely unit is named from the ratio to an adult's span;
- **an output** (``output_implausible``) with a non-finite value or one beyond ``output_max_m``
  metres is never published: a pose, odometry or joints message is suppressed, a cloud loses
  those points.
"""
from __future__ import annotations

import math

import numpy as np

from hac_ros.core.basics.numeric import median_of
from hac_ros.core.layouts import JointLayout

CLOUD_DEPTH_DECADES = 3.0  # a point 1000x nearer or further than the median depth ...
CLOUD_IMPLAUSIBLE_SHARE = 0.25  # ... for more than this share of a map's points: refused
BODY_SPAN_MIN_M = 0.3  # a person's joints (box diagonal) spread at least this much, metres ...
BODY_SPAN_MAX_M = 4.0  # ... and at most this much (an adult: about 1.7 m)
ADULT_SPAN_M = 1.7
UNITS = {1: 'decimetres', 2: 'centimetres', 3: 'millimetres'}


def implausible(points_map: np.ndarray, camera_map: np.ndarray | None,
                median_depth: float | None = None) -> tuple[np.ndarray, float]:
    """Which points lie beyond CLOUD_DEPTH_DECADES decades of the median distance from
    ``camera_map``: a (N,) bool mask, and the median distance (SLAM units).

    points_map: (N, 3) float, SLAM units, map frame (finite); camera_map: (3,) the camera centre,
    SLAM units, map frame, or None: the points' coordinate-wise median stands in (and only points
    too far count, a point may lie on it); median_depth:
    the median to judge by (default: these points').
    """
    points = np.asarray(points_map, dtype=np.float64)
    if not len(points):
        return np.zeros(0, dtype=bool), math.nan
    centre = np.median(points, axis=0) if camera_map is None else np.asarray(camera_map)
    with np.errstate(over='ignore', invalid='ignore'):
        depth = np.linalg.norm(points - centre, axis=1)
    median = median_of(depth) if median_depth is None else median_depth
    if camera_map is None and median == 0.0:  # most points on one: nothing to judge them by
        return np.zeros(len(points), dtype=bool), median
    if not math.isfinite(median) or median <= 0.0:  # most points at the camera, or overflowing
        return np.ones(len(points), dtype=bool), median
    with np.errstate(divide='ignore', over='ignore', invalid='ignore'):
        decades = np.log10(depth / median)
    if camera_map is None:  # the median point is no camera: a point may lie on it
        decades = np.maximum(decades, 0.0)
    return ~(np.abs(decades) <= CLOUD_DEPTH_DECADES), median  # NaN and inf count as beyond


def body_unit_problem(joints_cam: np.ndarray) -> str:
    """Why one person's joints are not metres, or '' when their spread is a body's.

    joints_cam: (K, 3) finite, the HMR joints of one person (metres if all is well). The reason
    names the likely unit from the ratio of the spread to an adult's.
    """
    return span_problem(float(np.linalg.norm(joints_cam.max(axis=0) - joints_cam.min(axis=0))))


def body_spans(joints: np.ndarray) -> np.ndarray:
    """The spread (box diagonal, metres if all is well) of every person whose joints are all
    finite: joints (..., K, 3) -> (M,) for the M such people."""
    people = np.asarray(joints, dtype=float).reshape(-1, *np.shape(joints)[-2:])
    people = people[np.isfinite(people).all(axis=(1, 2))]
    return np.linalg.norm(people.max(axis=1) - people.min(axis=1), axis=1)


def span_problem(span: float) -> str:
    """:func:`body_unit_problem` of a person spread over ``span`` (metres if all is well)."""
    if BODY_SPAN_MIN_M <= span <= BODY_SPAN_MAX_M:
        return ''
    if span <= 0.0:
        return 'a person whose joints are all at one point: HMR joints must be metres'
    decades = round(math.log10(ADULT_SPAN_M / span))  # > 0: too small, < 0: too large
    unit = UNITS.get(abs(decades), '')
    if decades > 0:
        likely = f', about {10 ** decades}x too small' + (
            f': {unit} converted to metres twice?' if unit else '')
    elif decades < 0:
        likely = f', about {10 ** -decades}x too large' + (f': {unit}?' if unit else '')
    else:
        likely = ''
    return (f'a person whose joints spread over {span:.3g} m (a body: {BODY_SPAN_MIN_M:g} to '
            f'{BODY_SPAN_MAX_M:g} m): HMR joints must be metres{likely}')


def sane(values: np.ndarray, bound_m: float) -> bool:
    """Every value finite and within ``bound_m`` (metres) in absolute value."""
    values = np.asarray(values)
    return bool(np.all(np.abs(values) <= bound_m))  # NaN compares False


def sane_rows(points: np.ndarray, bound_m: float) -> np.ndarray:
    """The rows of ``points`` (N, 3) whose coordinates are all finite and within ``bound_m``."""
    keep = np.all(np.abs(points) <= bound_m, axis=1)
    return points if keep.all() else points[keep]


MIN_SEEN_SHARE = 0.5  # a person is judged when at least this share of their joints is seen


def seen_problem(layout: JointLayout, seen: np.ndarray) -> str:
    """Why too little of a person is seen to judge them ('' when enough is): seen (K,) bool,
    the joints given (finite; NaN ones are unseen). The body axis needs one seen joint at each
    end, and at least :data:`MIN_SEEN_SHARE` of the joints must be seen."""
    flags = seen.tolist()
    for end, indices in (('lower', layout.axis_lower), ('upper', layout.axis_upper)):
        if not any(flags[i] for i in indices):
            return f'no joint of the body axis\'s {end} end seen'
    if sum(flags) < MIN_SEEN_SHARE * len(flags):
        return f'{sum(flags)} of {len(flags)} joints seen'
    return ''
