"""Recording I/O: rosbag2 in and out, atomic output staging, ground truth and outputs as arrays.

Everything that reads or writes a recording goes through here (``hac replay``, ``hac eval``,
``hac plot``, the demo, the tests): :class:`Recording` reads (rosbag2 sqlite3 or mcap, a bare
``.mcap``/``.db3`` file, or a ROS 1 ``.bag``; never written), :class:`OutputWriter` writes a new
rosbag2 recording, :class:`staged_output` makes it appear atomically, and the ``read_*``
functions turn topics into numpy tracks (header stamps as int nanoseconds; every array's frame and
unit in its docstring). Errors a user can fix raise :class:`~hac_ros.core.errors.HacError`.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections import Counter
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Iterable, Iterator

import numpy as np

from hac_ros.core.errors import HacError
from hac_ros.core.layouts import BUILT_IN, SMPL24, JointLayout

GT_CAMERA = ('/gt/camera_pose', 'geometry_msgs/msg/PoseStamped')
GT_JOINTS = ('/gt/human_joints', 'geometry_msgs/msg/PoseArray')
GT_SCALE = ('/gt/scale', 'std_msgs/msg/Float64')
STORAGES = ('mcap', 'sqlite3')
JOINTS_PER_PERSON = 24  # SMPL-24: a recording that does not say otherwise
# rosbag2 metadata custom_data keys: what a joints block is in the recording's PoseArrays
LAYOUT_KEY, JOINTS_KEY, ROLES_KEY = ('hac_ros.joint_layout', 'hac_ros.joints_per_person',
                                     'hac_ros.joint_roles')


def layout_data(layout: JointLayout) -> dict[str, str]:
    """The custom_data entries saying a recording's joint layout (written by the replay, the
    simulator and ``hac import``): its name, K and the root and body axis joints (JSON)."""
    roles = {'root': layout.root, 'axis_lower': layout.axis_lower,
             'axis_upper': layout.axis_upper}
    return {LAYOUT_KEY: layout.name, JOINTS_KEY: str(layout.joints_per_person),
            ROLES_KEY: json.dumps(roles)}


# ============================================================================ reading
class Recording:
    """A recording opened for reading: a rosbag2 directory, a bare .mcap/.db3 file, or a ROS 1 .bag.

    Read-only: nothing here writes to the path. Use as a context manager.
    """

    def __init__(self, path: str | Path) -> None:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        self.path = Path(path)
        if not self.path.exists():
            raise HacError(f'input recording {self.path} does not exist')
        try:
            self.reader = AnyReader([self.path],
                                    default_typestore=get_typestore(Stores.ROS2_JAZZY))
            self.reader.open()
        except Exception as exc:  # rosbags raises several types for unreadable files
            raise HacError(f'cannot read {self.path} as a recording (rosbag2 sqlite3/mcap or ROS 1 '
                           f'bag): {_reason(exc)}') from exc
        self.is_ros2 = self.reader.is2
        self.jazzy = get_typestore(Stores.ROS2_JAZZY)
        self.topics: dict[str, str | None] = {name: info.msgtype
                                              for name, info in self.reader.topics.items()}
        self.counts: dict[str, int] = {name: info.msgcount
                                       for name, info in self.reader.topics.items()}

    @cached_property
    def custom_data(self) -> dict[str, str]:
        """rosbag2 metadata ``custom_data`` (empty for ROS 1 bags and recordings without it);
        read once (a recording is never written while it is read)."""
        import yaml

        meta = self.path / 'metadata.yaml' if self.path.is_dir() else None
        if meta is None or not meta.is_file():
            return {}
        try:
            info = yaml.safe_load(meta.read_text(encoding='utf-8'))['rosbag2_bagfile_information']
        except (OSError, yaml.YAMLError, KeyError, TypeError):
            return {}
        data = info.get('custom_data') or {}
        return {str(k): str(v) for k, v in data.items()} if isinstance(data, dict) else {}

    @property
    def stated_joints_per_person(self) -> int | None:
        """K as the recording's custom_data states it, or None when it does not."""
        value = self.custom_data.get(JOINTS_KEY, '')
        return int(value) if value.isdigit() and int(value) > 0 else None

    @property
    def joints_per_person(self) -> int:
        """K of the recording's PoseArray joints blocks (its custom_data; SMPL-24's 24 without)."""
        return self.stated_joints_per_person or JOINTS_PER_PERSON

    @property
    def layout(self) -> JointLayout:
        """The recording's joint layout (custom_data): a built-in one by name, else K with the
        stored root and body axis; SMPL-24 when the recording does not say."""
        data = self.custom_data
        name = data.get(LAYOUT_KEY, SMPL24.name)
        if name in BUILT_IN:
            return BUILT_IN[name]
        k = self.joints_per_person
        try:
            roles = {key: tuple(int(i) for i in value if 0 <= int(i) < k)
                     for key, value in json.loads(data.get(ROLES_KEY, '{}')).items()}
        except (ValueError, TypeError, AttributeError):
            roles = {}
        every = tuple(range(k))
        return JointLayout(name, k, roles.get('root') or every, roles.get('axis_lower') or every,
                           roles.get('axis_upper') or every, (), (), ())

    def close(self) -> None:
        if self.reader.stack is not None:
            self.reader.close()

    def __enter__(self) -> 'Recording':
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    @property
    def start_ns(self) -> int:
        """The first log time, int nanoseconds."""
        return int(self.reader.start_time)

    def describe(self) -> str:
        """What the recording holds: ``topic (type, N messages)`` for each topic."""
        if not self.topics:
            return 'no topics'
        return ', '.join(f'{t} ({self.topics[t]}, {self.counts[t]})' for t in sorted(self.topics))

    def has(self, topic: str, msgtype: str | None = None) -> bool:
        return topic in self.topics and self.counts.get(topic, 0) > 0 and (
            msgtype is None or self.topics[topic] == msgtype)

    def check_topic(self, topic: str, msgtypes: Iterable[str], what: str, hint: str = '') -> None:
        """Raise a clear error if ``topic`` is missing, empty or of another type."""
        msgtypes = list(msgtypes)
        if topic not in self.topics:
            raise HacError(f'{what} topic {topic} is not in {self.path}{hint}; the recording '
                           f'contains: {self.describe()}')
        if self.topics[topic] not in msgtypes:
            raise HacError(f'{what} topic {topic} has type {self.topics[topic]}, expected '
                           f'{" or ".join(msgtypes)}{hint}')
        if self.counts.get(topic, 0) == 0:
            raise HacError(f'{what} topic {topic} in {self.path} has no messages (empty recording?)')

    def messages(self, topics: Iterable[str]) -> Iterator[tuple[str, int, Any]]:
        """(topic, log time ns, raw bytes) of ``topics`` in log-time order."""
        wanted = set(topics)
        connections = [c for c in self.reader.connections if c.topic in wanted]
        if not connections:
            return
        try:
            for connection, log_ns, raw in self.reader.messages(connections=connections):
                yield connection.topic, log_ns, raw
        except Exception as exc:  # a truncated or corrupt storage file
            raise HacError(f'{self.path} is corrupt: {_reason(exc)}') from exc

    def to_cdr(self, raw: Any, topic: str, log_ns: int = -1) -> Any:
        """The message bytes as ROS 2 CDR (a ROS 1 message becomes its ROS 2 Jazzy type).

        ROS 2 bytes are passed on as they are (a malformed message is then the decoder's to
        count); a ROS 1 message that does not convert raises HacError.
        """
        if self.is_ros2:
            return raw
        try:
            return self.jazzy.ros1_to_cdr(raw, self.topics[topic])
        except Exception as exc:
            raise self._corrupt(topic, log_ns, exc) from exc

    def deserialize(self, raw: Any, topic: str, log_ns: int = -1) -> Any:
        """A message of ``topic``; a ROS 1 message is converted to its ROS 2 Jazzy type first
        (``std_msgs/Header`` loses ``seq``, ``CameraInfo.K`` becomes ``k``, ...). HacError when it
        does not convert or deserialize."""
        data = self.to_cdr(raw, topic, log_ns)
        try:
            return self.typestore.deserialize_cdr(data, self.topics[topic])
        except Exception as exc:
            raise self._corrupt(topic, log_ns, exc) from exc

    def deserialize_or_none(self, data: Any, topic: str) -> Any:
        """The message of ROS 2 CDR bytes ``data`` of ``topic`` (as :meth:`to_cdr` gives them), or
        None when they do not deserialize (a malformed message: the caller counts it)."""
        try:
            return self.typestore.deserialize_cdr(data, self.topics[topic])
        except Exception:  # noqa: BLE001 - rosbags raises several types for malformed bytes
            return None

    @property
    def typestore(self) -> Any:
        """The types of :meth:`to_cdr`'s bytes: the recording's own (ROS 2) or Jazzy (ROS 1)."""
        return self.reader.typestore if self.is_ros2 else self.jazzy

    def read(self, topic: str) -> list[tuple[int, Any]]:
        """Every message of ``topic``, deserialized: [(log time ns, message)]."""
        return [(log_ns, self.deserialize(raw, topic, log_ns))
                for _, log_ns, raw in self.messages([topic])]

    def _corrupt(self, topic: str, log_ns: int, exc: BaseException) -> HacError:
        return HacError(f'{self.path} is corrupt: a {topic} message (log time {log_ns} ns) does '
                        f'not decode as {self.topics[topic]}: {_reason(exc)}')


