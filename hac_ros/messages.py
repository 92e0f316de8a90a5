"""Calibrator outputs → ROS messages, shared by the node (rclpy classes) and the replay (rosbags).

Both shells call :meth:`OutputMessages.convert` on every output of the
:class:`~hac_ros.core.calibrator.Calibrator` and publish or write what comes back, so that the same
recording gives the same messages online and replayed. Topics and types: SPEC, "Outputs".
"""
from __future__ import annotations

import dataclasses
from collections import deque
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from hac_ros.core.outputs import (DiagnosticsOut, HumanJointsOut, OdometryOut, Output, ScaleOut,
                                  Status)
from hac_ros.core.params import HacParams
from msg_adapters import joints_to_pose_array, make_header, rt_to_odometry

ODOMETRY = ('/hac/odometry', 'nav_msgs/msg/Odometry')
HUMAN_JOINTS = ('/hac/human_joints', 'geometry_msgs/msg/PoseArray')
SCALE = ('/hac/scale', 'std_msgs/msg/Float64')
MARKERS = ('/hac/markers', 'visualization_msgs/msg/MarkerArray')
DIAGNOSTICS = ('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray')
OUTPUT_TOPICS = (ODOMETRY, HUMAN_JOINTS, SCALE, MARKERS, DIAGNOSTICS)

DIAGNOSTIC_NAME = 'hac_ros: scale estimator'
PATH_LENGTH = 600  # camera positions kept for the path marker
PLANE_SIZE_M = 8.0  # side of the ground-plane marker, metres
# SMPL-24 bones (parent, child) for the skeleton marker
BONES = ((0, 1), (0, 2), (0, 3), (1, 4), (2, 5), (3, 6), (4, 7), (5, 8), (6, 9), (7, 10), (8, 11),
         (9, 12), (9, 13), (9, 14), (12, 15), (13, 16), (14, 17), (16, 18), (17, 19), (18, 20),
         (19, 21), (20, 22), (21, 23))
LINE_STRIP, LINE_LIST, CUBE = 4, 5, 1
DIAG_OK, DIAG_WARN = 0, 1


@dataclass
class Message:
    """One message to publish or write: topic, type name, the message, and its stamp (log time)."""

    topic: str
    msgtype: str
    msg: Any
    stamp_ns: int


