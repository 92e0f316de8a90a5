"""Reading recordings: rosbag2 (sqlite3 or mcap), a bare file, or a ROS 1 bag."""
from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from functools import cached_property
from pathlib import Path
from typing import Any

import yaml
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from hac_ros.core.basics.errors import ArgumentError, HacError
from hac_ros.core.basics.printable import first_line, printable
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
        self.path = Path(path)
        if not self.path.exists():
            raise HacError(f'input recording {self.path} does not exist')
        try:
            self.reader = AnyReader([self.path],
                                    default_typestore=get_typestore(Stores.ROS2_JAZZY))
            self.reader.open()
        except Exception as exc:  # rosbags raises several types for unreadable files
            reason = first_line(exc).rstrip('.')
            raise HacError(f'cannot read {self.path} as a recording (rosbag2 sqlite3/mcap or ROS 1 '
                           f'bag): {reason}{_cut_off_hint(self.path)}') from exc
        self.is_ros2 = self.reader.is2
        self.jazzy = get_typestore(Stores.ROS2_JAZZY)
        self.topics: dict[str, str] = {name: info.msgtype or ''
                                       for name, info in self.reader.topics.items()}
        self.counts: dict[str, int] = {name: info.msgcount
                                       for name, info in self.reader.topics.items()}

    @cached_property
    def custom_data(self) -> dict[str, str]:
        """rosbag2 metadata ``custom_data`` (empty for ROS 1 bags and recordings without it);
        read once (a recording is never written while it is read)."""
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

    def __enter__(self) -> Recording:
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
        return ', '.join(f'{printable(t)} ({printable(self.topics[t])}, {self.counts[t]})'
                         for t in sorted(self.topics))

    def publishers(self, topic: str) -> int:
        """How many publishers of ``topic`` the recorder saw: the offered QoS profiles rosbag2
        records, one per publisher (0 when the recording says nothing, as rosbags' writer)."""
        return sum(len(getattr(getattr(c, 'ext', None), 'offered_qos_profiles', None) or [])
                   for c in self.reader.connections if c.topic == topic)

    def has(self, topic: str, msgtype: str | None = None) -> bool:
        return topic in self.topics and self.counts.get(topic, 0) > 0 and (
            msgtype is None or self.topics[topic] == msgtype)

    def check_topic(self, topic: str, msgtypes: Iterable[str], what: str, hint: str = '',
                    arguments: tuple[str, ...] = ()) -> None:
        """Raise a clear error if ``topic`` is missing, empty or of another type. ``hint`` is
        added to a missing or mistyped topic's error: an :class:`ArgumentError` template naming
        ``arguments`` (``' (use {joints_topic})'``)."""
        msgtypes = list(msgtypes)
        name, path = printable(topic), printable(self.path)
        if topic not in self.topics:
            raise ArgumentError(f'{what} topic {name} is not in {path}{hint}; the '
                                f'recording contains: {self.describe()}', *arguments)
        if self.topics[topic] not in msgtypes:
            raise ArgumentError(f'{what} topic {name} has type {printable(self.topics[topic])}, '
                                f'expected {" or ".join(msgtypes)}{hint}', *arguments)
        if self.counts.get(topic, 0) == 0:
            raise HacError(f'{what} topic {name} in {path} has no messages (empty recording?)')

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
            raise HacError(f'{self.path} is corrupt: {first_line(exc)}') from exc

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
        except Exception:
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
        return HacError(f'{printable(self.path)} is corrupt: a {printable(topic)} message (log '
                        f'time {log_ns} ns) does not decode as {printable(self.topics[topic])}: '
                        f'{first_line(exc)}')


def _cut_off_hint(path: Path) -> str:
    """What to do with a recording whose recorder died (hac_ros.recording.recover), or ''."""
    from hac_ros.recording.recover import is_cut_off, storage_file

    single = storage_file(path)
    if is_cut_off(single or path):
        return (f'; {printable(single or path)} ends short (cut off while it was recorded?): '
                'hac recover keeps every complete message before the cut')
    if single is not None and not (path / 'metadata.yaml').exists():
        return (f'; no metadata.yaml (a recorder that did not close?): read its storage file '
                f'{printable(single)} itself')
    return ''

