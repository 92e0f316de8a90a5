"""Writing recordings: a new rosbag2 recording (staged by :mod:`hac_ros.recording.atomic`, so that
it appears whole or not at all)."""
from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

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

from hac_ros.core.basics.errors import HacError
from hac_ros.recording.reader import STORAGES


def _latched_qos() -> Any:
    never = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
               never, never, QosLiveliness.AUTOMATIC, never, False)


# ============================================================================ writing
class OutputWriter:
    """Writes serialized messages into a new rosbag2 recording."""

    def __init__(self, path: Path, storage: str, custom_data: dict[str, str] | None = None) -> None:
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

    def write(self, topic: str, msgtype: str, log_ns: int, data: bytes | memoryview) -> None:
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
