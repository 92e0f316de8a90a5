"""The parameters of hac_node and the commands: names, defaults, ranges, validation (docs/node.md).

The node declares exactly these fields as ROS parameters (with the description and range given
here) and the commands read the same parameters file (:mod:`hac_ros.files.params_file`); the
machinery (fields, checks, copies) is :mod:`hac_ros.core.basics.param_fields`, shared with
``hac_people_node``'s :mod:`hac_ros.people.params`.
Every length threshold is metric (applied after the current scale) or relative to the scene, never
a number of SLAM units (docs/interface.md, "Conventions").
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from hac_ros.core.basics.errors import ParameterError
from hac_ros.core.basics.param_fields import Choice, ParamSet
from hac_ros.core.basics.param_fields import param as _p  # short: the fields below align on it
from hac_ros.core.layouts import BUILT_IN, CUSTOM_ROLES, LAYOUTS, JointLayout, custom_layout

NODE_NAME = 'hac_node'

class ContactMode(Choice):
    """``contact_mode``: how the contact joint is chosen (docs/method.md)."""

    LOWEST = 'lowest'
    MAX_RATIO = 'max_ratio'
    LOWEST_GRAVITY = 'lowest_gravity'
    FEET = 'feet'
    PELVIS = 'pelvis'
    HEAD = 'head'


class ReferenceMode(Choice):
    """``reference_mode``: how a ray is measured in the map."""

    CONE_MEDIAN = 'cone_median'
    NEAREST_TO_RAY = 'nearest_to_ray'
    CONE_PLANE = 'cone_plane'
    FLOOR_PLANE = 'floor_plane'


class GroundMode(Choice):
    """``ground_mode``: where the floor's normal comes from."""

    HMR = 'hmr'
    SLAM_Y = 'slam_y'
    LARGEST_PLANE = 'largest_plane'
    NONE = 'none'


class PoseType(Choice):
    """``pose_type``: the message type of ``pose_topic``."""

    POSE_STAMPED = 'PoseStamped'
    ODOMETRY = 'Odometry'


class PoseSource(Choice):
    """``pose_source``: a topic, or TF."""

    TOPIC = 'topic'
    TF = 'tf'


class FrameAlignment(Choice):
    """``metric_frame_alignment``: the metric frame's axes."""

    GRAVITY = 'gravity'
    SLAM = 'slam'


class CloudMode(Choice):
    """``cloud_mode``: a new map replaces the one in use, or adds to it."""

    REPLACE = 'replace'
    ACCUMULATE = 'accumulate'


class HumanFilter(Choice):
    """``human_filter``: the world joints as measured, or smoothed."""

    NONE = 'none'
    SMOOTH = 'smooth'


class InputQos(Choice):
    """``input_qos``: the reliability of the pose and joints subscriptions."""

    BEST_EFFORT = 'best_effort'
    RELIABLE = 'reliable'


class CloudQos(Choice):
    """``cloud_qos``: the durability of the map subscription."""

    TRANSIENT_LOCAL = 'transient_local'
    VOLATILE = 'volatile'


# each parameter's choices, in the order the docs list them
CONTACT_MODES = tuple(m.value for m in ContactMode)
REFERENCE_MODES = tuple(m.value for m in ReferenceMode)
GROUND_MODES = tuple(m.value for m in GroundMode)
POSE_TYPES = tuple(m.value for m in PoseType)
POSE_SOURCES = tuple(m.value for m in PoseSource)
ALIGNMENTS = tuple(m.value for m in FrameAlignment)
# pose_type -> the ROS message type of pose_topic
POSE_MSGTYPES = {PoseType.POSE_STAMPED.value: 'geometry_msgs/msg/PoseStamped',
                 PoseType.ODOMETRY.value: 'nav_msgs/msg/Odometry'}
CLOUD_MODES = tuple(m.value for m in CloudMode)
HUMAN_FILTERS = tuple(m.value for m in HumanFilter)
INPUT_QOS = tuple(m.value for m in InputQos)
CLOUD_QOS = tuple(m.value for m in CloudQos)