class OutputMessages:
    """Builds the output messages; keeps the little state markers need (the camera path)."""

    def __init__(self, params: HacParams, types: Any) -> None:
        self.params = params
        self.types = types
        self._path: deque[np.ndarray] = deque(maxlen=PATH_LENGTH)
        self._status: Status | None = None
        self._plane_cache: tuple[Status, Any] | None = None  # rebuilt when the status changes

    def convert(self, output: Output) -> list[Message]:
        """The messages of one calibrator output (none for samples, notices and resets)."""
        frame = self.params.metric_frame
        if isinstance(output, OdometryOut):
            self._path.append(output.position_metric)
            msg = rt_to_odometry(output.rotation_metric, output.position_metric, output.stamp_ns,
                                 frame, output.child_frame_id, self.types,
                                 covariance=output.covariance, linear=output.linear_velocity,
                                 angular=output.angular_velocity)
            return [Message(*ODOMETRY, msg, output.stamp_ns)]
        if isinstance(output, HumanJointsOut):
            msgs = [Message(*HUMAN_JOINTS, joints_to_pose_array(output.joints_metric, output.stamp_ns,
                                                                frame, self.types), output.stamp_ns)]
            if self.params.publish_markers:
                msgs.append(Message(*MARKERS, self.markers(output), output.stamp_ns))
            return msgs
        if isinstance(output, ScaleOut):
            return [Message(*SCALE, new_message(self.types, SCALE[1], data=float(output.scale)),
                            output.stamp_ns)]
        if isinstance(output, DiagnosticsOut):
            self._status = output.status
            return [Message(*DIAGNOSTICS, self.diagnostics(output.status), output.status.stamp_ns)]
        return []

    # ------------------------------------------------------------------ diagnostics
    def diagnostics(self, status: Status) -> Any:
        """/diagnostics: one DiagnosticStatus with the estimator's state as key-values."""
        values = {
            'converged': str(status.converged).lower(),
            'scale': f'{status.scale:.9g}',
            'spread': f'{status.spread:.9g}',
            'samples': str(status.samples),
            'frames': str(status.frames),
            'people': str(status.people),
            'map_hits': str(status.map_hits),
            'ground_fallbacks': str(status.ground_fallbacks),
            'fallback_rate': f'{status.fallback_rate:.4f}',
            'resets': str(status.resets),
            'map_points': str(status.map_points),
            'rejected_total': str(sum(status.rejected.values())),
        }
        for reason, count in sorted(status.rejected.items()):
            values[f'rejected.{reason}'] = str(count)
        level = DIAG_OK if status.converged else DIAG_WARN
        message = (f'converged: scale {status.scale:.6g} +- {status.spread:.2g}' if status.converged
                   else f'not converged: {status.samples} samples')
        kv = [new_message(self.types, 'diagnostic_msgs/msg/KeyValue', key=k, value=v)
              for k, v in values.items()]
        entry = new_message(self.types, 'diagnostic_msgs/msg/DiagnosticStatus',
                            level=_byte(self.types, level), name=DIAGNOSTIC_NAME, message=message,
                            hardware_id=self.params.metric_frame, values=kv)
        return new_message(self.types, DIAGNOSTICS[1],
                           header=make_header(status.stamp_ns, '', self.types), status=[entry])

    # ------------------------------------------------------------------ markers
    def markers(self, output: HumanJointsOut) -> Any:
        """Skeletons (one LINE_LIST per person), the camera path, and the ground plane."""
        header = make_header(output.stamp_ns, self.params.metric_frame, self.types)
        items = []
        for person, joints in enumerate(output.joints_metric):
            if not np.all(np.isfinite(joints)):
                continue
            points = [joints[i] for bone in BONES for i in bone]
            items.append(self._marker(header, 'skeleton', person, LINE_LIST, points,
                                      (0.1, 0.9, 0.2), width=0.03))
        if len(self._path) >= 2:
            items.append(self._marker(header, 'camera_path', 0, LINE_STRIP, list(self._path),
                                      (0.2, 0.4, 1.0), width=0.02))
        status = self._status
        if status is not None and status.ground_point_metric is not None:
            if self._plane_cache is None or self._plane_cache[0] is not status:
                self._plane_cache = (status, self._plane_marker(header, status))
            plane = self._plane_cache[1]
            plane.header = header
            items.append(plane)
        return new_message(self.types, MARKERS[1], markers=items)

    def _marker(self, header: Any, ns: str, marker_id: int, kind: int, points: list,
                rgb: tuple[float, float, float], width: float) -> Any:
        t = self.types
        Point = t.get('geometry_msgs/msg/Point')
        return new_message(
            t, 'visualization_msgs/msg/Marker', header=header, ns=ns, id=int(marker_id),
            type=kind, action=0, pose=_pose(t, np.zeros(3), (0.0, 0.0, 0.0, 1.0)),
            scale=new_message(t, 'geometry_msgs/msg/Vector3', x=width, y=0.0, z=0.0),
            color=_color(t, rgb, 1.0),
            points=[Point(x=x, y=y, z=z) for x, y, z in np.asarray(points, dtype=float).tolist()])

    def _plane_marker(self, header: Any, status: Status) -> Any:
        from scipy.spatial.transform import Rotation

        t = self.types
        normal = np.asarray(status.ground_normal_metric, dtype=float)
        # a thin box whose z axis is the plane normal
        quat = Rotation.align_vectors([normal], [[0.0, 0.0, 1.0]])[0].as_quat()
        return new_message(
            t, 'visualization_msgs/msg/Marker', header=header, ns='ground_plane', id=0, type=CUBE,
            action=0, pose=_pose(t, status.ground_point_metric, quat),
            scale=new_message(t, 'geometry_msgs/msg/Vector3', x=PLANE_SIZE_M, y=PLANE_SIZE_M, z=0.01),
            color=_color(t, (0.6, 0.6, 0.6), 0.4))


