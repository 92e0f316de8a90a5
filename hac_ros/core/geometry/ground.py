"""The ground plane: the out-of-view fallback (docs/method.md, step 4; paper Eq. 6).

A plane is ``{p : n·p = b}`` in the SLAM map frame with ``n`` a unit normal pointing *down* (along
gravity) and ``b`` in SLAM units; a point with ``n·p > b`` is below it.

``hmr`` (ours) finds ``n`` without the scale it is used to find. First the body's up axis (pelvis →
neck) of many frames rotated into the map (the principal axis of their scatter, so a handstand still
gives the axis; which end is down from the scene, :mod:`hac_ros.core.geometry.down_vote`: never the
camera's axes): a degree or so off, as people lean. Then **the map's floor** (:func:`map_floor`):
the lowest dense surface across that axis, a plane fitted robustly to its points, gives the normal
to about a tenth of a degree and the offset ``b`` to about a centimetre; the floor is then *trusted*
(:attr:`GroundModel.trusted`): a map hit far above it is not a contact before any scale exists (a
table top between the camera and the feet, :mod:`hac_ros.core.bodies.sample`). Where the map shows
no floor, the contact joints placed in the map with the scale refine the body's normal: RANSAC
(3-point samples, a metric inlier distance), then a least-squares refit on the inliers; contacts
along a line (a straight walk) fix the normal only across the line, so the body normal is kept, made
perpendicular to the line; the offset is the lowest dense segment of the points along ``n`` (a
histogram, not the single lowest point; :meth:`MapIndex.floor_offset`).

Ablations: ``slam_y`` (the SLAM map's y axis as the normal), ``largest_plane`` (RANSAC's largest
plane of the map), ``none``.
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from hac_ros.core.basics.numeric import median_of
from hac_ros.core.geometry.down_vote import DownVote
from hac_ros.core.geometry.plane import Plane, fit_plane_lsq, ransac_plane, robust_plane
from hac_ros.core.geometry.reference import MapIndex
from hac_ros.core.rules.params import GroundMode, HacParams

BODY_MIN_FRAMES = 5  # body up axes needed before the hmr normal is trusted
BODY_REFRESH_REL = 0.1  # the body normal is recomputed when the bodies seen grew by 10 %
BODY_MIN_ANISOTROPY = 3.0  # largest / second eigenvalue of the up-axis scatter: a clear axis
CONTACT_MIN_POINTS = 30  # contact joints needed before refining the normal
CONTACT_REFIT_EVERY = 30  # refit the contact plane every this many new contacts
CONTACT_BUFFER = 3000  # contact joints kept for the refinement
RANSAC_SAMPLE = 500  # contact joints a RANSAC hypothesis is scored on
# a contact plane tilted further than this from the body normal is refused
CONTACT_MAX_TILT_DEG = 10.0
CONTACT_LINE_RATIO = 0.15  # second/first singular value below this: the contacts form a line
# a fixed camera without a map (static_camera): the normal from each person's own contacts
PERSON_MIN_CONTACTS = 5  # a person's contacts needed to take part
STATIC_MAX_TILT_DEG = 25.0  # such a normal further than this from the bodies' axis is refused
SOLE_MIN_POINTS = 30  # a fixed camera's sole points needed before its floor is fitted
SOLE_REFIT_EVERY = 20  # ... refitted every this many new ones
PERSON_MIN_SOLES = 5  # a person's sole points needed to take part
TRIM_SIGMAS = 3.0  # contacts further from their plane than this many robust sigmas: left out
# the map's floor (hmr): the lowest dense surface across the body normal, its plane fitted
FLOOR_BAND_EXTENT_REL = 0.01  # half width of the floor's band, fraction of the map's extent
FLOOR_MIN_POINTS = 30  # map points the floor's band needs
FLOOR_FIT_POINTS = 4000  # map points (an evenly strided subset) the floor is looked for in
FLOOR_ITERATIONS = 3  # band, plane fit, band again about the fitted plane, ...
FLOOR_LINE_RATIO = 0.05  # the band's second/first spread below this: a line (a wall's foot)
FLOOR_MAX_TILT_DEG = 30.0  # a map floor tilted further than this from the body normal is refused
FLOOR_MAX_BELOW = 0.10  # share of the map below the band: more, and it is not the lowest surface
LARGEST_PLANE_INLIER_REL = 0.005  # largest_plane: inlier distance as a fraction of the map extent
LARGEST_PLANE_SAMPLE = 5000  # map points used by the largest_plane RANSAC


def map_floor(map_index: MapIndex, body_normal: np.ndarray, previous: Plane | None = None
              ) -> Plane | None:
    """The floor in the map: the lowest dense surface across ``body_normal`` (down, unit, map
    frame), its plane fitted to the map's points; None when the map shows no such surface.

    The map points within FLOOR_BAND_EXTENT_REL of the map's extent of the lowest dense segment
    along the normal (:meth:`MapIndex.floor_offset`) are fitted by :func:`robust_plane`, starting
    from that segment (the floor's many points win over the feet of walls and furniture that share
    the band); the band is taken again about the fitted plane and refitted (FLOOR_ITERATIONS in
    all: the bodies' axis can be 15 degrees off, as walkers lean). A floor of many points gives its
    normal to about a tenth of a degree, where the bodies' axis is a degree or more off. Refused:
    too few points, points along a line, a plane tilted more than FLOOR_MAX_TILT_DEG from the
    bodies, or a surface with more than FLOOR_MAX_BELOW of the map below it (not the lowest: table
    tops over a floor the map missed). The floor is looked for in FLOOR_FIT_POINTS of the map's
    points, evenly strided whatever the band: the cost is bounded (a few ms), and a rigid motion
    of the map keeps the same points. ``previous``: the floor found in the segment's previous map,
    where the search starts, refitted once (a SLAM republishes much the same map every second);
    None: a search from the bodies' axis.
    """
    points = map_index.sample[::max(1, len(map_index.sample) // FLOOR_FIT_POINTS)]
    half = FLOOR_BAND_EXTENT_REL * map_index.extent
    body = np.asarray(body_normal, dtype=np.float64)
    if previous is None:
        normal, offset, rounds = body, map_index.floor_offset(body), FLOOR_ITERATIONS
    else:
        normal, offset, rounds = previous.normal, previous.offset, 1
    plane = None
    for _ in range(rounds):
        band = points[np.abs(points @ normal - offset) <= half]
        if len(band) < FLOOR_MIN_POINTS:
            return None
        fit = robust_plane(band, normal, offset)
        if fit is None:
            return None
        normal, offset, spread = fit
        if spread[1] < FLOOR_LINE_RATIO * spread[0]:
            return None  # a line of points (a wall's foot, a row of table edges)
        if np.degrees(np.arccos(min(float(normal @ body), 1.0))) > FLOOR_MAX_TILT_DEG:
            return None
        plane = Plane(normal, offset)
    assert plane is not None
    if np.mean(points @ plane.normal > plane.offset + half) > FLOOR_MAX_BELOW:
        return None
    return plane


class GroundModel:
    """Owns the ground-plane state of one SLAM map (reset with the estimator)."""

    def __init__(self, mode: str, *, inlier_m: float, ransac_iters: int, seed: int = 0,
                 static_camera: bool = False) -> None:
        self.mode = mode
        # a fixed camera (static_camera): people stand upright, so down is against their up
        # axis; without a map the floor is one SLAM unit below the camera (unit_floor)
        self.static_camera = static_camera
        self.inlier_m = inlier_m
        self.ransac_iters = ransac_iters
        self._rng = np.random.default_rng(seed)
        self._seed = seed
        self.reset()

    @classmethod
    def from_params(cls, params: HacParams) -> GroundModel:
        """The ground model ``params`` ask for (``ground_mode``, ``ground_inlier_m``,
        ``ground_ransac_iters``, ``seed``, ``static_camera``)."""
        return cls(params.ground_mode, inlier_m=params.ground_inlier_m,
                   ransac_iters=params.ground_ransac_iters, seed=params.seed,
                   static_camera=params.static_camera)

    def reset(self) -> None:
        # sums over the frames (unit vectors, map frame)
        self._scatter = np.zeros((3, 3))  # sum of the bodies' up axes' outer products, map frame
        self._up_sum = np.zeros(3)  # sum of the bodies' up axes (a sign for the axis)
        self.down = DownVote()  # which way along the bodies' axis is down (the scene says)
        self._body_frames = 0
        self._body_cache: tuple[int, np.ndarray | None] = (0, None)
        # ring buffer of the last CONTACT_BUFFER contact joints, SLAM units, map frame
        # a fixed camera's sole points, metres, map axes, from the camera (static_camera
        # without a map), and whose each is (-1: not followed)
        self._soles: deque[np.ndarray] = deque(maxlen=CONTACT_BUFFER)
        self._sole_people: deque[int] = deque(maxlen=CONTACT_BUFFER)
        self._soles_since_fit = 0
        self.camera_map: np.ndarray | None = None  # a fixed camera's centre, SLAM units
        self._contacts = np.empty((CONTACT_BUFFER, 3))
        self._contact_count = 0
        self._contacts_since_fit = 0
        self._contact_normal: np.ndarray | None = None
        self._plane_cache: tuple[MapIndex, bytes, Plane | None] | None = None
        self._floor: Plane | None = None  # the map's floor, when one was found (hmr)
        self._was_trusted = False  # as of the last judge_window
        self._readings: list[float] | None = None  # floor scales judging the window, or None
        self._floor_cache: tuple[MapIndex, bytes, Plane | None] | None = None
        self._rng = np.random.default_rng(self._seed)

    # ------------------------------------------------------------------ evidence
    def add_body(self, R_wc: np.ndarray, up_cam: np.ndarray) -> None:
        """One person's up axis (the layout's lower → upper joints), up_cam (3,) camera optical
        frame, any length."""
        norm = float(np.linalg.norm(up_cam))
        if not math.isfinite(norm) or norm <= 0.0:
            return
        up_map = R_wc @ (up_cam / norm)
        self._up_sum += up_map
        self._scatter += np.outer(up_map, up_map)
        self._body_frames += 1

    def add_contact(self, contact_map: np.ndarray, scale: float) -> None:
        """A contact joint placed in the map with the current scale (SLAM units, map frame).

        Every CONTACT_REFIT_EVERY contacts the plane is refitted (RANSAC, then least squares)."""
        if self.mode != GroundMode.HMR or not np.all(np.isfinite(contact_map)):
            return
        self._contacts[self._contact_count % CONTACT_BUFFER] = contact_map
        self._contact_count += 1
        self._contacts_since_fit += 1
        if (self._contact_count >= CONTACT_MIN_POINTS
                and self._contacts_since_fit >= CONTACT_REFIT_EVERY):
            self._contacts_since_fit = 0
            self._refine_with_contacts(self.inlier_m / scale)

    def add_sole(self, sole_map: np.ndarray, person: int = -1) -> None:
        """A fixed camera without a map: the point a standing person's sole touches, metres, map
        axes, from the camera (R_wc J: no scale needed). Every SOLE_REFIT_EVERY the floor's
        normal is refitted to them all (Tukey-weighted least squares, :func:`robust_plane`): its
        offset is the camera's height, but the estimate measures that, person by person."""
        if not (self.static_camera and self.mode == GroundMode.HMR
                and np.all(np.isfinite(sole_map))):
            return
        self._soles.append(np.asarray(sole_map, dtype=float))
        self._sole_people.append(person)
        self._soles_since_fit += 1
        body = self._body_normal()
        if (body is None or len(self._soles) < SOLE_MIN_POINTS
                or self._soles_since_fit < SOLE_REFIT_EVERY):
            return
        self._soles_since_fit = 0
        points = np.array(self._soles)
        # each person's soles lie on a plane of the floor's normal, offset by as much as their
        # size is off the model's: centred person by person, the offsets leave the fit
        people = np.array(self._sole_people)
        parts = [points[people == k] - points[people == k].mean(axis=0)
                 for k in np.unique(people[people >= 0])
                 if (people == k).sum() >= PERSON_MIN_SOLES]
        if len(parts) < 2:
            return
        points = np.concatenate(parts)
        fitted = robust_plane(points, body, median_of(points @ body))
        if fitted is None:
            return
        normal, _, sing = fitted
        self._adopt_normal(points, normal, sing, body)  # everyone walked one way: across it

    # ------------------------------------------------------------------ queries
    @property
    def refined(self) -> bool:
        """Whether the normal comes from contact joints, not the body axis alone."""
        return self._contact_normal is not None

    @property
    def trusted(self) -> bool:
        """Whether the floor is found in the map (its normal and offset from the map's own lowest
        surface) or its normal refined by contacts: a plane to judge map hits against before any
        scale exists."""
        return self._floor is not None or self._contact_normal is not None

    @property
    def floor_missing(self) -> bool:
        """``hmr``: the floor was looked for in the current map (a body normal exists) and not
        found; nothing then says that a map hit before any scale is not on a table top or a step
        (``floor_unknown`` in /diagnostics, :meth:`Calibrator.conditions`)."""
        cache = self._floor_cache
        return self.mode == GroundMode.HMR and cache is not None and cache[2] is None

    def judge_window(self, floor_scale: float, estimate: float | None, window_samples: int,
                     needed: int, tolerance: float) -> bool:
        """Whether the estimator's window must be dropped because the floor, now trusted, says it
        locked on something else (docs/method.md, plausibility rule 3).

        When the floor becomes trusted while the window already holds samples (taken without a
        floor to refuse occluders by: table tops hit before the first map showed the floor), the
        ``floor_scale`` of the next ``needed`` samples (metres per SLAM unit: the ground plane's
        reading of each contact, :class:`~hac_ros.core.bodies.sample.Sample`) judge the window once:
        True when their median and ``estimate`` (None before convergence) differ by more than
        ``tolerance`` (relative)."""
        if self.trusted and not self._was_trusted:
            self._readings = [] if window_samples else None
        self._was_trusted = self.trusted
        if self._readings is None or not math.isfinite(floor_scale):
            return False
        self._readings.append(floor_scale)
        if len(self._readings) < needed:
            return False
        floor, self._readings = median_of(self._readings), None
        return estimate is not None and abs(estimate / floor - 1.0) > tolerance

    def normal(self) -> np.ndarray | None:
        """The current down-pointing unit normal in the map frame, or None (not enough evidence)."""
        if self.mode == GroundMode.SLAM_Y:
            return np.array([0.0, 1.0, 0.0])
        if self.mode == GroundMode.HMR and self._floor is not None:
            return self._floor.normal
        if self.mode == GroundMode.HMR and self._contact_normal is not None:
            return self._contact_normal
        if self.mode in (GroundMode.HMR, GroundMode.LARGEST_PLANE):
            return self._body_normal()
        return None

    def body_axis(self, min_frames: int = BODY_MIN_FRAMES) -> np.ndarray | None:
        """The bodies' axis (3,), unit, map frame, once ``min_frames`` bodies give a clear one
        (else None); signed as most bodies' lower → upper joints point (up, unless most people
        are on their hands: :mod:`hac_ros.core.geometry.down_vote` says which way is down)."""
        if self._body_frames < max(min_frames, BODY_MIN_FRAMES):
            return None
        eigval, eigvec = np.linalg.eigh(self._scatter)
        if eigval[-1] < BODY_MIN_ANISOTROPY * max(eigval[-2], 1e-12):
            return None
        axis = eigvec[:, -1]
        return axis if float(axis @ self._up_sum) >= 0.0 else -axis

    def rough_down(self) -> np.ndarray | None:
        """Down (3,), unit, map frame, for choosing a contact: the normal, else the bodies' votes
        (:class:`~hac_ros.core.geometry.down_vote.DownVote`), else None."""
        normal = self.normal()
        return normal if normal is not None else self.down.down()

    def plane(self, map_index: MapIndex | None) -> Plane | None:
        """The current plane for this map, cached per (map, normal); a fixed camera without a map:
        the plane one SLAM unit below the camera (the camera at the map's origin), across the
        normal the bodies and their contacts give."""
        if self.static_camera and map_index is None and self.mode == GroundMode.HMR:
            normal = self.normal()
            centre = self.camera_map if self.camera_map is not None else np.zeros(3)
            return None if normal is None else Plane(normal, 1.0 + float(normal @ centre))
        if self.mode == GroundMode.NONE or map_index is None or len(map_index) < 3:
            return None
        if self.mode == GroundMode.HMR:
            self._floor = self._map_floor(map_index)
            if self._floor is not None:
                return self._floor
        normal = None if self.mode == GroundMode.LARGEST_PLANE else self.normal()
        if self.mode != GroundMode.LARGEST_PLANE and normal is None:
            return None
        key = b'' if normal is None else normal.tobytes()
        cache = self._plane_cache
        if cache is not None and cache[0] is map_index and cache[1] == key:
            return cache[2]
        if normal is None:  # largest_plane
            plane = self._largest_plane(map_index)
        else:
            plane = Plane(normal, map_index.floor_offset(normal))
        self._plane_cache = (map_index, key, plane)
        return plane

    # ------------------------------------------------------------------ internals
    def _orient_down(self, normal: np.ndarray) -> np.ndarray | None:
        """``normal`` turned to point down as the scene says (the bodies' votes), or None while
        that is undecided."""
        if self.static_camera:  # upright people: down is against their mean up axis
            side = float(normal @ self._up_sum)
            return -normal * math.copysign(1.0, side) if side != 0.0 else None
        return self.down.orient(normal)

    def _map_floor(self, map_index: MapIndex) -> Plane | None:
        """The map's floor (cached per map and body normal): :func:`map_floor` about the bodies'
        normal; None before a body normal exists."""
        body = self._body_normal()
        if body is None:
            return None
        key = body.tobytes()
        cache = self._floor_cache
        if cache is not None and cache[0] is map_index and cache[1] == key:
            return cache[2]
        previous = self._floor_cache[2] if self._floor_cache is not None else None
        floor = map_floor(map_index, body, previous) if previous is not None else None
        if floor is None:  # no floor before, or the previous one did not refit: a full search
            floor = map_floor(map_index, body)
        self._floor_cache = (map_index, key, floor)
        return floor

    def _body_normal(self) -> np.ndarray | None:
        """The bodies' axis, recomputed when the evidence grew by BODY_REFRESH_REL (so that the
        plane, cached per normal, is not rebuilt every frame)."""
        if self._body_frames < BODY_MIN_FRAMES:
            return None
        count, normal = self._body_cache
        if normal is not None and self._body_frames < count * (1.0 + BODY_REFRESH_REL):
            return normal
        normal = self._compute_body_normal()
        self._body_cache = (self._body_frames, normal)
        return normal

    def _compute_body_normal(self) -> np.ndarray | None:
        eigval, eigvec = np.linalg.eigh(self._scatter)
        if eigval[-1] < BODY_MIN_ANISOTROPY * max(eigval[-2], 1e-12):
            return None
        return self._orient_down(eigvec[:, -1])

    def _refine_with_contacts(self, inlier_distance: float) -> None:
        body = self._body_normal()
        if body is None:
            return
        points = self._contact_points()
        sample = points
        if len(points) > RANSAC_SAMPLE:  # RANSAC on a subset; the refit uses every inlier
            sample = points[self._rng.choice(len(points), RANSAC_SAMPLE, replace=False)]
        hypothesis = ransac_plane(sample, inlier_distance, self.ransac_iters, self._rng)
        if hypothesis is None or hypothesis.sum() < 3:
            return
        n0, b0, _ = fit_plane_lsq(sample[hypothesis])
        mask = np.abs(points @ n0 - b0) <= inlier_distance
        if mask.sum() < CONTACT_MIN_POINTS:
            return
        normal, _, sing = fit_plane_lsq(points[mask])
        self._adopt_normal(points[mask], normal, sing, body)

    def _adopt_normal(self, points: np.ndarray, normal: np.ndarray, sing: np.ndarray,
                      body: np.ndarray) -> None:
        """The floor's normal refined to ``normal``, the plane fitted to ``points`` (with its
        singular values ``sing``), once turned down and within the tilt allowed from the bodies'
        axis ``body``: CONTACT_MAX_TILT_DEG, STATIC_MAX_TILT_DEG for a fixed camera. Points along
        a line (people who all walked one way) say only the line's direction: the normal is then
        the bodies' axis made square to it."""
        if sing[1] < CONTACT_LINE_RATIO * sing[0]:
            line = np.linalg.svd(points - points.mean(axis=0), full_matrices=False)[2][0]
            normal = body - (body @ line) * line
            normal /= np.linalg.norm(normal)
        oriented = self._orient_down(normal)
        limit = STATIC_MAX_TILT_DEG if self.static_camera else CONTACT_MAX_TILT_DEG
        if oriented is not None and (np.degrees(np.arccos(np.clip(oriented @ body, -1, 1)))
                                     <= limit):
            self._contact_normal = oriented

    def _contact_points(self) -> np.ndarray:
        """The buffered contact joints (M, 3), oldest first, SLAM units, map frame."""
        n = self._contact_count
        if n <= CONTACT_BUFFER:
            return self._contacts[:n].copy()
        start = n % CONTACT_BUFFER
        return np.concatenate([self._contacts[start:], self._contacts[:start]])

    def _largest_plane(self, map_index: MapIndex) -> Plane | None:
        points = map_index.sample
        if len(points) > LARGEST_PLANE_SAMPLE:
            points = points[self._rng.choice(len(points), LARGEST_PLANE_SAMPLE, replace=False)]
        mask = ransac_plane(points, LARGEST_PLANE_INLIER_REL * map_index.extent,
                            self.ransac_iters, self._rng)
        if mask is None or mask.sum() < 3:
            return None
        normal, offset, _ = fit_plane_lsq(points[mask])
        oriented = self._orient_down(normal)
        if oriented is None:
            return None
        if oriented @ normal < 0:
            offset = -offset
        return Plane(oriented, offset)
