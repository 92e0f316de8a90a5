"""Faults injected into real recordings, for the fault suite (test_faults*.py).

A recording of the simulator is copied message by message with an edit applied: the recording
played twice (header stamps go back), one SLAM pose glitched or stamped far ahead, the SLAM frozen,
maps whose bytes decode to garbage, joints in the wrong unit. Each edit is a function
``(topic, log_ns, msg) -> [(topic, log_ns, msg), ...]`` on rosbags' message objects; the copy keeps
every other message as it is.
"""
from __future__ import annotations

import copy
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from hac_ros.core.basics.numeric import NS

Message = tuple[str, int, Any]  # (topic, log time ns, rosbags message)
Edit = Callable[[Iterator[Message]], Iterator[Message]]
POSE, JOINTS, CLOUD = '/slam/pose', '/hmr/joints', '/slam/cloud'


def simulate(path: Path, scenario: str = 'walk', seed: int = 1, duration: float | None = None,
             hmr_bias: float = 0.0) -> Path:
    """``hac simulate SCENARIO --seed SEED --hmr-bias 0`` (the issue's recipe) into ``path``."""
    from hac_ros.simulate import make_scenario, write_recording

    sc = make_scenario(scenario, seed=seed, duration=duration, hmr_bias=hmr_bias)
    return write_recording(sc, path)


def rewrite(source: Path, target: Path, edit: Edit,
            publishers: dict[str, int] | None = None) -> Path:
    """A copy of ``source`` at ``target`` with ``edit`` applied to its messages (in log order);
    ``publishers``: topic -> how many publishers the metadata says offered it (rosbag2 records
    one offered QoS profile per publisher it saw; none by default)."""
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    never = QosTime(0, 0)
    qos = Qos(QosHistory.KEEP_LAST, 10, QosReliability.RELIABLE, QosDurability.VOLATILE, never,
              never, QosLiveliness.AUTOMATIC, never, False)
    offered = publishers or {}
    store = get_typestore(Stores.ROS2_JAZZY)
    with AnyReader([source], default_typestore=store) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}

        def messages() -> Iterator[Message]:
            for conn, log_ns, raw in reader.messages():
                yield conn.topic, log_ns, reader.deserialize(raw, conn.msgtype)

        writer = Writer(target, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        conns = {topic: writer.add_connection(topic, msgtype, typestore=store,
                                              offered_qos_profiles=[qos] * offered.get(topic, 0))
                 for topic, msgtype in types.items()}
        for topic, log_ns, msg in edit(messages()):
            writer.write(conns[topic], log_ns, store.serialize_cdr(msg, types[topic]))
        writer.close()
    return target


def _stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * NS + int(msg.header.stamp.nanosec)


def _set_stamp(msg: Any, stamp_ns: int) -> Any:
    msg = copy.deepcopy(msg)
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), NS)
    return msg


# ---------------------------------------------------------------------------------------- edits
def played(times: int, gap_s: float = 1.0) -> Edit:
    """The recording played ``times`` times in a row (``ros2 bag play --loop``): the same header
    stamps again, later log times."""
    def edit(messages: Iterator[Message]) -> Iterator[Message]:
        items = list(messages)
        span = items[-1][1] - items[0][1] + int(gap_s * NS)
        for k in range(times):
            for topic, log_ns, msg in items:
                yield topic, log_ns + k * span, msg
    return edit


def pose_moved(index: int, offset: float) -> Edit:
    """SLAM pose ``index`` glitched: its centre moved by ``offset`` SLAM units along x."""
    return _nth(POSE, {index}, lambda msg: _moved(msg, offset))


def poses_moved(indices: set[int], offset: float) -> Edit:
    return _nth(POSE, indices, lambda msg: _moved(msg, offset))


def pose_stamped_ahead(index: int, seconds: float) -> Edit:
    """SLAM pose ``index`` stamped ``seconds`` ahead of its image (a clock glitch)."""
    return _nth(POSE, {index}, lambda msg: _set_stamp(msg, _stamp_ns(msg) + int(seconds * NS)))


def slam_frozen(start_s: float, duration_s: float) -> Edit:
    """SLAM tracking frozen: from ``start_s`` into the recording, for ``duration_s``, every pose
    repeats the last one before it bit for bit (with its own stamp)."""
    def edit(messages: Iterator[Message]) -> Iterator[Message]:
        first: int | None = None
        held: Any = None
        for topic, log_ns, msg in messages:
            first = log_ns if first is None else first
            if topic == POSE:
                into = (log_ns - first) / NS
                if start_s <= into < start_s + duration_s and held is not None:
                    frozen = copy.deepcopy(held)
                    frozen.header.stamp = copy.deepcopy(msg.header.stamp)
                    msg = frozen
                elif into < start_s:
                    held = msg
            yield topic, log_ns, msg
    return edit


