"""The maps of one stream: which map a frame uses, and when the map changed beyond recognition.

A frame uses the latest map whose stamp is not after its own (docs/interface.md, "Processing
order"): maps wait in :class:`MapBook` until a frame of their stamp activates them. A map is judged
before it waits (:meth:`MapBook.judge`, hac_ros.core.geometry.plausibility): one of values no SLAM
produces is refused, one with a few such points is used without them. On activation, a map that
overlaps the one in use too little (``map_overlap_min``, both ways) says the SLAM re-initialised;
the calibrator resets. The map in use goes to the metric stage (/hac/cloud) at most once per
``cloud_min_period_s`` of stamp time. Maps are :class:`~hac_ros.core.geometry.reference.MapIndex`,
SLAM units, the map frame; stamps int ns.
"""
from __future__ import annotations

import bisect
from collections.abc import Callable

import numpy as np

from hac_ros.core.basics.numeric import NS
from hac_ros.core.geometry.map_shape import MapShape, map_shape
from hac_ros.core.geometry.plausibility import CLOUD_IMPLAUSIBLE_SHARE, implausible
from hac_ros.core.geometry.reference import MapIndex
from hac_ros.core.rules.params import CloudMode, HacParams

PENDING_MAPS_MAX = 8  # maps waiting for a frame of their stamp


