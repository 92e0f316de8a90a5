"""The speed benchmarks' fixed input: a room scene, its ROS messages and its recording.

Written out here with numpy, scipy and rosbags only (nothing from ``hac_ros`` or ``msg_adapters``):
both sides of an A/B comparison (bench/ab.py) must get the same bytes, and a reference must not
move with the package it measures.

The scene: a person walking a 3 m circle in a 12 m room, a camera 1.5 m high following 4 m behind
the person and looking at them; SLAM poses and map at TRUE_SCALE metres per SLAM unit, the SLAM map
frame being the first camera's; HMR joints (SMPL-24) in the camera optical frame, metres, 1 cm
noise.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

TRUE_SCALE = 0.5  # metres per SLAM unit
RATE_HZ = 30.0  # camera rate: one SLAM pose and one joints message per frame
NS = 1_000_000_000
FIRST_STAMP_NS = NS
MAP_FRAME, CAMERA_FRAME = 'map', 'camera'
POSE_TOPIC, JOINTS_TOPIC, CLOUD_TOPIC = '/slam/pose', '/hmr/joints', '/slam/cloud'
POSE_TYPE = 'geometry_msgs/msg/PoseStamped'
JOINTS_TYPE = 'geometry_msgs/msg/PoseArray'
CLOUD_TYPE = 'sensor_msgs/msg/PointCloud2'
FLOAT32 = 7  # sensor_msgs/PointField FLOAT32

# SMPL-24 joints of a standing person, metres, z up, feet at z = 0
STANCE = np.array([
    [0, 0, .93], [.09, 0, .86], [-.09, 0, .86], [0, .01, 1.05], [.1, 0, .46], [-.1, 0, .46],
    [0, .01, 1.18], [.1, .02, .08], [-.1, .02, .08], [0, .01, 1.26], [.11, -.1, 0],
    [-.11, -.1, 0], [0, 0, 1.45], [.07, 0, 1.38], [-.07, 0, 1.38], [0, -.02, 1.62],
    [.18, 0, 1.4], [-.18, 0, 1.4], [.22, 0, 1.12], [-.22, 0, 1.12], [.24, -.03, .86],
    [-.24, -.03, .86], [.25, -.05, .78], [-.25, -.05, .78]])


@dataclass
class RoomScene:
    """F frames of the room scene."""

    stamps_ns: np.ndarray  # (F,) int64, ns
    R_wc: np.ndarray  # (F, 3, 3) camera-to-map rotations, SLAM map frame
    c: np.ndarray  # (F, 3) camera centres, SLAM units, map frame
    joints_cam: np.ndarray  # (F, 24, 3) metres, camera optical frame
    _world_to_slam: tuple[np.ndarray, np.ndarray]  # (R0, c0): the first camera's pose in metres

    def __len__(self) -> int:
        return len(self.stamps_ns)

    def map_points(self, count: int) -> np.ndarray:
        """(count, 3) float64 map points, SLAM units, map frame: the floor (70 %) and the four
        walls (30 %), 1 cm noise; the same points for the same count."""
        rng = np.random.default_rng(count)
        floor_count = int(0.7 * count)
        floor = np.c_[rng.uniform(-6, 6, (floor_count, 2)), np.zeros(floor_count)]
        wall_count = count - floor_count
        side = rng.integers(0, 4, wall_count)
        along, height = rng.uniform(-6, 6, wall_count), rng.uniform(0, 3, wall_count)
        at = np.where(side % 2 == 0, 6.0, -6.0)
        walls = np.where((side < 2)[:, None], np.c_[along, at, height], np.c_[at, along, height])
        points = np.vstack([floor, walls]) + rng.normal(0, 0.01, (count, 3))
        R0, c0 = self._world_to_slam
        return (points - c0) @ R0 / TRUE_SCALE


def room_scene(frames: int, rate_hz: float = RATE_HZ, seed: int = 0) -> RoomScene:
    """``frames`` frames at ``rate_hz``, stamps from FIRST_STAMP_NS."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / rate_hz
    angle = 0.3 * t  # rad: the person walks at 0.9 m/s
    person = np.stack([3 * np.cos(angle), 3 * np.sin(angle), np.zeros(frames)], 1)
    cam = person * [7 / 3, 7 / 3, 0] + [0, 0, 1.5]
    z = person + [0, 0, 0.3] - cam  # optical axis: at the person's hips
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    x = np.cross(z, [0, 0, 1.0])
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    R = np.stack([x, np.cross(z, x), z], 2)  # (F, 3, 3) camera-to-world, columns x, y, z
    body = STANCE[None] + person[:, None]
    body[np.arange(frames), 10 + np.arange(frames) % 2, 2] += 0.08  # one foot lifted at a time
    joints = np.einsum('fji,fkj->fki', R, body - cam[:, None]) + rng.normal(0, 0.01,
                                                                            (frames, 24, 3))
    R0, c0 = R[0], cam[0]
    return RoomScene(stamps_ns=(t * NS).astype(np.int64) + FIRST_STAMP_NS,
                     R_wc=np.einsum('ji,fjk->fik', R0, R), c=(cam - c0) @ R0 / TRUE_SCALE,
                     joints_cam=joints, _world_to_slam=(R0, c0))


# ============================================================================ CDR messages
def _typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_JAZZY)


TYPESTORE = _typestore()
_T = TYPESTORE.types