# ---------------------------------------------------------------------- message construction
def new_message(types: Any, msgtype: str, /, **fields: Any) -> Any:
    """A message of type ``msgtype`` from ``types`` with ``fields``; the rest get ROS defaults.

    rclpy classes have defaults; rosbags dataclasses need every field, so the missing ones are
    filled from the Jazzy type definitions (zeros, empty strings and sequences, nested defaults).
    """
    cls = types.get(msgtype)
    names = _dataclass_fields(cls)
    if names and len(fields) < len(names):
        defs = dict(_fielddefs(msgtype))
        for name in names:
            if name not in fields and name in defs:
                fields[name] = _default(types, defs[name])
    return cls(**fields)


@lru_cache(maxsize=None)
def _dataclass_fields(cls: type) -> tuple[str, ...]:
    """Field names of a rosbags dataclass (empty for rclpy classes, which have defaults)."""
    return tuple(f.name for f in dataclasses.fields(cls)) if dataclasses.is_dataclass(cls) else ()


@lru_cache(maxsize=None)
def _fielddefs(name: str) -> tuple:
    """The Jazzy field definitions of a message type (the typestore is built once, not per call)."""
    return tuple(_jazzy_typestore().fielddefs[name][1])


@lru_cache(maxsize=1)
def _jazzy_typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


_NUMPY = {'bool': np.bool_, 'byte': np.uint8, 'char': np.uint8, 'int8': np.int8, 'uint8': np.uint8,
          'int16': np.int16, 'uint16': np.uint16, 'int32': np.int32, 'uint32': np.uint32,
          'int64': np.int64, 'uint64': np.uint64, 'float32': np.float32, 'float64': np.float64}


def _default(types: Any, fielddef: tuple) -> Any:
    from rosbags.interfaces import Nodetype

    kind, spec = fielddef
    if kind == Nodetype.BASE:
        base = spec[0]
        if base == 'string':
            return ''
        if base == 'bool':
            return False
        return 0.0 if base.startswith('float') else 0
    if kind == Nodetype.NAME:
        return new_message(types, spec)
    (inner_kind, inner), length = spec
    if inner_kind == Nodetype.BASE and inner[0] in _NUMPY:
        return np.zeros(length if kind == Nodetype.ARRAY else 0, dtype=_NUMPY[inner[0]])
    if kind == Nodetype.ARRAY:
        return [_default(types, (inner_kind, inner)) for _ in range(length)]
    return []


def _byte(types: Any, value: int) -> Any:
    """A ``byte`` field: rclpy wants bytes, rosbags an int."""
    cls = types.get('diagnostic_msgs/msg/DiagnosticStatus')
    return value if dataclasses.is_dataclass(cls) else bytes([value])


def _pose(types: Any, position: np.ndarray, quat_xyzw: Any) -> Any:
    return new_message(
        types, 'geometry_msgs/msg/Pose',
        position=new_message(types, 'geometry_msgs/msg/Point', x=float(position[0]),
                             y=float(position[1]), z=float(position[2])),
        orientation=new_message(types, 'geometry_msgs/msg/Quaternion', x=float(quat_xyzw[0]),
                                y=float(quat_xyzw[1]), z=float(quat_xyzw[2]), w=float(quat_xyzw[3])))


def _color(types: Any, rgb: tuple[float, float, float], alpha: float) -> Any:
    return new_message(types, 'std_msgs/msg/ColorRGBA', r=float(rgb[0]), g=float(rgb[1]),
                       b=float(rgb[2]), a=float(alpha))
