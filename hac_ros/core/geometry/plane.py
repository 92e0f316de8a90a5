"""Plane geometry in the SLAM map frame: the plane, its fits, a ray's intersection, the floor.

A plane is ``{p : n·p = b}`` with ``n`` a unit normal and ``b`` its offset in SLAM units. The ground
plane's normal points *down* (along gravity, like the camera's y axis), so a point with
``n·p > b`` is below it (paper Eq. 6). Used by the ground model
(:mod:`hac_ros.core.geometry.ground`) and by the map's ray query (``cone_plane``,
:mod:`hac_ros.core.geometry.reference`). Pure numpy, no state.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hac_ros.core.basics.numeric import MAD_TO_SIGMA, median_of

# A ray within 3° of parallel to a plane meets it too far away to be measured: no answer.
COS_MIN_RAY_PLANE = math.cos(math.radians(87.0))
# local_plane: a point further from the first fit than this many robust sigmas is dropped
PLANE_INLIER_MADS = 3.0
# lowest_segment_offset: the floor as the lowest dense segment of the map along the normal
OFFSET_RANGE_QUANTILES = (0.005, 0.995)  # the map's robust range along n
OFFSET_BINS = 100  # histogram bins over that range
OFFSET_DENSE_FACTOR = 4.0  # a dense bin holds this many times the median non-empty bin ...
OFFSET_MIN_COUNT = 5  # ... and at least this many points
OFFSET_WINDOW_BINS = 3  # half width of the floor segment around its peak, in bins
OFFSET_FALLBACK_QUANTILE = 0.99  # without a dense bin: the authors' code's quantile
# robust_plane: the biweight's cut in robust sigmas, narrower than the usual 4.685, as the floor's
# noise is symmetric while the feet of walls and furniture in its band lie on one side of it
TUKEY_C = 2.0
ROBUST_PLANE_ITERS = 8  # reweighting rounds


@dataclass
class Plane:
    """normal: (3,) unit, SLAM map frame, pointing down; offset: SLAM units (n·p = offset)."""

    normal: np.ndarray
    offset: float

    def ray_distance(self, origin_map: np.ndarray, direction_map: np.ndarray) -> float:
        """Distance (SLAM units) from the camera centre ``origin_map`` (3,) along the unit
        ``direction_map`` (3,) to the plane, both map frame; NaN when the ray is (nearly) parallel
        to the plane, points away from it, or the camera is below it."""
        n_dot_d = float(self.normal @ direction_map)
        height = self.offset - float(self.normal @ origin_map)  # > 0: camera above the plane
        if n_dot_d <= COS_MIN_RAY_PLANE or height <= 0.0:
            return float('nan')
        return height / n_dot_d


def ray_plane_distance(origin: np.ndarray, direction: np.ndarray, normal: np.ndarray,
                       point: np.ndarray) -> float | None:
    """Where the ray ``origin + t·direction`` meets the plane through ``point`` with unit
    ``normal`` (either side): t in the points' unit, or None when the ray is within 3° of parallel
    to it. All (3,), one frame; ``direction`` unit."""
    along = float(normal @ direction)
    if abs(along) < COS_MIN_RAY_PLANE:
        return None
    return float(normal @ (point - origin)) / along


def fit_plane_lsq(points: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """Least-squares plane of (N, 3) points: (unit normal, offset, singular values)."""
    centroid = points.mean(axis=0)
    _, sing, vt = np.linalg.svd(points - centroid, full_matrices=False)
    normal = vt[-1]
    return normal, float(normal @ centroid), sing


def ransac_plane(points: np.ndarray, inlier_distance: float, iterations: int,
                 rng: np.random.Generator) -> np.ndarray | None:
    """Inlier mask of the plane with the most inliers among 3-point samples (the authors' RANSAC).

    points: (N, 3); inlier_distance in the points' unit. Vectorised over all samples at once.
    """
    n = len(points)
    if n < 3:
        return None
    picks = rng.integers(0, n, size=(iterations, 3))
    a, b, c = points[picks[:, 0]], points[picks[:, 1]], points[picks[:, 2]]
    normals = np.cross(b - a, c - a)
    norms = np.linalg.norm(normals, axis=1)
    valid = norms > 1e-12 * max(float(np.ptp(points)), 1e-300) ** 2
    if not valid.any():
        return None
    normals = normals[valid] / norms[valid, None]
    offsets = np.einsum('ij,ij->i', normals, a[valid])
    best_mask, best_count = None, -1
    # chunks keep memory bounded: (chunk x N) distances at a time
    chunk = max(1, 2_000_000 // max(n, 1))
    for start in range(0, len(normals), chunk):
        dist = np.abs(points @ normals[start:start + chunk].T - offsets[start:start + chunk])
        counts = (dist <= inlier_distance).sum(axis=0)
        k = int(np.argmax(counts))
        if counts[k] > best_count:
            best_count = int(counts[k])
            best_mask = dist[:, k] <= inlier_distance
    return best_mask


def local_plane(points: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """A plane through (N, 3) points, robust to a few off it: (unit normal, a point on it), or None
    when the points do not span a plane (collinear).

    Least squares (the centroid and the smallest principal axis), then again on the points within
    PLANE_INLIER_MADS robust sigmas (MAD_TO_SIGMA × the median distance) of the first plane.
    """
    keep = np.ones(len(points), dtype=bool)
    for _ in range(2):
        inliers = points[keep]
        if len(inliers) < 3:
            return None
        centroid = inliers.mean(axis=0)
        centred = inliers - centroid
        eigval, eigvec = np.linalg.eigh(centred.T @ centred)
        if eigval[1] <= 1e-12 * max(eigval[2], 1e-300):  # collinear: no plane
            return None
        normal = eigvec[:, 0]
        residual = np.abs((points - centroid) @ normal)
        sigma = MAD_TO_SIGMA * median_of(residual[keep])
        keep = residual <= PLANE_INLIER_MADS * sigma if sigma > 0.0 else keep
    return normal, centroid


def lowest_segment_offset(points_map: np.ndarray, normal: np.ndarray) -> float:
    """Offset b of the floor along the down-pointing ``normal``: the lowest dense segment of the
    map, SLAM units.

    A histogram of n·p over the map's robust range (OFFSET_RANGE_QUANTILES); walking up from the
    bottom, the first bin holding OFFSET_DENSE_FACTOR times the median non-empty bin (and
    OFFSET_MIN_COUNT points) belongs to the floor. Isolated points below the floor do not make a
    dense bin. The first dense bin is the floor's lower noise tail, not its middle: climb to the
    segment's peak, then b is the median of the points within OFFSET_WINDOW_BINS of it, re-centred
    once on that median (a symmetric window around a symmetric noise gives an unbiased middle).
    Without a dense bin: the OFFSET_FALLBACK_QUANTILE (the authors' code).

    points_map: (N, 3) float, SLAM units, map frame; normal: (3,) unit, map frame.
    """
    h = np.asarray(points_map, dtype=np.float64) @ np.asarray(normal, dtype=np.float64)
    if h.size == 0:
        return float('nan')
    lo, hi = (float(v) for v in np.quantile(h, OFFSET_RANGE_QUANTILES))
    if not hi - lo > 1e-9 * max(abs(lo), abs(hi), 1e-300):  # flat to rounding: one segment
        return median_of(h)
    counts, edges = np.histogram(h, bins=OFFSET_BINS, range=(lo, hi))
    width = edges[1] - edges[0]
    nonempty = counts[counts > 0]
    threshold = float(OFFSET_MIN_COUNT)  # also when every value is outside the range (tiny maps)
    if nonempty.size:
        threshold = max(threshold, OFFSET_DENSE_FACTOR * median_of(nonempty))
    dense = np.flatnonzero(counts >= threshold)
    if dense.size == 0:
        return float(np.quantile(h, OFFSET_FALLBACK_QUANTILE))
    k = int(dense[-1])  # n points down: the largest n·p is the lowest
    for _ in range(OFFSET_WINDOW_BINS):  # climb to the peak of the floor's segment
        if k > 0 and counts[k - 1] >= counts[k]:
            k -= 1
        else:
            break
    centre = lo + (k + 0.5) * width
    for _ in range(2):
        segment = h[np.abs(h - centre) <= OFFSET_WINDOW_BINS * width]
        if segment.size == 0:
            break
        centre = median_of(segment)
    return centre


def robust_plane(points: np.ndarray, normal: np.ndarray, offset: float
                 ) -> tuple[np.ndarray, float, np.ndarray] | None:
    """A plane through (N, 3) points robust to the points off it: (unit normal signed like
    ``normal``, offset, the spread's singular values (3,) largest first), or None (no plane).

    Iteratively reweighted least squares with Tukey's biweight (weight (1 - (r / (c sigma))^2)^2
    within c = TUKEY_C robust sigmas of the plane, 0 beyond; sigma MAD_TO_SIGMA × the median
    absolute residual), starting from the plane (``normal``, ``offset``). The weights are continuous
    in the points, so the plane is too: no random draw, and a rigid motion of the points moves it
    exactly.
    """
    residual = points @ normal - offset
    for _ in range(ROBUST_PLANE_ITERS):
        sigma = MAD_TO_SIGMA * median_of(np.abs(residual))
        if not sigma > 0.0:
            weights = (residual == 0.0).astype(np.float64)
        else:
            u = residual / (TUKEY_C * sigma)
            weights = np.clip(1.0 - u * u, 0.0, None) ** 2
        total = float(weights.sum())
        if total <= 0.0:
            return None
        centroid = weights @ points / total
        centred = points - centroid
        eigval, eigvec = np.linalg.eigh((centred * weights[:, None]).T @ centred)
        if eigval[1] <= 1e-12 * max(eigval[2], 1e-300):
            return None  # the weighted points are collinear
        fitted = eigvec[:, 0] if eigvec[:, 0] @ normal >= 0 else -eigvec[:, 0]
        residual = centred @ fitted
    return fitted, float(fitted @ centroid), np.sqrt(np.clip(eigval[::-1], 0.0, None) / total)
