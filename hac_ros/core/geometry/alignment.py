"""Where one SLAM map (a segment between re-initialisations) sits in the metric frame.

docs/interface.md, "The metric frame" (``metric_frame_alignment``). A segment's map is placed by a
similarity

    p_metric = R · s · (p_slam − origin) + offset

(R (3, 3) SLAM map frame to metric frame; origin (3,) SLAM units; offset (3,) metres; s the scale
of the moment, metres per SLAM unit):

- ``gravity`` (the default): z up against the ground normal, the floor at z = 0, x the viewing
  direction of the segment's first SLAM pose projected on the floor, the origin on the floor below
  that pose (:func:`levelled`). A planner's 2-D costmap works in it directly. The normal and the
  floor come from the ground model, so online the alignment is refined as the ground model
  improves.
- ``slam``: the SLAM map's own axes, scaled (R = I, origin 0, offset 0).

Across a SLAM re-initialisation the metric frame stays the same physical frame: in ``gravity``
the new segment's yaw, x and y come from the anchor, the last published metric pose, which is where
the new segment's first pose is (:func:`placed`: in the levelled frame that pose is right above the
origin), its roll, pitch and z are levelled again from the new segment's own floor; in ``slam``
the anchor fixes all six degrees of freedom (:func:`slam_continuing`). Pure numpy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hac_ros.core.geometry.plane import Plane

# a camera looking this close to straight down has no heading: its x axis is used instead
MIN_HEADING_NORM = 0.1


@dataclass(frozen=True)
class Alignment:
    """The similarity of one segment (module docstring): rotation (3, 3) SLAM map to metric frame,
    origin (3,) SLAM units, offset (3,) metres; ``levelled``: z is up and the floor at z = 0."""

    rotation: np.ndarray
    origin: np.ndarray
    offset: np.ndarray
    levelled: bool = False

    @classmethod
    def identity(cls) -> Alignment:
        return cls(np.eye(3), np.zeros(3), np.zeros(3))

    def point(self, p_slam: np.ndarray, scale: float) -> np.ndarray:
        """(..., 3) SLAM units, map frame -> (..., 3) metres, metric frame."""
        return (scale * (np.asarray(p_slam) - self.origin)) @ self.rotation.T + self.offset

    def camera(self, R_wc: np.ndarray, c_map: np.ndarray, scale: float
               ) -> tuple[np.ndarray, np.ndarray]:
        """A camera-to-map pose (R_wc (3, 3), c (3,) SLAM units) -> camera-to-metric (R (3, 3),
        centre (3,) metres)."""
        return self.rotation @ R_wc, self.point(c_map, scale)

    def moved_from(self, other: Alignment, scale: float,
                   at_slam: np.ndarray) -> tuple[float, float]:
        """How far this alignment is from ``other``: (rotation angle, degrees; metres the point
        ``at_slam`` (SLAM units) moves in the metric frame at ``scale``)."""
        cos = (np.trace(self.rotation.T @ other.rotation) - 1.0) * 0.5
        angle = math.degrees(math.acos(min(max(cos, -1.0), 1.0)))
        shift = self.point(at_slam, scale) - other.point(at_slam, scale)
        return angle, float(np.linalg.norm(shift))


def gravity_rotation(normal_down: np.ndarray, R_wc: np.ndarray) -> np.ndarray | None:
    """The rotation (3, 3) from the SLAM map frame to a frame with z up (against ``normal_down``,
    (3,) unit, map frame) and x the camera's viewing direction (R_wc's z axis) projected on the
    floor; None when the camera looks along the normal and has no other usable axis."""
    up = -np.asarray(normal_down, dtype=float)
    up = up / np.linalg.norm(up)
    for axis in (R_wc[:, 2], R_wc[:, 0]):  # the view, else the camera's x axis
        heading = axis - (axis @ up) * up
        norm = float(np.linalg.norm(heading))
        if norm >= MIN_HEADING_NORM:
            x = heading / norm
            return np.stack([x, np.cross(up, x), up])
    return None


def levelled(plane: Plane, R_wc: np.ndarray, c_map: np.ndarray) -> Alignment | None:
    """The ``gravity`` alignment of a segment whose first pose is (R_wc, c_map): z up against the
    plane's normal, the floor (the plane) at z = 0, x the first view projected on the floor, the
    origin on the floor below the first camera. None without a usable heading."""
    rotation = gravity_rotation(plane.normal, R_wc)
    if rotation is None:
        return None
    c = np.asarray(c_map, dtype=float)
    below = c + (plane.offset - plane.normal @ c) * plane.normal  # the floor point below c
    return Alignment(rotation, below, np.zeros(3), levelled=True)


def placed(level: Alignment, yaw: float, x: float, y: float) -> Alignment:
    """A levelled alignment turned by ``yaw`` (rad, about z) and moved by (x, y) metres: its
    origin (below the segment's first camera) lands at (x, y, 0), its x axis at heading ``yaw``."""
    c, s = math.cos(yaw), math.sin(yaw)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return Alignment(turn @ level.rotation, level.origin, np.array([x, y, 0.0]), levelled=True)


def heading(R_metric: np.ndarray) -> float:
    """The heading (rad, about z) of a camera's view (R_metric: camera to a levelled metric frame);
    0 when it looks straight up or down."""
    view = np.asarray(R_metric)[:, 2]
    if math.hypot(view[0], view[1]) <= 1e-9:
        return 0.0
    return math.atan2(float(view[1]), float(view[0]))


def slam_continuing(last_rotation: np.ndarray, last_position: np.ndarray, R_wc: np.ndarray,
                    c_map: np.ndarray) -> Alignment:
    """``slam`` across a re-initialisation: the new segment's first pose (R_wc, c_map: new map
    frame, SLAM units) placed exactly on the last published metric pose (last_rotation camera to
    metric, last_position metres): all six degrees of freedom from the anchor."""
    return Alignment(np.asarray(last_rotation) @ np.asarray(R_wc).T,
                     np.asarray(c_map, dtype=float).copy(),
                     np.asarray(last_position, dtype=float).copy())