@dataclass
class HacParams(ParamSet):
    """Every parameter of the node and the replay, with their names and defaults."""

    # --- topics and types (docs/interface.md, "Topics")
    pose_topic: str = _p('slam/pose', 'SLAM camera pose input (map frame, unknown scale)')
    cloud_topic: str = _p('slam/cloud', 'SLAM map points input (PointCloud2, map frame)')
    joints_topic: str = _p('hmr/joints',
                           'HMR joints input (PoseArray, camera optical frame, metres)')
    camera_info_topic: str = _p('camera/camera_info',
                                'CameraInfo of the camera; "" turns it off')
    pose_type: str = _p('PoseStamped', 'message type of pose_topic', choices=POSE_TYPES)
    pose_source: str = _p('topic', 'where the SLAM pose comes from: topic (pose_topic) or tf (the '
                          'transform slam_map_frame -> slam_pose_frame on /tf and /tf_static; the '
                          'node needs tf2_ros)', choices=POSE_SOURCES)
    slam_map_frame: str = _p('map', 'pose_source tf: the SLAM map frame')
    slam_pose_frame: str = _p('', 'pose_source tf: the frame whose pose the SLAM publishes (the '
                              'camera optical frame, or a body frame with pose_to_optical); '
                              'static transforms on the way are composed')
    metric_frame: str = _p('map_metric', 'frame_id of /hac/pose, /hac/human_joints, /hac/cloud')
    camera_frame: str = _p('', 'camera optical frame; "" = from the inputs')
    odom_frame: str = _p('hac_odom', 'frame_id of /hac/odometry (continuous)')
    metric_frame_alignment: str = _p('gravity', 'metric_frame: gravity (z up, floor at z = 0, x '
                                     'the first view) or slam (the SLAM map\'s axes, scaled)',
                                     choices=ALIGNMENTS)

    # --- method (docs/method.md)
    contact_mode: str = _p('lowest_gravity', 'how the contact joint is chosen',
                           choices=CONTACT_MODES)
    reference_mode: str = _p('cone_plane', 'map ray query (floor_plane: the floor plane found in '
                             'the map, no points near the contact: a sparse map)',
                             choices=REFERENCE_MODES)
    sole_correction: bool = _p(True, 'cast the contact joint\'s ray from the surface it touches: '
                               'the joint moved down by its height above the sole (a fraction of '
                               'the leg length per joint)')
    cone_angle_deg: float = _p(2.56, 'half angle of the ray cone (2.56 deg = authors cos 0.999)',
                               low=0.05, high=20.0)
    cone_min_points: int = _p(3, 'map points needed in the cone for a hit', low=1, high=1000)
    ground_mode: str = _p('hmr', 'ground plane strategy', choices=GROUND_MODES)
    static_camera: bool = _p(False, 'the camera does not move (a tripod, a wall): no SLAM pose '
                             'is needed (one given is used), slam_frozen is off, the people '
                             'stand upright; without a map the floor is one unit below the '
                             'camera, so the scale is the camera\'s height above the floor in '
                             'metres (docs/method.md, "A fixed camera")')

    # --- the HMR model's joints (core/layouts/); the index lists are for joint_layout custom
    joint_layout: str = _p('smpl24', 'joint order of each person in the joints message',
                           choices=LAYOUTS)
    joints_per_person: int = _p(0, 'custom: joints per person (ignored by the built-in layouts)',
                                low=0, high=10_000)
    contact_joints: list = _p([], 'custom: joints that may touch the scene (empty: all); also '
                              'the feet contact mode\'s', kind='indices')
    root_joints: list = _p([], 'custom: the root (mean of these): depth, world track; also the '
                           'pelvis contact mode\'s', kind='indices')
    body_axis_lower_joints: list = _p([], 'custom: lower end of the body\'s up axis (mean)',
                                      kind='indices')
    body_axis_upper_joints: list = _p([], 'custom: upper end of the body\'s up axis (mean); '
                                      'also the head contact mode\'s', kind='indices')
    skeleton_edges: list = _p([], 'custom: bones for the markers, flat index pairs',
                              kind='indices')

    # --- estimator
    window_s: float = _p(30.0, 'rolling window length, stamp seconds', low=0.1, high=1e6)
    window_max_samples: int = _p(2000, 'cap of samples in the window', low=1, high=10_000_000)
    min_samples: int = _p(10, 'samples a segment needs to converge online (nothing metric is '
                          'published before); offline a segment with fewer but at least 3 gets '
                          'its estimate, flagged "few samples"', low=1, high=100_000)
    converged_max_rel_sigma: float = _p(0.02, 'converged once the estimate\'s own relative '
                                        'uncertainty (1 sigma, the unobservable HMR and '
                                        'contact-height biases excluded) is under this, with '
                                        'min_samples samples; no longer above twice this',
                                        low=1e-6, high=10.0)

    # --- synchronisation
    sync_slop_s: float = _p(0.005, 'joints/pose stamp match tolerance, seconds', low=0.0, high=10.0)
    pose_buffer: int = _p(600, 'SLAM poses kept for matching', low=2, high=1_000_000)

    # --- map
    cloud_mode: str = _p('replace', 'each cloud replaces the map or adds to it',
                         choices=CLOUD_MODES)
    cloud_max_points: int = _p(2_000_000, 'cap of map points (oldest leave first)',
                               low=1, high=1_000_000_000)

    # --- QoS (node only)
    input_qos: str = _p('best_effort', 'QoS reliability of pose/joints subscriptions',
                        choices=INPUT_QOS)
    cloud_qos: str = _p('transient_local', 'QoS durability of the map subscription',
                        choices=CLOUD_QOS)
    joints_backlog_max: int = _p(2, 'node: joints frames that may wait to be processed, in input '
                                 'periods of work: beyond this many frames, the oldest are dropped '
                                 '(frames_dropped) when the frames waiting would take longer than '
                                 'this many input periods to process (with the older of two poses '
                                 'left side by side); larger trades '
                                 'drops for latency', low=1, high=100_000)
    latency_warn_s: float = _p(0.1, 'node: /diagnostics warns when the node is behind by more '
                               'than this (now minus the arrival of the oldest input waiting, or '
                               'the p99 of the recent joints frames from arrival to processed; '
                               'wall clock), seconds', low=0.0, high=1e6)
    stale_after_s: float = _p(2.0, 'node: no SLAM pose or joints for this long (wall clock): '
                              '/diagnostics says STALE (nothing) or WARN (one of them), seconds',
                              low=0.1, high=1e6)
    pose_coalesce_s: float = _p(0.01, 'node: SLAM poses faster than one per this (stamp '
                                'seconds) are thinned to it: a pose this close after the last one '
                                'kept is held, and coalesced into the next (its odometry not '
                                'published, counted as poses_coalesced) while that one is close '
                                'too; the newest and the pose before each joints frame are kept; '
                                '0 = every pose', low=0.0, high=1.0)
    log_period_s: float = _p(10.0, 'node: a status line in the log this often (scale, spread, '
                             'samples, status, frames received, processed, dropped); 0 = off, '
                             'wall seconds', low=0.0, high=1e6)
    autostart: bool = _p(False, 'hac_lifecycle_node: configure and activate at start (nav2\'s '
                         'convention); hac_node accepts it and is always active')
    publish_markers: bool = _p(True, 'publish /hac/markers for RViz')
    publish_cloud: bool = _p(True, 'publish /hac/cloud: the map in metric_frame, metres')
    cloud_republish_rel: float = _p(0.01, '/hac/cloud is republished when the estimate moved by '
                                    'more than this fraction', low=0.0, high=10.0)
    cloud_min_period_s: float = _p(5.0, '/hac/cloud at most once per this much stamp time, '
                                   'seconds', low=0.0, high=1e6)
    cloud_out_max_points: int = _p(30_000, 'points of /hac/cloud at most (the map thinned '
                                   'evenly); 30000 fit Fast DDS\'s default shared-memory segment: '
                                   'raise it with config/fastdds_large_data.xml in every process '
                                   'of the host (a larger cloud delays the other topics of a '
                                   'process that also takes it)', low=1, high=100_000_000)
    publish_obstacles: bool = _p(False, 'publish /hac/obstacles with /hac/cloud: its points '
                                 'between obstacle_min_height and obstacle_max_height above the '
                                 'floor (gravity alignment only), for costmaps')
    obstacle_min_height: float = _p(0.1, 'lowest obstacle point above the floor, metres',
                                    low=-10.0, high=100.0)
    obstacle_max_height: float = _p(2.0, 'highest obstacle point above the floor, metres',
                                    low=-10.0, high=100.0)
    human_filter: str = _p('smooth', 'world humans: none (the joints as they come) or smooth (each '
                           "person's world root filtered: causally online, zero-phase offline)",
                           choices=HUMAN_FILTERS)

    # --- tuning: documented extras with metric or scene-relative units
    interp_max_gap_s: float = _p(0.2, 'largest gap between two poses that a joints stamp may be '
                                 'interpolated across, seconds', low=0.0, high=60.0)
    plausibility_rel_tol: float = _p(0.2, 'a map hit is implausible when its metric distance '
                                     'differs from the joint distance by more than this fraction',
                                     low=0.01, high=10.0)
    ray_window_rel: float = _p(0.5, 'once a scale exists, map points are searched along the ray '
                               'within this fraction of the predicted distance; 0 = every point '
                               '(the literal authors method)', low=0.0, high=100.0)
    gate_k: float = _p(5.0, 'a new sample is gated when further than gate_k robust sigmas from '
                       'the median (once converged)', low=0.5, high=1000.0)
    gate_min_rel: float = _p(0.15, 'the gate is never narrower than this fraction of the median',
                             low=0.0, high=100.0)
    ground_inlier_m: float = _p(0.05, 'RANSAC inlier distance of contact points, metres',
                                low=1e-4, high=10.0)
    ground_ransac_iters: int = _p(300, 'RANSAC iterations of the plane fits', low=1, high=100_000)
    reset_jump_factor: float = _p(8.0, 'a pose step larger than this many times the recent median '
                                  'step (and than reset_jump_min_rel of the trajectory extent and '
                                  '1 % of the map extent) is a jump',
                                  low=1.5, high=1e6)
    reset_jump_min_rel: float = _p(0.05, 'a jump is at least this fraction of the trajectory '
                                   'extent so far', low=0.0, high=100.0)
    reset_confirm_poses: int = _p(3, 'poses after a jump that must continue from it to make it '
                                  'a SLAM re-initialisation', low=1, high=1000)
    time_jump_back_s: float = _p(1.0, 'a SLAM pose stamped this much (seconds) before the newest '
                                 'one, followed by reset_confirm_poses poses that go on from it, '
                                 'is time jumping back (a recording played again): a new stream '
                                 'starts; a smaller step back is a late message',
                                 low=0.0, high=1e9)
    time_jump_ahead_s: float = _p(60.0, 'a SLAM pose stamped this much (seconds) after the newest '
                                  'one is one stamp far ahead (refused) unless '
                                  'reset_confirm_poses poses go on from it: then a new segment '
                                  'starts', low=0.0, high=1e9)
    output_max_m: float = _p(1e5, 'no output carries a value beyond this many metres (nor a '
                             'non-finite one): such a message is suppressed, a cloud loses those '
                             'points (output_implausible)', low=1.0, high=1e12)
    map_overlap_min: float = _p(0.1, 'a new map overlapping the previous one less than this '
                                'fraction is a SLAM re-initialisation (0 disables)',
                                low=0.0, high=1.0)
    index_max_points: int = _p(262_144, 'maps larger than this are thinned uniformly at random '
                               'before indexing (bounds the per-frame cost)', low=1000,
                               high=1_000_000_000)
    seed: int = _p(0, 'seed of the RANSAC sampling (reproducible output)', low=0, high=2**31 - 1)
    base_frame: str = _p('', 'if set, /hac/odometry and /hac/pose describe this frame instead of '
                         'the camera')
    base_to_camera: list = _p([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
                              'camera pose in base_frame: x y z qx qy qz qw (metres)', length=7)
    pose_to_optical: list = _p([0.0, 0.0, 0.0, 1.0], 'the camera optical frame in the SLAM '
                               'pose\'s child frame: a rotation x y z w, the position unchanged '
                               '([-0.5, 0.5, -0.5, 0.5] for an x-forward, z-up camera body frame), '
                               'or x y z qx qy qz qw: the transform a wrapper composed its camera '
                               'pose with to report a body or base frame, the translation in the '
                               'pose\'s own (SLAM) units', length=(4, 7))
    hmr_focal_px: float = _p(0.0, 'focal length (pixels, CameraInfo\'s resolution) the HMR model '
                             'assumed when placing people in depth; 0 = the camera\'s own '
                             '(needs CameraInfo)', low=0.0, high=1e6)
    orientation_variance: float = _p(1e-4, 'variance reported for each orientation axis, rad^2',
                                     low=0.0, high=1e6)
    publish_tf: bool = _p(False, 'broadcast metric_frame -> odom_frame on TF, the correction that '
                          'composes /hac/odometry into /hac/pose (needs tf2_ros)')
    publish_odom_tf: bool = _p(False, 'broadcast odom_frame -> the child frame of /hac/odometry on '
                               'TF (needs tf2_ros)')

    # ------------------------------------------------------------------ validation
    def check(self) -> None:
        """The checks between fields: raise :class:`ParameterError` naming the first invalid."""
        if self.reference_mode == ReferenceMode.CONE_MEDIAN and self.cone_min_points < 1:
            raise ParameterError('cone_min_points: must be >= 1')
        if self.obstacle_min_height >= self.obstacle_max_height:
            raise ParameterError('obstacle_min_height: must be below obstacle_max_height')
        if self.pose_source == PoseSource.TF and not self.slam_pose_frame.strip('/'):
            raise ParameterError('slam_pose_frame: pose_source tf needs the frame whose pose the '
                                 'SLAM publishes in TF (its camera optical or body frame)')
        if self.pose_source == PoseSource.TF and (self.slam_pose_frame.strip('/')
                                         == self.slam_map_frame.strip('/')):
            raise ParameterError('slam_pose_frame: must differ from slam_map_frame')
        if abs(math.sqrt(sum(x * x for x in self.pose_to_optical[-4:])) - 1.0) > 1e-3:
            raise ParameterError('pose_to_optical: the quaternion (its last 4 values, x y z w) '
                                 'must be unit')
        self.layout()  # a custom layout raises on missing roles or indices outside the person
        q = self.base_to_camera[3:]
        if abs(math.sqrt(sum(x * x for x in q)) - 1.0) > 1e-3:
            raise ParameterError('base_to_camera: the quaternion (last 4 values) must be unit')

    def layout(self) -> JointLayout:
        """The joint layout these parameters select (``joint_layout``; ``custom`` from
        ``joints_per_person`` and its index lists)."""
        if self.joint_layout != 'custom':
            return BUILT_IN[self.joint_layout]
        return custom_layout(self.joints_per_person,
                             {name: getattr(self, name) for name in CUSTOM_ROLES})


def names() -> list[str]:
    """Every parameter name, in declaration order."""
    return HacParams.names()


def describe(name: str) -> dict[str, Any]:
    """The description, default and range of one parameter (for ParameterDescriptors, docs)."""
    return HacParams.describe(name)
