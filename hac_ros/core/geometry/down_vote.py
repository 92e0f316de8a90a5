"""Which way is down, from the scene: never from the camera's axes (a camera mounted at any roll
calibrates; docs/method.md, "Which way is down").

Each body's axis (the layout's lower → upper joints, rotated into the map) gives the vertical *line*
to a degree or so; which way along it is down is the scene's to say. For each of the two ways along
it, the floor would be the map's lowest dense surface that way (:meth:`MapIndex.floor_offset`, as
the ground model finds it), and each body's contact the joint lowest that way (the feet standing,
the hands on the hands). The true way has two marks the other lacks:

- **the contact lies below the camera**: a camera stands above the floor its people stand on, so
  the ray to the contact goes down and meets that floor in front of the camera, for every body;
  the other way, the "contact" is a head, and its ray goes "down" only while the camera is lower
  than the head;
- **one scale for all**: where the contact's ray meets the floor, its metric distance over the
  map's distance is the scale, the same for every body and frame (to the HMR's few per cent);
  the other way the ray meets a ceiling, the tops of things or nothing, at ratios that scatter.

:class:`DownVote` pools, per way, the share of bodies whose contact ray meets that way's floor in
front of the camera and the relative spread (MAD over median) of their ratios. After
DOWN_BODIES_MIN bodies, a way is down when at least DOWN_VALID_MIN of its rays meet its floor and
the other way's meet theirs less than DOWN_VALID_OTHER_MAX of the time, or scatter DOWN_SPREAD_RATIO
times as much. People lying alone (their axis level) give no answer: both ways meet walls alike.
Scale-free and roll-free. Down, once decided, stays for the segment.

A map that is one plane (hac_ros.core.geometry.map_shape: a floor-only map) says it at once: its
floor is below the camera, so down is the way along the bodies' axis towards the plane, once
DOWN_BODIES_MIN bodies' axis lies within PLANE_TILT_MAX_DEG of its normal (a wall is refused).
The vote cannot tell there: along an axis tilted by HMR's noise a plane's far parts lie above the
camera, so both ways' rays meet "a floor" (seen on a real-motion composite: 5 bodies decided
upside down, and the run calibrated nothing).
"""
from __future__ import annotations

import math

import numpy as np

from hac_ros.core.basics.numeric import median_of
from hac_ros.core.geometry.map_shape import PLANE_TILT_MAX_DEG, MapShape, tilt_deg
from hac_ros.core.geometry.reference import MapIndex
from hac_ros.core.layouts import JointLayout

DOWN_BODIES_MIN = 5  # bodies before down is decided
DOWN_VALID_MIN = 0.8  # share of a way's contact rays that must meet its floor in front
DOWN_VALID_OTHER_MAX = 0.5  # ... while the other way's meet theirs less often than this,
DOWN_SPREAD_RATIO = 2.0  # ... or scatter this many times as much (MAD / median of the ratios)
DOWN_POOL_MAX = 400  # ratios kept per way (memory stays flat)


class DownVote:
    """The bodies' evidence for which way along their axis is down, until it decides."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self._bodies = 0
        self._valid = [0, 0]  # per way (0: against the bodies' up, 1: along it)
        self._ratios: tuple[list[float], list[float]] = ([], [])
        self._down: np.ndarray | None = None
        self._up_sum = np.zeros(3)  # the bodies' up axes (lower → upper joints), map frame
        self._below: np.ndarray | None = None  # a plane map's normal towards it from the camera
        self.along_up = False  # once decided: down is along the bodies' up (on their hands)

    @property
    def wanted(self) -> bool:
        """Whether down is still to be decided."""
        return self._down is None

    def add(self, layout: JointLayout, joints_cam: np.ndarray, R_wc: np.ndarray,
            c_map: np.ndarray, map_index: MapIndex, up_map: np.ndarray,
            shape: MapShape | None = None) -> None:
        """One body: joints_cam (K, 3) metres, camera optical frame, finite; R_wc (3, 3) camera to
        map; c_map (3,) camera centre, SLAM units; up_map (3,) this body's up axis (the layout's
        lower → upper joints), unit, map frame. The two ways are taken along it: against it (way
        0: standing) and along it (way 1: on the hands). ``shape``: the map's (a plane decides,
        module docstring)."""
        self._up_sum += up_map
        if shape is not None and shape.kind == 'plane':
            side = shape.offset - float(shape.normal @ c_map)  # the plane from the camera, along n
            self._below = shape.normal * math.copysign(1.0, side) if side != 0.0 else None
        floors = (map_index.floor_offset(-up_map), map_index.floor_offset(up_map))
        allowed = list(layout.contact) or list(range(len(joints_cam)))
        if not np.isfinite(joints_cam[allowed]).all():  # a candidate not seen: no vote
            self._down = self._decide()
            return
        self._bodies += 1
        for way, down in enumerate((-up_map, up_map)):
            down_cam = R_wc.T @ down
            contact = allowed[int(np.argmax(joints_cam[allowed] @ down_cam))]
            joint = joints_cam[contact]
            distance_metric = float(np.linalg.norm(joint))
            if joint[2] <= 0.0 or distance_metric <= 0.0:
                continue
            towards = float(down_cam @ joint) / distance_metric  # the ray's cosine with down
            below = floors[way] - float(down @ c_map)  # the floor's depth below the camera
            if towards <= 0.0 or below <= 0.0 or not math.isfinite(below):
                continue
            self._valid[way] += 1
            if len(self._ratios[way]) < DOWN_POOL_MAX:
                self._ratios[way].append(distance_metric * towards / below)
        self._down = self._decide()

    def _decide(self) -> np.ndarray | None:
        norm = float(np.linalg.norm(self._up_sum))
        if self._bodies < DOWN_BODIES_MIN or norm <= 0.0:
            return None
        up = self._up_sum / norm
        if self._below is not None and tilt_deg(self._below, up) <= PLANE_TILT_MAX_DEG:
            self.along_up = float(self._below @ up) > 0.0
            return up if self.along_up else -up
        share = [v / self._bodies for v in self._valid]
        spread = [_relative_spread(r) for r in self._ratios]
        for way, other in ((0, 1), (1, 0)):
            if share[way] < DOWN_VALID_MIN:
                continue
            if (share[other] < DOWN_VALID_OTHER_MAX
                    or spread[way] * DOWN_SPREAD_RATIO < spread[other]):
                self.along_up = way == 1
                return -up if way == 0 else up
        return None

    def down(self) -> np.ndarray | None:
        """Down (3,), unit, map frame, once decided (the bodies' mean axis, signed); else None."""
        return self._down

    def orient(self, normal: np.ndarray) -> np.ndarray | None:
        """``normal`` (3,) turned to point down, or None while down is undecided."""
        if self._down is None:
            return None
        return normal if float(normal @ self._down) >= 0.0 else -normal


def _relative_spread(values: list[float]) -> float:
    """MAD over median of ``values`` (inf for fewer than three)."""
    if len(values) < 3:
        return math.inf
    array = np.asarray(values)
    median = median_of(array)
    return median_of(np.abs(array - median)) / median if median > 0.0 else math.inf
