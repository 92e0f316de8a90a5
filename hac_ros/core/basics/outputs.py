"""What the :class:`~hac_ros.core.calibrator.Calibrator` hands back: plain numpy results.

The node turns them into messages and publishes them; the replay turns them into the same messages
and writes them at their ``stamp_ns``. Every ``stamp_ns`` is an input header stamp (int
nanoseconds).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(slots=True)
class OdometryOut:
    """/hac/odometry: the continuous metric odometry of the camera (or of ``base_frame``) at one
    SLAM pose stamp (hac_ros.core.stream.odometry).

    rotation_metric: (3, 3) float64, child frame to ``odom_frame``.
    position_metric: (3,) float64, metres, ``odom_frame``.
    covariance: (6, 6) float64, ROS order (x, y, z, rot x, rot y, rot z), metres² and rad².
    linear_velocity: (3,) float64, m/s, child frame; angular_velocity: (3,) rad/s, child frame;
    twist_covariance: (6, 6) float64, (m/s)² and (rad/s)².
    """

    stamp_ns: int
    child_frame_id: str
    rotation_metric: np.ndarray
    position_metric: np.ndarray
    covariance: np.ndarray
    linear_velocity: np.ndarray
    angular_velocity: np.ndarray
    twist_covariance: np.ndarray


@dataclass(slots=True)
class PoseOut:
    """/hac/pose: the globally consistent metric pose of the camera (or of ``base_frame``) at one
    SLAM pose stamp: rotation_metric (3, 3) child frame to ``metric_frame``, position_metric (3,)
    metres, covariance (6, 6) metres² and rad² (ROS order)."""

    stamp_ns: int
    child_frame_id: str
    rotation_metric: np.ndarray
    position_metric: np.ndarray
    covariance: np.ndarray


@dataclass(slots=True)
class CloudOut:
    """/hac/cloud: the map in ``metric_frame``: points_metric (N, 3) float32, metres;
    ``levelled``: the frame is gravity-aligned (z up, the floor at z = 0)."""

    stamp_ns: int
    points_metric: np.ndarray
    levelled: bool = False


@dataclass(slots=True)
class HumanJointsOut:
    """The frame's joints in the metric world. joints_metric: (P, K, 3) float64, metres,
    metric_frame."""

    stamp_ns: int
    joints_metric: np.ndarray


@dataclass(slots=True)
class ScaleOut:
    """The current scale (metres per SLAM unit) after the frame of ``stamp_ns`` was processed."""

    stamp_ns: int
    scale: float
    spread: float  # the estimate's own standard deviation, metres per SLAM unit (its ±)


@dataclass(slots=True)
class SampleOut:
    """One per-person scale sample of one frame (for plots and analysis; not a ROS topic).

    source: 'map' (ray query), 'ground' (ground-plane fallback) or the rejection reason.
    """

    stamp_ns: int
    person: int
    scale: float  # NaN when rejected
    source: str
    accepted: bool


@dataclass
class Status:
    """A snapshot of the estimator for /diagnostics (and the replay summary)."""

    stamp_ns: int
    converged: bool
    scale: float  # NaN before any sample
    # the ± a user reads: the estimate's own standard deviation and the layout's prior for the
    # biases no sample shows, in quadrature, metres per SLAM unit; inf early
    spread: float
    samples: int
    frames: int
    people: int
    map_hits: int
    ground_fallbacks: int
    resets: int
    rejected: dict[str, int] = field(default_factory=dict)
    map_points: int = 0
    ground_normal_map: np.ndarray | None = None  # (3,) unit, SLAM map frame, points down
    ground_offset_slam: float = float('nan')  # plane n·p = b, SLAM units
    ground_normal_metric: np.ndarray | None = None  # (3,) unit, metric frame, points down
    # (3,) metres, metric frame: the plane below the camera
    ground_point_metric: np.ndarray | None = None
    drifting: bool = False  # the evidence says the scale drifts (hac_ros.core.estimate.estimator)
    frozen: bool = False  # the scale is held (~/freeze)
    alignment: str = ''  # the metric frame of the current segment: 'gravity' or 'slam'
    services: dict[str, int] = field(default_factory=dict)  # service requests taken, by name
    suspects: dict[str, str] = field(default_factory=dict)  # convention warnings (convention_check)
    events: dict[str, int] = field(default_factory=dict)  # time jumps, by kind (core.timeline)
    # conditions that hold now and make the status WARN: reason -> text (hac_ros.core.rules.health)
    conditions: dict[str, str] = field(default_factory=dict)
    # how frames found their SLAM pose: 'exact' (within sync_slop_s), 'interpolated'
    pose_matches: dict[str, int] = field(default_factory=dict)
    spread_stat: float = float('nan')  # the estimate's own standard deviation (σ_stat), same unit
    # the camera over the ground plane, once there are a plane and a scale: its height (metres),
    # its pitch (degrees its optical axis points below the horizon) and roll (degrees its x axis
    # turns about the optical axis, clockwise in the image)
    camera_height_m: float = float('nan')
    camera_pitch_deg: float = float('nan')
    camera_roll_deg: float = float('nan')
    publishing: bool = False  # metric outputs flow: from the segment's first convergence on

    @property
    def fallback_rate(self) -> float:
        used = self.map_hits + self.ground_fallbacks
        return self.ground_fallbacks / used if used else 0.0


@dataclass(slots=True)
class DiagnosticsOut:
    """Emitted once per second of stamp time (the first input of each new second)."""

    status: Status


@dataclass(slots=True)
class ResetOut:
    """The estimator was reset. cause: a SLAM re-initialisation ('pose_jump', 'map_frame',
    'map_overlap'), a service ('service'), or header time that jumped ('time_jump_back': a new
    stream, 'time_jump_ahead': a new segment)."""

    stamp_ns: int
    cause: str


@dataclass(slots=True)
class MapRescaleOut:
    """A new map came into use with another scale than the map before it (the map's own word:
    hac_ros.core.geometry.reference.MapIndex.rescale_against): the scale is ``factor`` times what it
    was (new over old, metres per SLAM unit); the samples before it were measured in the old unit.
    ``since_ns``: the stamp of the map it replaced (the change came about in between)."""

    stamp_ns: int
    factor: float
    since_ns: int


@dataclass(slots=True)
class NoticeOut:
    """Something a human should read once: the first rejection of each cause, a reset, a relock.

    The shells log it (the node with its logger, the replay on stderr) so that both log the same
    things once per cause, not once per message.
    """

    stamp_ns: int
    cause: str
    text: str
    level: str = 'warn'  # 'info' | 'warn' | 'error'


Output = (OdometryOut | PoseOut | CloudOut | HumanJointsOut | ScaleOut | SampleOut | DiagnosticsOut
          | ResetOut | MapRescaleOut | NoticeOut)
