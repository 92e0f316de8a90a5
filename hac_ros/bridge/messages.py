"""Calibrator outputs → serialized ROS messages, shared by the node and the replay.

Both shells call :meth:`OutputMessages.convert` on every output of the
:class:`~hac_ros.core.calibrator.Calibrator` and publish (``Publisher.publish(bytes)``) or write
what comes back, so that the same recording gives the same bytes online and replayed. Each message
is built as a rosbags ROS 2 Jazzy message object (by :mod:`msg_adapters` where it converts numpy)
and serialized by rosbags' ``serialize_cdr``: CDR that rclpy reads as its own. The topics: one
table, :mod:`hac_ros.bridge.topics`; the (name, type) pairs below come from it.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from hac_ros.bridge import topics
from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import (
    CloudOut,
    DiagnosticsOut,
    HumanJointsOut,
    OdometryOut,
    Output,
    PoseOut,
    SampleOut,
    ScaleOut,
    Status,
)
from hac_ros.core.rules.health import Finding, Health, HealthMonitor
from hac_ros.core.rules.params import FrameAlignment, HacParams
from msg_adapters import (
    joints_to_pose_array,
    make_header,
    rosbags_types,
    rt_to_odometry,
    rt_to_pose_with_covariance_stamped,
    xyz_to_cloud,
)

# (name, type) of each output (hac_ros.bridge.topics)
ODOMETRY, POSE, HUMAN_JOINTS = topics.ODOMETRY.pair, topics.POSE.pair, topics.HUMAN_JOINTS.pair
SCALE, CLOUD, OBSTACLES = topics.SCALE.pair, topics.CLOUD.pair, topics.OBSTACLES.pair
MARKERS, DIAGNOSTICS, SAMPLES = topics.MARKERS.pair, topics.DIAGNOSTICS.pair, topics.SAMPLES.pair
OUTPUT_TOPICS = tuple(topic.pair for topic in topics.NODE_TOPICS)  # what the node publishes
SAMPLE_FIELDS = 4
SAMPLE_LABEL = 'person,scale,source(0 map 1 ground 2 rejected),accepted'
SOURCE_CODES = {'map': 0.0, 'ground': 1.0}
SOURCE_REJECTED = 2.0

DIAGNOSTIC_NAME = 'hac_ros: scale estimator'
PATH_LENGTH = 600  # camera positions kept for the path marker
# The camera path (600 points, 14 kB) and the ground plane are re-sent at most once per this much
# stamp time, the skeletons every frame: RViz keeps a marker until it is replaced (lifetime 0).
SLOW_MARKERS_PERIOD_NS = NS
PLANE_SIZE_M = 8.0  # side of the ground-plane marker, metres
PLANE_THICKNESS_M = 0.01
LINE_STRIP, LINE_LIST, CUBE = 4, 5, 1
ADD = 0
SKELETON_RGBA = (0.1, 0.9, 0.2, 1.0)
PATH_RGBA = (0.2, 0.4, 1.0, 1.0)
PLANE_RGBA = (0.6, 0.6, 0.6, 0.4)
SKELETON_WIDTH_M, PATH_WIDTH_M = 0.03, 0.02
IDENTITY_POSE = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])  # position, quaternion (x, y, z, w)
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
TYPES = rosbags_types(TYPESTORE)  # its message classes (dataclasses), by ROS name


def serialize(msg: Any, msgtype: str) -> bytes:
    """A message object of :data:`TYPES` of type ``msgtype`` -> its CDR bytes (little endian)."""
    return bytes(TYPESTORE.serialize_cdr(msg, msgtype))


@dataclass
class Message:
    """One serialized message to publish or write: topic (relative, see :func:`in_root`), type
    name, CDR bytes, stamp (log time)."""

    topic: str
    msgtype: str
    msg: bytes
    stamp_ns: int


def message(topic: tuple[str, str], msg: Any, stamp_ns: int) -> Message:
    """The :class:`Message` of a rosbags message object on ``topic`` (name, type)."""
    name, msgtype = topic
    return Message(name, msgtype, serialize(msg, msgtype), stamp_ns)


class OutputMessages:
    """Serializes the outputs; keeps the little state markers need (the camera path, the plane)."""

    def __init__(self, params: HacParams) -> None:
        self.health = HealthMonitor()  # the level and reasons of each /diagnostics status
        self.last_health: Health | None = None  # those of the last status made
        # the node's own findings and key-values, added to every status (None in the replay)
        self.extra_status: Callable[[], tuple[list[Finding], list[tuple[str, str]]]] | None = None
        self.params = params
        self._path = np.empty((PATH_LENGTH, 3))  # ring buffer of camera positions, metres
        self._path_count = 0
        self._status: Status | None = None
        self._plane: tuple[Status, np.ndarray] | None = None  # (status, pose (7,)) of the plane
        self._slow_sent_ns: int | None = None  # stamp of the last path and plane markers sent

    @property
    def params(self) -> HacParams:
        return self._params

    @params.setter
    def params(self, params: HacParams) -> None:
        """The parameters; a new set (the node's runtime change) also renews what derives from
        them: the skeleton marker's LINE_LIST point order, the layout's bones (parent, child)."""
        self._params = params
        self.health.gravity_wanted = params.metric_frame_alignment == FrameAlignment.GRAVITY
        self._bone_joints = np.array(params.layout().edges, dtype=int).reshape(-1)

    def convert(self, output: Output) -> list[Message]:
        """The messages of one calibrator output (none for samples, notices and resets)."""
        frame = self.params.metric_frame
        stamp = (output.status.stamp_ns if isinstance(output, DiagnosticsOut)
                 else output.stamp_ns)
        if isinstance(output, PoseOut):
            self._path[self._path_count % PATH_LENGTH] = output.position_metric
            self._path_count += 1
            return [message(POSE, rt_to_pose_with_covariance_stamped(
                output.rotation_metric, output.position_metric, stamp, frame, TYPES,
                output.covariance), stamp)]
        if isinstance(output, OdometryOut):
            return [message(ODOMETRY, rt_to_odometry(
                output.rotation_metric, output.position_metric, stamp, self.params.odom_frame,
                output.child_frame_id, TYPES, output.covariance, output.linear_velocity,
                output.angular_velocity, output.twist_covariance), stamp)]
        if isinstance(output, CloudOut):
            points = output.points_metric
            msgs = [message(CLOUD, xyz_to_cloud(points, stamp, frame, TYPES), stamp)]
            if topics.OBSTACLES.enabled(self.params) and output.levelled:
                z = points[:, 2]
                band = ((z >= self.params.obstacle_min_height)
                        & (z <= self.params.obstacle_max_height))
                msgs.append(message(OBSTACLES, xyz_to_cloud(points[band], stamp, frame, TYPES),
                                    stamp))
            return msgs
        if isinstance(output, HumanJointsOut):
            msgs = [message(HUMAN_JOINTS,
                            joints_to_pose_array(output.joints_metric, stamp, frame, TYPES), stamp)]
            if topics.MARKERS.enabled(self.params):
                msgs.append(Message(*MARKERS, self.markers(output), stamp))
            return msgs
        if isinstance(output, ScaleOut):
            return [message(SCALE, TYPES.get(SCALE[1])(data=float(output.scale)), stamp)]
        if isinstance(output, DiagnosticsOut):
            self._status = output.status
            extra, values = self.extra_status() if self.extra_status is not None else ([], [])
            return [Message(*DIAGNOSTICS, self.diagnostics(output.status, extra, values), stamp)]
        return []

    # ------------------------------------------------------------------ diagnostics
    def diagnostics(self, status: Status, extra: Sequence[Finding] = (),
                    extra_values: Sequence[tuple[str, str]] = (), take: bool = True) -> bytes:
        """/diagnostics: one DiagnosticStatus with the estimator's state as key-values, its level
        and message from :mod:`hac_ros.core.rules.health` (``reasons``: the findings' reasons).

        extra, extra_values: findings and key-values only the shell knows (the node's latency,
        backlog, stale input); take: False for a status that repeats the last one (the node's
        timer), whose counts must not be taken as seen."""
        values = [
            ('converged', str(status.converged).lower()),
            ('publishing', str(status.publishing).lower()),
            ('scale', f'{status.scale:.9g}'),
            ('spread', f'{status.spread:.9g}'),
            ('spread_stat', f'{status.spread_stat:.9g}'),
            ('samples', str(status.samples)),
            ('frames', str(status.frames)),
            ('people', str(status.people)),
            ('map_hits', str(status.map_hits)),
            ('ground_fallbacks', str(status.ground_fallbacks)),
            ('fallback_rate', f'{status.fallback_rate:.4f}'),
            ('resets', str(status.resets)),
            ('map_points', str(status.map_points)),
            ('drifting', str(status.drifting).lower()),
            ('frozen', str(status.frozen).lower()),
            ('alignment', status.alignment),
            ('rejected_total', str(sum(status.rejected.values()))),
        ]
        values += [(key, f'{value:.4g}') for key, value in (
            ('camera_height_m', status.camera_height_m), ('camera_pitch_deg',
                                                          status.camera_pitch_deg),
            ('camera_roll_deg', status.camera_roll_deg)) if math.isfinite(value)]
        values += [(f'service.{name}', str(count))
                   for name, count in sorted(status.services.items())]
        values += [(f'event.{kind}', str(count)) for kind, count in sorted(status.events.items())]
        values += [(f'rejected.{reason}', str(count))
                   for reason, count in sorted(status.rejected.items())]
        values += [(f'pose_match.{case}', str(count))
                   for case, count in sorted(status.pose_matches.items())]
        values += [(f'suspect.{key}', text) for key, text in sorted(status.suspects.items())]
        values += [(f'condition.{key}', text) for key, text in sorted(status.conditions.items())]
        values += list(extra_values)
        health = self.health.assess(status, extra) if take else self.health.peek(status, extra)
        self.last_health = health  # what the message says (the replay's summary counts them)
        values.append(('reasons', ','.join(health.reasons)))
        KeyValue = TYPES.get('diagnostic_msgs/msg/KeyValue')
        diagnostic = TYPES.get('diagnostic_msgs/msg/DiagnosticStatus')(
            level=health.level, name=DIAGNOSTIC_NAME, message=health.message,
            hardware_id=self.params.metric_frame,
            values=[KeyValue(key=key, value=value) for key, value in values])
        return serialize(TYPES.get(DIAGNOSTICS[1])(header=make_header(status.stamp_ns, '', TYPES),
                                                   status=[diagnostic]), DIAGNOSTICS[1])

    # ------------------------------------------------------------------ markers
    def markers(self, output: HumanJointsOut) -> bytes:
        """Skeletons (one LINE_LIST per person, the bones whose joints are both seen) every frame;
        the camera path and the ground plane
        with the first frame and then at most once per SLOW_MARKERS_PERIOD_NS of stamp time."""
        stamp, frame = output.stamp_ns, self.params.metric_frame
        people = []  # each person's bones with both ends seen (a NaN joint is not seen)
        for person, joints in enumerate(output.joints_metric):
            bones = joints[self._bone_joints].reshape(-1, 2, 3)
            bones = bones[np.isfinite(bones).all(axis=(1, 2))]
            if len(bones):
                people.append((person, bones.reshape(-1, 3)))
        path, plane = _NO_POINTS, None
        last = self._slow_sent_ns
        if last is None or not 0 <= stamp - last < SLOW_MARKERS_PERIOD_NS:
            path, plane = self._path_points(), self._plane_pose()
            if len(path) >= 2 or plane is not None:
                self._slow_sent_ns = stamp
        markers = [marker(stamp, frame, 'skeleton', person, LINE_LIST, IDENTITY_POSE,
                          (SKELETON_WIDTH_M, 0.0, 0.0), SKELETON_RGBA, bones)
                   for person, bones in people]
        if len(path) >= 2:
            markers.append(marker(stamp, frame, 'camera_path', 0, LINE_STRIP, IDENTITY_POSE,
                                  (PATH_WIDTH_M, 0.0, 0.0), PATH_RGBA, path))
        if plane is not None:
            markers.append(marker(stamp, frame, 'ground_plane', 0, CUBE, plane,
                                  (PLANE_SIZE_M, PLANE_SIZE_M, PLANE_THICKNESS_M), PLANE_RGBA))
        return serialize(TYPES.get(MARKERS[1])(markers=markers), MARKERS[1])

    def _path_points(self) -> np.ndarray:
        """The last PATH_LENGTH camera positions (N, 3), metres, oldest first."""
        n = self._path_count
        if n <= PATH_LENGTH:
            return self._path[:n]
        start = n % PATH_LENGTH
        return np.concatenate([self._path[start:], self._path[:start]])

    def _plane_pose(self) -> np.ndarray | None:
        """Pose (7,) of the ground-plane marker: a thin box whose z axis is the plane's normal."""
        status = self._status
        if status is None or status.ground_point_metric is None:
            return None
        if self._plane is None or self._plane[0] is not status:

            normal = np.asarray(status.ground_normal_metric, dtype=float)
            quat = Rotation.align_vectors([normal], [[0.0, 0.0, 1.0]])[0].as_quat()
            self._plane = (status, np.concatenate([status.ground_point_metric, quat]))
        return self._plane[1]


_NO_POINTS = np.empty((0, 3))


def marker(stamp_ns: int, frame_id: str, ns: str, marker_id: int, kind: int, pose: np.ndarray,
           scale: Sequence[float], rgba: Sequence[float], points: np.ndarray = _NO_POINTS) -> Any:
    """One visualization_msgs/Marker (ADD) in ``frame_id``: pose (7,) position (metres) and
    quaternion (x, y, z, w); scale (3,) metres; colour rgba (4,) in [0, 1]; points (N, 3) metres.
    Every other field is empty: lifetime 0 (kept until replaced), not frame-locked, no per-point
    colours, texture, mesh or text."""
    t = TYPES
    Point, no_bytes = t.get('geometry_msgs/msg/Point'), np.empty(0, np.uint8)
    x, y, z, qx, qy, qz, qw = np.asarray(pose, dtype=float).tolist()
    sx, sy, sz = scale
    r, g, b, a = rgba
    return t.get('visualization_msgs/msg/Marker')(
        header=make_header(stamp_ns, frame_id, t), ns=ns, id=marker_id, type=kind, action=ADD,
        pose=t.get('geometry_msgs/msg/Pose')(
            position=Point(x=x, y=y, z=z),
            orientation=t.get('geometry_msgs/msg/Quaternion')(x=qx, y=qy, z=qz, w=qw)),
        scale=t.get('geometry_msgs/msg/Vector3')(x=sx, y=sy, z=sz),
        color=t.get('std_msgs/msg/ColorRGBA')(r=r, g=g, b=b, a=a),
        lifetime=t.get('builtin_interfaces/msg/Duration')(sec=0, nanosec=0), frame_locked=False,
        points=[Point(x=px, y=py, z=pz) for px, py, pz in np.asarray(points, dtype=float).tolist()],
        colors=[], texture_resource='',
        texture=t.get('sensor_msgs/msg/CompressedImage')(
            header=make_header(0, '', t), format='', data=no_bytes),
        uv_coordinates=[], text='', mesh_resource='',
        mesh_file=t.get('visualization_msgs/msg/MeshFile')(filename='', data=no_bytes),
        mesh_use_embedded_materials=False)


def samples_message(samples: list[SampleOut]) -> bytes:
    """The /hac/samples message of one frame (see :data:`SAMPLES`)."""
    data = np.empty(SAMPLE_FIELDS * len(samples))
    for k, s in enumerate(samples):
        code = (SOURCE_CODES.get(s.source, SOURCE_REJECTED) if math.isfinite(s.scale)
                else SOURCE_REJECTED)
        start = SAMPLE_FIELDS * k
        data[start:start + SAMPLE_FIELDS] = (s.person, s.scale, code, float(s.accepted))
    dims = [('sample', len(samples), len(data)), (SAMPLE_LABEL, SAMPLE_FIELDS, SAMPLE_FIELDS)]
    Dimension = TYPES.get('std_msgs/msg/MultiArrayDimension')
    layout = TYPES.get('std_msgs/msg/MultiArrayLayout')(
        dim=[Dimension(label=label, size=size, stride=stride) for label, size, stride in dims],
        data_offset=0)
    return serialize(TYPES.get(SAMPLES[1])(layout=layout, data=data), SAMPLES[1])