def _header(stamp_ns: int, frame_id: str) -> Any:
    sec, nanosec = divmod(int(stamp_ns), NS)
    return _T['std_msgs/msg/Header'](stamp=_T['builtin_interfaces/msg/Time'](sec=sec,
                                                                              nanosec=nanosec),
                                     frame_id=frame_id)


def pose_cdr(R_wc: np.ndarray, c: np.ndarray, stamp_ns: int, frame_id: str = MAP_FRAME) -> bytes:
    """PoseStamped CDR bytes: the camera's pose (R_wc (3, 3), c (3,) SLAM units) in ``frame_id``."""
    x, y, z, w = Rotation.from_matrix(R_wc).as_quat()
    pose = _T['geometry_msgs/msg/Pose'](
        position=_T['geometry_msgs/msg/Point'](x=float(c[0]), y=float(c[1]), z=float(c[2])),
        orientation=_T['geometry_msgs/msg/Quaternion'](x=x, y=y, z=z, w=w))
    msg = _T[POSE_TYPE](header=_header(stamp_ns, frame_id), pose=pose)
    return bytes(TYPESTORE.serialize_cdr(msg, POSE_TYPE))


def joints_cdr(joints: np.ndarray, stamp_ns: int, frame_id: str = CAMERA_FRAME) -> bytes:
    """PoseArray CDR bytes: one person's (24, 3) joints, metres, identity orientations."""
    Pose, Point, Quaternion = (_T[f'geometry_msgs/msg/{name}']
                               for name in ('Pose', 'Point', 'Quaternion'))
    poses = [Pose(position=Point(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                  orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)) for p in joints]
    msg = _T[JOINTS_TYPE](header=_header(stamp_ns, frame_id), poses=poses)
    return bytes(TYPESTORE.serialize_cdr(msg, JOINTS_TYPE))


def cloud_cdr(points: np.ndarray, stamp_ns: int, frame_id: str = MAP_FRAME) -> bytes:
    """PointCloud2 CDR bytes: (N, 3) points as little-endian float32 x, y, z, height 1."""
    fields = [_T['sensor_msgs/msg/PointField'](name=axis, offset=4 * k, datatype=FLOAT32, count=1)
              for k, axis in enumerate('xyz')]
    data = np.ascontiguousarray(points, dtype='<f4').reshape(-1).view(np.uint8)
    msg = _T[CLOUD_TYPE](header=_header(stamp_ns, frame_id), height=1, width=len(points),
                         fields=fields, is_bigendian=False, point_step=12,
                         row_step=12 * len(points), data=data, is_dense=True)
    return bytes(TYPESTORE.serialize_cdr(msg, CLOUD_TYPE))


def set_cdr_stamp(raw: bytearray, stamp_ns: int) -> None:
    """Patch header.stamp: the first 8 bytes after the 4-byte CDR encapsulation header of any
    message whose first field is a std_msgs/Header."""
    struct.pack_into('<iI', raw, 4, *divmod(int(stamp_ns), NS))


def cdr_stamp(raw: bytes) -> int:
    """header.stamp of CDR bytes (see :func:`set_cdr_stamp`), ns."""
    sec, nanosec = struct.unpack_from('<iI', raw, 4)
    return sec * NS + nanosec


# ============================================================================ the recording
def write_recording(path: Path, duration_s: float, map_points: int) -> dict[str, Any]:
    """The room scene as a rosbag2 mcap recording at ``path`` (must not exist): ``duration_s`` of
    poses and joints at RATE_HZ and a ``map_points`` map republished every stamp second. Returns
    its frame count, map count and size in bytes."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    scene = room_scene(int(round(duration_s * RATE_HZ)))
    cloud = bytearray(cloud_cdr(scene.map_points(map_points), 0))
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    try:
        conns = {topic: writer.add_connection(topic, msgtype, typestore=TYPESTORE)
                 for topic, msgtype in ((POSE_TOPIC, POSE_TYPE), (JOINTS_TOPIC, JOINTS_TYPE),
                                        (CLOUD_TOPIC, CLOUD_TYPE))}
        next_map_ns, maps = int(scene.stamps_ns[0]), 0
        for i, stamp in enumerate(scene.stamps_ns.tolist()):
            if stamp >= next_map_ns:
                set_cdr_stamp(cloud, stamp)
                writer.write(conns[CLOUD_TOPIC], stamp, bytes(cloud))
                next_map_ns += NS
                maps += 1
            writer.write(conns[POSE_TOPIC], stamp, pose_cdr(scene.R_wc[i], scene.c[i], stamp))
            writer.write(conns[JOINTS_TOPIC], stamp, joints_cdr(scene.joints_cam[i], stamp))
    finally:
        writer.close()
    return {'frames': len(scene), 'duration_s': len(scene) / RATE_HZ, 'maps': maps,
            'map_points': map_points, 'bytes': sum(f.stat().st_size for f in path.iterdir())}


def read_recording(path: Path) -> int:
    """The bare read: every message of the recording at ``path`` read with rosbags' AnyReader and
    deserialized with the ROS 2 Jazzy typestore. Returns the number of messages."""
    from rosbags.highlevel import AnyReader

    count = 0
    with AnyReader([Path(path)], default_typestore=TYPESTORE) as reader:
        for connection, _, raw in reader.messages():
            TYPESTORE.deserialize_cdr(raw, connection.msgtype)
            count += 1
    return count