def maps_big_endian(indices: set[int] | None = None) -> Edit:
    """Map clouds whose bytes decode to garbage: little-endian floats flagged ``is_bigendian``
    (every map, or those of ``indices``)."""
    def flip(msg: Any) -> Any:
        msg = copy.deepcopy(msg)
        msg.is_bigendian = True
        return msg
    return _nth(CLOUD, indices, flip)


def joints_scaled(factor: float) -> Edit:
    """HMR joints in another unit: every joint multiplied by ``factor`` (0.01: decimetres read
    as metres twice over, 0.1: centimetres converted twice)."""
    def scaled(msg: Any) -> Any:
        msg = copy.deepcopy(msg)
        for pose in msg.poses:
            pose.position.x *= factor
            pose.position.y *= factor
            pose.position.z *= factor
        return msg
    return _nth(JOINTS, None, scaled)


def chained(*edits: Edit) -> Edit:
    def edit(messages: Iterator[Message]) -> Iterator[Message]:
        for one in edits:
            messages = one(messages)
        return messages
    return edit


def _nth(topic: str, indices: set[int] | None, change: Callable[[Any], Any]) -> Edit:
    def edit(messages: Iterator[Message]) -> Iterator[Message]:
        count = 0
        for t, log_ns, msg in messages:
            if t == topic:
                if indices is None or count in indices:
                    msg = change(msg)
                count += 1
            yield t, log_ns, msg
    return edit


def _moved(msg: Any, offset: float) -> Any:
    msg = copy.deepcopy(msg)
    pose = msg.pose.pose if hasattr(msg.pose, 'pose') else msg.pose
    pose.position.x += offset
    return msg


def truth_scale(path: Path) -> float:
    """The recording's /gt/scale (the first; the simulator's walk has one)."""
    from hac_ros.recording.reader import Recording

    with Recording(path) as rec:
        return float(rec.read('/gt/scale')[0][1].data)


def finite_abs_max(values: list[np.ndarray]) -> float:
    """The largest |value| over arrays (inf when any is not finite)."""
    top = 0.0
    for v in values:
        v = np.asarray(v, dtype=float)
        if v.size and not np.isfinite(v).all():
            return float('inf')
        if v.size:
            top = max(top, float(np.abs(v).max()))
    return top


def maps_stamped_back(seconds: float) -> Edit:
    """Every map cloud stamped ``seconds`` before the log time it is written at (a SLAM that
    stamps its map with the keyframe it came from, or a map that takes seconds to build or to
    cross DDS)."""
    return _nth(CLOUD, None, lambda msg: _set_stamp(msg, _stamp_ns(msg) - int(seconds * NS)))


def camera_rolled(degrees: float) -> Edit:
    """The camera mounted rolled by ``degrees`` about its optical axis: each SLAM pose's
    orientation turned about its own z (R_wc' = R_wc Rz), and the joints, the same points in
    the world, expressed in the rolled optical frame (J' = Rzᵀ J). The intrinsics stay."""
    from scipy.spatial.transform import Rotation

    turn = Rotation.from_euler('z', degrees, degrees=True)
    back = turn.inv().as_matrix()

    def pose(msg: Any) -> Any:
        msg = copy.deepcopy(msg)
        p = msg.pose.pose if hasattr(msg.pose, 'pose') else msg.pose
        q = p.orientation
        x, y, z, w = (Rotation.from_quat([q.x, q.y, q.z, q.w]) * turn).as_quat()
        q.x, q.y, q.z, q.w = float(x), float(y), float(z), float(w)
        return msg

    def joints(msg: Any) -> Any:
        msg = copy.deepcopy(msg)
        for each in msg.poses:
            v = back @ np.array([each.position.x, each.position.y, each.position.z])
            each.position.x, each.position.y, each.position.z = (float(c) for c in v)
        return msg
    return chained(_nth(POSE, None, pose), _nth(JOINTS, None, joints))


# ------------------------------------------------------------------------ maps of one shape
def _cloud_points(msg: Any) -> np.ndarray:
    """A PointCloud2's x, y, z as (N, 3) float64 (the simulator's float32 layout)."""
    from msg_adapters import cloud_to_xyz

    return np.asarray(cloud_to_xyz(msg), dtype=np.float64)


def _cloud_with(msg: Any, points: np.ndarray) -> Any:
    """``msg`` (a rosbags PointCloud2) carrying ``points`` (N, 3) instead: x, y, z float32."""
    msg = copy.deepcopy(msg)
    data = np.ascontiguousarray(points, dtype='<f4')
    msg.fields = msg.fields[:3]
    for k, field in enumerate(msg.fields):
        field.offset, field.datatype, field.count = 4 * k, 7, 1
    msg.is_bigendian, msg.point_step = False, 12
    msg.height, msg.width = 1, len(data)
    msg.row_step = 12 * len(data)
    msg.data = np.frombuffer(data.tobytes(), dtype=np.uint8)
    msg.is_dense = True
    return msg