def _latched_qos() -> Any:
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)

    never = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
               never, never, QosLiveliness.AUTOMATIC, never, False)


def _reason(exc: BaseException) -> str:
    """The first line of an exception's text (rosbags' messages can run to many lines)."""
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]


# ============================================================================ writing
class OutputWriter:
    """Writes serialized messages into a new rosbag2 recording."""

    def __init__(self, path: Path, storage: str, custom_data: dict[str, str] | None = None) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        if storage not in STORAGES:
            raise HacError(f'storage must be one of {", ".join(STORAGES)}, not {storage!r}')
        self.typestore = get_typestore(Stores.ROS2_JAZZY)
        plugin = StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3
        self.writer = Writer(path, version=9, storage_plugin=plugin)
        self.writer.open()
        for key, value in (custom_data or {}).items():  # rosbag2 metadata custom_data
            self.writer.set_custom_data(key, value)
        self._connections: dict[str, Any] = {}
        self.counts: Counter[str] = Counter()

    def connection(self, topic: str, msgtype: str, typestore: Any = None,
                   latched: bool = False) -> Any:
        """The connection of ``topic`` (added on first use); ``latched``: recorded as offered
        reliable + transient local (depth 1), so that ``ros2 bag play`` latches it as the node
        does."""
        conn = self._connections.get(topic)
        if conn is None:
            qos = [_latched_qos()] if latched else []
            conn = self.writer.add_connection(topic, msgtype, typestore=typestore or self.typestore,
                                              offered_qos_profiles=qos)
            self._connections[topic] = conn
        return conn

    def write(self, topic: str, msgtype: str, log_ns: int, data: bytes) -> None:
        """One message's CDR bytes on ``topic``, logged at ``log_ns``."""
        self.write_raw(self.connection(topic, msgtype), log_ns, data)

    def write_raw(self, conn: Any, log_ns: int, data: Any) -> None:
        self.writer.write(conn, int(log_ns), data)
        self.counts[conn.topic] += 1

    def close(self) -> None:
        self.writer.close()


