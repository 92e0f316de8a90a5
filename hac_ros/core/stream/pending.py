"""Metric records: what a metric output is before a scale is applied to it.

The :class:`~hac_ros.core.calibrator.Calibrator` makes one of these wherever a metric output
(odometry and pose, world joints and scale, the cloud, a status) is due, with its SLAM-unit
quantities; the :class:`~hac_ros.core.stream.metric_stage.MetricStage` turns it into the output with
the published scale. Online that happens at once; offline (``Calibrator(offline=True)``) the records
wait in the calibrator's journal until the whole recording's schedule is known
(:func:`hac_ros.core.offline.resolve_offline`). They never leave the core.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hac_ros.core.basics.outputs import Output, Status

if TYPE_CHECKING:
    from hac_ros.core.geometry.plane import Plane


@dataclass(slots=True)
class PendingSegment:
    """A segment (one SLAM map, between re-initialisations) starts at this pose: R_wc (3, 3), c_map
    (3,) SLAM units, its map frame; ``index`` counts segments from 0; ``keeps_map``: the map in use
    stays valid (a service reset); ``cause``: '' for the first segment, else the reset's cause."""

    stamp_ns: int
    index: int
    R_wc: np.ndarray
    c_map: np.ndarray
    keeps_map: bool = False
    cause: str = ''


@dataclass(slots=True)
class PendingMap:
    """A new map used by the frames from ``stamp_ns`` on (handed over at most once per
    ``cloud_min_period_s``): points_slam (N, 3) float32, SLAM units, segment ``segment``'s map
    frame, already thinned to ``cloud_out_max_points``."""

    stamp_ns: int
    segment: int
    points_slam: np.ndarray


@dataclass(slots=True)
class PendingOdometry:
    """The odometry and pose of one SLAM pose before a scale is applied.

    R_wc: (3, 3) camera to SLAM map; c_map: (3,) camera centre, SLAM units, map frame;
    sigma_scale: the online estimate's standard error then, metres per SLAM unit (NaN before any
    sample), for the covariance; plane: the ground plane then (SLAM map frame) or None;
    ground_share: the fraction of the window's recent samples the ground plane gave.
    """

    stamp_ns: int
    child_frame_id: str
    segment: int
    R_wc: np.ndarray
    c_map: np.ndarray
    sigma_scale: float
    plane: Plane | None = None
    ground_share: float = 0.0


@dataclass(slots=True)
class PendingFrame:
    """A processed frame's world joints and scale before a scale is applied.

    R_wc, c_map: the frame's camera pose (SLAM map frame, SLAM units); joints_cam: (P, K, 3)
    metres, camera optical frame; spread: the estimator's spread after the frame; plane: the
    ground plane then (SLAM map frame) or None.
    """

    stamp_ns: int
    segment: int
    R_wc: np.ndarray
    c_map: np.ndarray
    joints_cam: np.ndarray
    spread: float
    plane: Plane | None = None


@dataclass(slots=True)
class PendingStatus:
    """A /diagnostics status whose metric ground plane is still to be placed.

    status: every SLAM-unit field filled, the metric ones None; plane: the ground plane (SLAM map
    frame) or None; c_map: (3,) the last camera centre, SLAM units (the plane point below it);
    R_wc: (3, 3) the last camera-to-map rotation (the camera's tilt over the plane); segment: the
    segment then.
    """

    status: Status
    plane: Plane | None
    c_map: np.ndarray | None
    R_wc: np.ndarray | None
    segment: int = 0


Pending = PendingSegment | PendingMap | PendingOdometry | PendingFrame | PendingStatus
# what the calibrator's steps produce: outputs, and metric records not yet resolved
Record = Output | Pending
PENDING = (PendingSegment, PendingMap, PendingOdometry, PendingFrame, PendingStatus)


def outputs_only(records: list[Record]) -> list[Output]:
    """The outputs among ``records``, in order (the metric records left out)."""
    return [r for r in records if not isinstance(r, PENDING)]