class MapBook:
    """The waiting maps (sorted by stamp), the map in use, a map in a frame the poses have not
    reached yet (``foreign``), and what the metric stage has been handed."""

    def __init__(self, params: HacParams) -> None:
        self.params = params
        self.waiting: list[MapIndex] = []
        self.in_use: MapIndex | None = None
        self.foreign: MapIndex | None = None
        self.expect_new = False  # the next map starts a segment: no overlap test
        self.segment_ns: int | None = None  # a new SLAM map's segment starts here: older maps
        # belong to the segment before
        self.handed_ns: int | None = None  # stamp of the last map handed to the metric stage
        self.unhanded = False  # the map in use has not been handed to the metric stage yet
        self.shape: MapShape | None = None  # the map in use's shape
        # (hac_ros.core.geometry.map_shape)
        self.plane_unjudged = False  # the map in use is a plane not yet judged as a floor
        self.previous: MapIndex | None = None  # the map before the one in use
        self.degenerate = ''  # why the last map offered was refused as degenerate, until one serves

    # ------------------------------------------------------------------ maps in
    def judge(self, index: MapIndex, camera_map: np.ndarray | None
              ) -> tuple[MapIndex | None, str, str]:
        """``index`` as the calibrator may use it: itself, itself without a few points no SLAM
        produces (indexed again: rare), or None with the reason it is refused
        (``cloud_implausible``, ``map_degenerate``: at a point or on a line) and a text.
        camera_map: (3,) the last camera centre, SLAM units (None before any pose)."""
        far, median = implausible(index.sample, camera_map)
        share = float(far.mean()) if len(far) else 0.0
        if share > CLOUD_IMPLAUSIBLE_SHARE:
            return None, 'cloud_implausible', (
                f'a map cloud with {100 * share:.0f} % of its points 1000x nearer or further '
                'than its median depth from the camera: values no SLAM produces (a wrong byte '
                'order or field layout?): refused')
        if share > 0.0:
            far, _ = implausible(index.points_map, camera_map, median)
            index = MapIndex(index.points_map[~far], index.frame_id, index.stamp_ns,
                             self.params.index_max_points)
        kind = map_shape(index.sample, camera_map, index.axes).kind
        if kind in ('point', 'line'):
            self.degenerate = f'a map cloud whose points lie on one {kind}: no surface to measure'
            return None, 'map_degenerate', self.degenerate + ' (refused)'
        return index, '', ''

    def before_segment(self, stamp_ns: int) -> bool:
        """A map stamped before the segment of a new SLAM map began: the old map's."""
        return self.segment_ns is not None and stamp_ns < self.segment_ns

    def add(self, index: MapIndex) -> bool:
        """Keep ``index`` until a frame of its stamp; False when it is not newer than the map in
        use (superseded). A map of the same stamp as a waiting one replaces it. However far its
        stamp lags the poses, the newest map is used: maps are slow by nature."""
        if self.in_use is not None and index.stamp_ns <= self.in_use.stamp_ns:
            return False
        stamps = [m.stamp_ns for m in self.waiting]
        pos = bisect.bisect_right(stamps, index.stamp_ns)
        if pos and stamps[pos - 1] == index.stamp_ns:
            self.waiting[pos - 1] = index  # same stamp: the newer message wins
        else:
            self.waiting.insert(pos, index)
        del self.waiting[:-PENDING_MAPS_MAX]
        return True

    def refuse_foreign(self, map_frame: str) -> list[MapIndex]:
        """The waiting maps in another frame than ``map_frame`` (the first pose fixed it): taken
        out, the newest kept as ``foreign`` in case the poses reach its frame."""
        foreign = [m for m in self.waiting if m.frame_id != map_frame]
        self.waiting = [m for m in self.waiting if m.frame_id == map_frame]
        self.foreign = foreign[-1] if foreign else self.foreign
        return foreign

    def drop(self, segment_ns: int) -> None:
        """A new SLAM map from ``segment_ns`` on: the maps so far are gone, and any stamped
        before it; the next one starts the segment."""
        self.in_use = None
        self.waiting.clear()
        self.expect_new = True
        self.segment_ns = segment_ns

    @property
    def extent(self) -> float:
        """The extent of the map in use or about to be, SLAM units (0 without a map)."""
        latest = self.waiting[-1] if self.waiting else self.in_use
        return latest.extent if latest is not None else 0.0

    # ------------------------------------------------------------------ maps used
    def activate(self, stamp_ns: int, plane_problem: Callable[[MapIndex, MapShape], str]
                 ) -> tuple[MapIndex | None, bool, str]:
        """Make the latest waiting map not after ``stamp_ns`` the one in use (composed with the
        previous one in ``accumulate`` mode). Returns it (None: no change), whether it overlaps
        the previous one too little (the SLAM re-initialised), and why it was refused instead (a
        plane that ``plane_problem`` says cannot be the floor: '' when it can or cannot be told
        yet; the map in use stays)."""
        chosen = None
        while self.waiting and self.waiting[0].stamp_ns <= stamp_ns:
            chosen = self.waiting.pop(0)
        if chosen is None:
            return None, False, ''
        p, old = self.params, self.in_use
        chosen = chosen.composed(old if p.cloud_mode == CloudMode.ACCUMULATE else None,
                                 p.cloud_max_points, p.index_max_points)
        shape = chosen.shape
        why = plane_problem(chosen, shape)
        if why:
            self.degenerate = f'a map cloud on one plane that cannot be the floor: {why}'
            return None, False, self.degenerate + ' (refused)'
        # the maps share too few points either way (within a scene-relative radius;
        # MapIndex.overlap_fraction): a map that grew around the old one keeps the old points,
        # one that was pruned keeps its points near the old ones
        lost = (old is not None and not self.expect_new and p.cloud_mode == CloudMode.REPLACE
                and p.map_overlap_min > 0
                and chosen.overlap_fraction(old) < p.map_overlap_min
                and old.overlap_fraction(chosen) < p.map_overlap_min)
        self.expect_new = False
        self.previous, self.in_use, self.unhanded = old, chosen, True
        self.shape, self.plane_unjudged = shape, shape.kind == 'plane'
        if not self.plane_unjudged:
            self.degenerate = ''
        return chosen, lost, ''

    def refuse_in_use(self, why: str) -> None:
        """The plane map in use cannot be the floor after all (judged once the bodies gave their
        axis): the map before it serves again, if any."""
        self.degenerate = f'a map cloud on one plane that cannot be the floor: {why}'
        self.in_use, self.previous = self.previous, None
        self.shape, self.plane_unjudged, self.unhanded = None, False, self.in_use is not None

    def plane_judged(self) -> None:
        """The plane map in use can be the floor (a floor-only map)."""
        self.plane_unjudged, self.degenerate = False, ''

    def to_hand(self, stamp_ns: int) -> np.ndarray | None:
        """The map in use for the metric stage (/hac/cloud), thinned to ``cloud_out_max_points``
        ((N, 3) float32, SLAM units), at most once per ``cloud_min_period_s``: the cloud cannot be
        published more often, and offline every map handed over is kept until the end."""
        p, last = self.params, self.handed_ns
        if (not self.unhanded or self.in_use is None or not p.publish_cloud
                or (last is not None and stamp_ns - last < p.cloud_min_period_s * NS)):
            return None
        self.unhanded, self.handed_ns = False, stamp_ns
        return self.in_use.thinned(p.cloud_out_max_points)