def check_output_path(input_path: Path, output_path: Path) -> None:
    """OUT must not exist, and must not be inside IN (IN is never touched)."""
    if output_path.exists() or output_path.is_symlink():
        raise HacError(f'output {output_path} already exists (hac never overwrites a recording: '
                       'remove it or choose another name)')
    if output_path.parent.exists() and not output_path.parent.is_dir():
        raise HacError(f'{output_path.parent} is not a directory')
    out, src = output_path.resolve(), input_path.resolve()
    if out == src or src in out.parents:
        raise HacError(f'output {output_path} is inside the input {input_path}')


class staged_output:
    """A temporary directory beside OUT; the recording is written in it, renamed to OUT at the end.

    ``with staged_output(out) as path:`` gives the path to write. Missing parent directories of OUT
    are created. On an error or KeyboardInterrupt the temporary directory (and the parents it
    created) is removed and OUT never appears; OUT appears whole or not at all.
    """

    def __init__(self, output_path: Path) -> None:
        self.output_path = Path(output_path)
        self.tmp: Path | None = None
        self.created: list[Path] = []

    def __enter__(self) -> Path:
        parent = self.output_path.parent
        while not parent.exists():
            self.created.append(parent)
            parent = parent.parent
        self.output_path.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = Path(tempfile.mkdtemp(prefix=f'.{self.output_path.name}.', suffix='.partial',
                                         dir=self.output_path.parent))
        return self.tmp / self.output_path.name

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        assert self.tmp is not None
        done = False
        try:
            if exc_type is None:
                if self.output_path.exists():
                    raise HacError(f'output {self.output_path} appeared while writing it: not '
                                   'overwritten')
                os.rename(self.tmp / self.output_path.name, self.output_path)
                done = True
        finally:
            shutil.rmtree(self.tmp, ignore_errors=True)
            if not done:
                for directory in self.created:  # innermost first
                    try:
                        directory.rmdir()
                    except OSError:
                        break


