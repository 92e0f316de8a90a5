"""The map reference distance: a ray from the camera centre through a joint, queried in the map.

SPEC, method step 3 (paper Eq. 4; the authors' code): every map point whose direction from the camera
centre ``o`` is within the cone ``cos > cos(cone_angle)`` of the ray counts; ``d_S`` is the median of
their distances to ``o`` (``cone_median``), or the distance of the point closest in angle to the ray
(``nearest_to_ray``, the paper's "map point nearest the ray", measured as an angle so that it does
not depend on the SLAM unit). Only points in front of the camera count; fewer than
``cone_min_points`` is "no hit".

Speed: the index is a k-d tree built once per map update. Once a scale exists the contact is
expected at ``d_A / scale`` SLAM units, and the query looks only within a depth window around it
(``ray_window_rel``): a chain of balls that covers the cone between the window's ends, so the cost is
a few tree look-ups plus the points actually in the cone, whatever the map's size. Before a scale
exists the query scans every point (the literal method). Points outside the window are the only
difference from the literal method: they are occluders or far walls, which the plausibility rule
would refuse anyway.

The number of points in a cone grows with the map's density, and a median needs a few hundred of
them, not thousands: maps larger than ``index_max_points`` are thinned uniformly at random (a
fixed seed) before indexing, which bounds both the index build and the per-frame cost. The
speed benchmark measures what this changes against the literal method on the full map.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

# The chain's balls advance geometrically by (1 + 2 tan θ): each ball then covers one cone segment
# with about twice the segment's volume, a good trade between look-ups and excess points.
_MIN_WINDOW_NEAR_REL = 1e-6
SAMPLE_POINTS = 65536  # points of the map kept for whole-map statistics  # a window never starts closer than this fraction of the map extent


@dataclass
class RayHit:
    """A map hit: distance (SLAM units) from the camera centre and the number of points in the cone."""

    distance: float
    points: int


class MapIndex:
    """The current map, ready for ray queries.

    points_map: (N, 3) float64, SLAM units, map frame (finite, no (0,0,0) points: the adapters
    drop them). extent: the diagonal of the points' robust bounding box (1st–99th percentile),
    SLAM units: the scene's size, for scene-relative thresholds. max_points: above it the map is
    thinned uniformly at random before indexing (``index_max_points``); ``received`` counts the
    points before thinning.
    """

    def __init__(self, points_map: np.ndarray, frame_id: str = '', stamp_ns: int = 0,
                 max_points: int | None = None) -> None:
        points = np.ascontiguousarray(points_map, dtype=np.float64).reshape(-1, 3)
        finite = np.all(np.isfinite(points), axis=1)
        if not finite.all():
            points = points[finite]
        self.received = len(points)
        if max_points is not None and len(points) > max_points:
            # thinned uniformly at random (fixed seed: reproducible), see the module docstring
            keep = np.random.default_rng(0).random(len(points)) < max_points / len(points)
            points = points[keep]
        self.points_map = points
        self.frame_id = frame_id
        self.stamp_ns = int(stamp_ns)
        self.size = len(points)
        # an evenly strided subset for whole-map statistics (the ground plane's offset histogram)
        self.sample = points[::max(1, self.size // SAMPLE_POINTS)]
        if self.size:
            # balanced_tree=False builds ~2x faster with near-identical query cost on SLAM maps
            self.tree: cKDTree | None = cKDTree(points, balanced_tree=False, compact_nodes=False)
            if self.size >= 100:
                lo, hi = np.percentile(points, [1.0, 99.0], axis=0)
            else:
                lo, hi = points.min(axis=0), points.max(axis=0)
            self.extent = float(np.linalg.norm(hi - lo))
        else:
            self.tree = None
            self.extent = 0.0

    def __len__(self) -> int:
        return self.size

    # ------------------------------------------------------------------ ray queries
    def cone_distances(self, origin_map: np.ndarray, direction_map: np.ndarray, cos_min: float,
                       window: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Distances (SLAM units) and cosines of the map points inside the cone around one ray.

        origin_map: (3,) camera centre, SLAM units, map frame; direction_map: (3,) unit ray
        direction, map frame; window: (near, far) SLAM units along the ray, or None for all depths.
        """
        if self.size == 0:
            return np.empty(0), np.empty(0)
        o = np.asarray(origin_map, dtype=np.float64)
        d = np.asarray(direction_map, dtype=np.float64)
        if window is None:
            candidates = self.points_map
        else:
            idx = self._chain_candidates(o, d, cos_min, window)
            if idx.size == 0:
                return np.empty(0), np.empty(0)
            candidates = self.points_map[idx]
        v = candidates - o
        dist = np.sqrt(np.einsum('ij,ij->i', v, v))
        along = v @ d
        with np.errstate(invalid='ignore', divide='ignore'):
            cos = along / dist
        keep = (along > 0.0) & (cos > cos_min)
        if window is not None:
            keep &= (dist >= window[0]) & (dist <= window[1])
        return dist[keep], cos[keep]

    def query(self, origin_map: np.ndarray, direction_map: np.ndarray, *, mode: str,
              cos_min: float, min_points: int,
              window: tuple[float, float] | None = None) -> RayHit | None:
        """``d_S`` along one ray (SPEC step 3) or None for "no hit"."""
        dist, cos = self.cone_distances(origin_map, direction_map, cos_min, window)
        if dist.size < min_points or dist.size == 0:
            return None
        if mode == 'nearest_to_ray':
            return RayHit(float(dist[int(np.argmax(cos))]), int(dist.size))
        return RayHit(float(np.median(dist)), int(dist.size))

    def _chain_candidates(self, o: np.ndarray, d: np.ndarray, cos_min: float,
                          window: tuple[float, float]) -> np.ndarray:
        """Indices of points in a chain of balls covering the cone between window[0] and window[1]."""
        assert self.tree is not None
        near = max(window[0], _MIN_WINDOW_NEAR_REL * max(self.extent, 1e-300))
        far = window[1]
        if not (far > near):
            return np.empty(0, dtype=np.intp)
        tan = math.tan(math.acos(min(max(cos_min, -1.0), 1.0)))
        growth = 1.0 + 2.0 * tan
        count = max(1, int(math.ceil(math.log(far / near) / math.log(growth))))
        starts = near * growth ** np.arange(count)
        ends = np.minimum(starts * growth, far)
        mids = 0.5 * (starts + ends)
        half = 0.5 * (ends - starts)
        radii = np.sqrt(half ** 2 + (ends * tan) ** 2)
        centres = o + mids[:, None] * d
        lists = self.tree.query_ball_point(centres, radii, return_sorted=False)
        if count == 1:
            return np.asarray(lists[0], dtype=np.intp)
        # Balls overlap: keep each point only in the ball whose depth segment holds it (no sort).
        arrays = [np.asarray(x, dtype=np.intp) for x in lists]
        sizes = np.fromiter((len(x) for x in arrays), dtype=np.intp, count=count)
        idx = np.concatenate(arrays)
        ball = np.repeat(np.arange(count), sizes)
        v = self.points_map[idx] - o
        dist = np.sqrt(np.einsum('ij,ij->i', v, v))
        keep = (dist >= starts[ball]) & (dist < ends[ball])
        keep[ball == count - 1] |= dist[ball == count - 1] == ends[-1]
        return idx[keep]


def literal_cone_median(points_map: np.ndarray, origin_map: np.ndarray, direction_map: np.ndarray,
                        cos_min: float, min_points: int) -> float:
    """The authors' method written out: every map point against the ray, no index (the baseline).

    Returns d_S (SLAM units) or NaN for "no hit". Used by the speed benchmark and the equivalence test.
    """
    v = np.asarray(points_map) - np.asarray(origin_map)
    dist = np.linalg.norm(v, axis=1)
    cos = (v @ np.asarray(direction_map)) / dist
    inside = cos > cos_min
    if np.count_nonzero(inside) < max(min_points, 1):
        return float('nan')
    return float(np.median(dist[inside]))