def world_in_map(path: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """The simulator's world in its SLAM map frame (the first segment): (R (3, 3) world to map,
    t (3,) the world origin in the map, SLAM units, s metres per SLAM unit): p_map = R p_world / s
    + t. From the first SLAM and ground-truth camera poses and /gt/scale."""
    from scipy.spatial.transform import Rotation

    from hac_ros.recording.reader import Recording

    with Recording(path) as rec:
        slam = rec.read(POSE)[0][1]
        truth = rec.read('/gt/camera_pose')[0][1]
        scale = float(rec.read('/gt/scale')[0][1].data)

    def pose(msg: Any) -> tuple[np.ndarray, np.ndarray]:
        p = msg.pose.pose if hasattr(msg.pose, 'pose') else msg.pose
        q = p.orientation
        return (Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(),
                np.array([p.position.x, p.position.y, p.position.z]))
    R_slam, c_slam = pose(slam)
    R_gt, c_gt = pose(truth)
    R = R_slam @ R_gt.T
    return R, c_slam - R @ c_gt / scale, scale


def maps_reshaped(path: Path, shape: str) -> Edit:
    """Every map cloud of the recording at ``path`` made degenerate, or floor-only: ``line`` (its
    points projected onto their principal line), ``point`` (all at their centroid), ``wall``
    (projected onto a vertical plane through their centroid: a wall-only map), ``camera_plane``
    (projected onto the level plane through the first camera: a plane the camera moves in) or
    ``floor`` (only the points within 5 cm of the floor: a floor-only map)."""
    R, t, scale = world_in_map(path)
    up = R @ np.array([0.0, 0.0, 1.0])
    camera = None
    if shape == 'camera_plane':
        from hac_ros.recording.reader import Recording

        with Recording(path) as rec:
            p = rec.read(POSE)[0][1].pose
            p = p.pose if hasattr(p, 'pose') else p
            camera = np.array([p.position.x, p.position.y, p.position.z])

    def reshape(msg: Any) -> Any:
        points = _cloud_points(msg)
        centre = points.mean(axis=0)
        if shape == 'point':
            out = np.repeat(centre[None], len(points), 0)
        elif shape == 'line':
            axis = np.linalg.svd(points - centre, full_matrices=False)[2][0]
            out = centre + np.outer((points - centre) @ axis, axis)
        elif shape in ('wall', 'camera_plane'):
            if shape == 'wall':  # a vertical plane: its normal level, along the cloud's spread
                level = np.linalg.svd((points - centre) - np.outer((points - centre) @ up, up),
                                      full_matrices=False)[2][1]
                normal, origin = level, centre
            else:
                normal, origin = up, camera
            out = points - np.outer((points - origin) @ normal, normal)
        elif shape == 'floor':
            height = ((points - t) @ R) * scale @ np.array([0.0, 0.0, 1.0])
            out = points[height < 0.05]
        else:
            raise ValueError(shape)
        return _cloud_with(msg, out)
    return _nth(CLOUD, None, reshape)


def person_lifted(path: Path, start_s: float, duration_s: float, height_m: float) -> Edit:
    """The people of the recording at ``path`` jump: from ``start_s`` into it, for
    ``duration_s``, every joint ``height_m`` metres higher in the world (the body as it stands,
    the feet in the air), in the camera frame of the SLAM pose of the same stamp."""
    from scipy.spatial.transform import Rotation

    R, _, _ = world_in_map(path)
    up_map = R @ np.array([0.0, 0.0, 1.0])

    def edit(messages: Iterator[Message]) -> Iterator[Message]:
        first: int | None = None
        R_wc = np.eye(3)
        for topic, log_ns, msg in messages:
            first = log_ns if first is None else first
            if topic == POSE:
                p = msg.pose.pose if hasattr(msg.pose, 'pose') else msg.pose
                q = p.orientation
                R_wc = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
            elif topic == JOINTS and start_s <= (log_ns - first) / NS < start_s + duration_s:
                lift = R_wc.T @ up_map * height_m
                msg = copy.deepcopy(msg)
                for each in msg.poses:
                    each.position.x += float(lift[0])
                    each.position.y += float(lift[1])
                    each.position.z += float(lift[2])
            yield topic, log_ns, msg
    return edit


def maps_densified(path: Path, extra_points: int, keep: int) -> Edit:
    """The first ``keep`` map clouds of the recording at ``path`` each with ``extra_points`` more
    points on its floor (a dense map: the same surfaces), the later ones left out."""
    R, t, scale = world_in_map(path)
    rng = np.random.default_rng(0)
    floor_world = np.c_[rng.uniform(-7.0, 7.0, (extra_points, 2)), np.zeros(extra_points)]
    floor_map = (floor_world @ R.T) / scale + t

    def edit(messages: Iterator[Message]) -> Iterator[Message]:
        seen = 0
        for topic, log_ns, msg in messages:
            if topic == CLOUD:
                seen += 1
                if seen > keep:
                    continue
                msg = _cloud_with(msg, np.vstack([_cloud_points(msg), floor_map]))
            yield topic, log_ns, msg
    return edit