# ============================================================================ tracks
def _no_stamps() -> np.ndarray:
    return np.zeros(0, dtype=np.int64)


@dataclass
class _Track:
    """Values at header stamps: stamps_ns (N,) int nanoseconds (empty by default)."""

    stamps_ns: np.ndarray = field(default_factory=_no_stamps)

    def __len__(self) -> int:
        return len(self.stamps_ns)


@dataclass
class CameraTrack(_Track):
    """positions (T, 3) camera centres, metres (SLAM units for a SLAM track), in the track's
    world/metric frame; rotations (T, 3, 3) camera to that frame."""

    positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    rotations: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))


@dataclass
class JointsTrack(_Track):
    """joints[f]: (P_f, 24, 3) metres, the track's frame (P_f people in frame f)."""

    joints: list[np.ndarray] = field(default_factory=list)


@dataclass
class ScaleTrack(_Track):
    """values (S,) metres per SLAM unit."""

    values: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def at(self, stamps_ns: np.ndarray) -> np.ndarray:
        """As a step function (the latest value at or before each stamp; the first before it)."""
        if not len(self.stamps_ns):
            return np.full(len(stamps_ns), np.nan)
        idx = np.searchsorted(self.stamps_ns, np.asarray(stamps_ns, dtype=np.int64), side='right') - 1
        return self.values[np.clip(idx, 0, len(self.values) - 1)]


@dataclass
class Truth:
    """Ground truth of a recording (any part may be missing): SPEC, "Recordings"."""

    camera: CameraTrack | None
    joints: JointsTrack | None
    scale: ScaleTrack | None


def read_camera(recording: Recording, topic: str) -> CameraTrack:
    """PoseStamped or Odometry messages of ``topic`` as a camera track (header stamps)."""
    from msg_adapters import pose_msg_to_rt, stamp_to_ns

    stamps, positions, rotations = [], [], []
    for _, msg in recording.read(topic):
        R, c = pose_msg_to_rt(msg)
        stamps.append(stamp_to_ns(msg.header.stamp))
        rotations.append(R)
        positions.append(c)
    if not stamps:
        return CameraTrack()
    return CameraTrack(np.asarray(stamps, dtype=np.int64), np.asarray(positions, dtype=float),
                       np.asarray(rotations, dtype=float))


def read_joints(recording: Recording, topic: str) -> JointsTrack:
    """PoseArray messages of ``topic``: (P, K, 3) joints per header stamp, K the recording's
    (:attr:`Recording.joints_per_person`); malformed ones skipped."""
    from msg_adapters import MessageError, pose_array_to_joints, stamp_to_ns

    stamps, joints = [], []
    k = recording.joints_per_person
    for _, msg in recording.read(topic):
        try:
            people = pose_array_to_joints(msg, k)
        except MessageError:
            continue
        stamps.append(stamp_to_ns(msg.header.stamp))
        joints.append(people)
    return JointsTrack(np.asarray(stamps, dtype=np.int64), joints)


def read_scale(recording: Recording, topic: str) -> ScaleTrack:
    """std_msgs/Float64 messages of ``topic`` at their log times."""
    items = recording.read(topic)
    return ScaleTrack(np.asarray([t for t, _ in items], dtype=np.int64),
                      np.asarray([float(m.data) for _, m in items], dtype=float))


def read_truth(path: str | Path) -> Truth:
    """/gt/camera_pose, /gt/human_joints and /gt/scale of a recording (whichever it has)."""
    with Recording(path) as rec:
        camera = read_camera(rec, GT_CAMERA[0]) if rec.has(*GT_CAMERA) else None
        joints = read_joints(rec, GT_JOINTS[0]) if rec.has(*GT_JOINTS) else None
        scale = read_scale(rec, GT_SCALE[0]) if rec.has(*GT_SCALE) else None
        if camera is None and joints is None and scale is None:
            raise HacError(f'{path} has no ground truth ({GT_CAMERA[0]}, {GT_JOINTS[0]}, '
                           f'{GT_SCALE[0]}); it contains: {rec.describe()}')
    return Truth(camera, joints, scale)


@dataclass
class Samples:
    """Per-person scale samples of each frame (/hac/samples): stamps_ns, person, scale (metres per
    SLAM unit, NaN when rejected), source (0 map, 1 ground, 2 rejected), accepted (bool)."""

    stamps_ns: np.ndarray
    person: np.ndarray
    scale: np.ndarray
    source: np.ndarray
    accepted: np.ndarray


@dataclass
class Replayed:
    """What a replay wrote: the metric camera (/hac/pose: metres, metric frame), world joints,
    scale, diagnostics [(log time ns, {key: value})], the per-frame samples and the continuous
    odometry (/hac/odometry: metres, odom frame)."""

    camera: CameraTrack
    joints: JointsTrack
    scale: ScaleTrack
    diagnostics: list[tuple[int, dict[str, str]]]
    samples: Samples | None
    odometry: CameraTrack = field(default_factory=CameraTrack)
    layout: JointLayout = SMPL24  # of the joints (the recording's custom_data)


def read_output(path: str | Path) -> Replayed:
    """Read a recording written by ``hac replay`` (SPEC's output topics and /hac/samples)."""
    from hac_ros.messages import (DIAGNOSTICS, HUMAN_JOINTS, ODOMETRY, POSE, SAMPLES, SCALE,
                                  in_root)

    pose, odom, diag = in_root(POSE[0]), in_root(ODOMETRY[0]), DIAGNOSTICS[0]
    joints_topic, scale_topic, samples_topic = (in_root(HUMAN_JOINTS[0]), in_root(SCALE[0]),
                                                in_root(SAMPLES[0]))
    with Recording(path) as rec:
        if not rec.has(diag) and not rec.has(pose):
            raise HacError(f'{path} is not a recording written by hac replay (no {pose} or '
                           f'{diag}); it contains: {rec.describe()}')
        camera = read_camera(rec, pose) if rec.has(pose) else CameraTrack()
        odometry = read_camera(rec, odom) if rec.has(odom) else CameraTrack()
        joints = read_joints(rec, joints_topic) if rec.has(joints_topic) else JointsTrack()
        scale = read_scale(rec, scale_topic) if rec.has(scale_topic) else ScaleTrack()
        diagnostics = [(log_ns, {kv.key: kv.value for kv in status.values})
                       for log_ns, msg in (rec.read(diag) if rec.has(diag) else [])
                       for status in msg.status]
        samples = _read_samples(rec, samples_topic) if rec.has(samples_topic) else None
        layout = rec.layout
    return Replayed(camera, joints, scale, diagnostics, samples, odometry, layout)


def _read_samples(recording: Recording, topic: str) -> Samples:
    from hac_ros.messages import SAMPLE_FIELDS

    stamps, rows = [], []
    for log_ns, msg in recording.read(topic):
        data = np.asarray(msg.data, dtype=float).reshape(-1, SAMPLE_FIELDS)
        stamps.extend([log_ns] * len(data))
        rows.append(data)
    table = np.vstack(rows) if rows else np.zeros((0, SAMPLE_FIELDS))
    return Samples(np.asarray(stamps, dtype=np.int64), table[:, 0].astype(int), table[:, 1],
                   table[:, 2].astype(int), table[:, 3] > 0.5)
