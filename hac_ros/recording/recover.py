"""A recording cut off while it was written (power lost, the recorder killed, a full disk): its
complete part kept.

An MCAP file is written front to back as records (an opcode byte, a little-endian uint64 length,
the body); its summary and footer come last, when the writer closes. A file cut off has neither,
and ends inside a record, often a chunk of messages. :func:`recover` copies every complete record
before the cut (the header, the schemas and channels, the whole chunks and messages) and closes
the copy as a writer would without a summary: a DataEnd record, a footer that points to no
summary, the closing magic. Readers (rosbags, the mcap tools) then index it by scanning it. What
is lost is the record the cut went through: at most one chunk (rosbag2's default is 768 KiB of
messages) and whatever came after.

A rosbag2 directory whose recorder died has its storage file but often no ``metadata.yaml``
(written on close): its one storage file (:func:`storage_file`) is read instead.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

from hac_ros.core.basics.errors import HacError
from hac_ros.core.basics.printable import first_line
from hac_ros.recording.atomic import staged_output

MAGIC = b'\x89MCAP0\r\n'
OP_HEADER, OP_FOOTER, OP_DATA_END = 0x01, 0x02, 0x0F
RECORD_HEAD = 9  # the opcode byte and the uint64 length
COPY_BLOCK = 1 << 20  # bytes copied at a time


@dataclass
class Recovered:
    """What :func:`recover` kept: ``kept_bytes`` of the ``total_bytes`` of ``source``, written to
    ``target``, with ``messages`` per topic."""

    source: Path
    target: Path
    kept_bytes: int
    total_bytes: int
    messages: dict[str, int] = field(default_factory=dict)

    def text(self) -> str:
        lost = self.total_bytes - self.kept_bytes
        topics = ', '.join(f'{topic} {count}' for topic, count in sorted(self.messages.items()))
        return (f'hac recover: {self.source} -> {self.target}\n'
                f'  kept {self.kept_bytes} of {self.total_bytes} bytes: the unfinished record at '
                f'the cut ({lost} bytes) dropped\n'
                f'  messages: {sum(self.messages.values())} ({topics or "none"})')


def storage_file(path: Path) -> Path | None:
    """The one storage file (.mcap or .db3) of a rosbag2 directory, or None (a file, a directory
    with none or several)."""
    if not path.is_dir():
        return None
    files = sorted(p for p in path.iterdir() if p.suffix in ('.mcap', '.db3') and p.is_file())
    return files[0] if len(files) == 1 else None


def complete_prefix(handle: BinaryIO, size: int) -> int | None:
    """The length of the MCAP file's complete part (its magic and every whole record before the
    first that the file cuts off), or None when the file is whole (it ends with a footer and the
    magic) or is no MCAP file at all (its first 8 bytes are not the magic)."""
    handle.seek(0)
    if handle.read(len(MAGIC)) != MAGIC:
        return None
    end = offset = len(MAGIC)
    while offset + RECORD_HEAD <= size:
        handle.seek(offset)
        head = handle.read(RECORD_HEAD)
        op, length = head[0], struct.unpack('<Q', head[1:])[0]
        if offset + RECORD_HEAD + length > size:
            break  # the record the cut went through
        if op == OP_FOOTER:  # a writer closed the file: whole if the magic follows
            after = offset + RECORD_HEAD + length
            handle.seek(after)
            return None if handle.read(len(MAGIC)) == MAGIC else after
        offset += RECORD_HEAD + length
        if op != OP_DATA_END:
            end = offset
    return end


def is_cut_off(path: Path) -> bool:
    """Whether ``path`` is an MCAP file that ends short (no footer, or a record cut through)."""
    if not path.is_file():
        return False
    with path.open('rb') as handle:
        return complete_prefix(handle, path.stat().st_size) is not None


def recover(source: str | Path, target: str | Path) -> Recovered:
    """Copy the complete part of the cut-off MCAP recording ``source`` (a file, or a rosbag2
    directory holding one .mcap file) to the MCAP file ``target`` (which must not exist),
    closed without a summary (module docstring). HacError when ``source`` is not a cut-off MCAP
    file, or holds no complete message."""
    source, target = Path(source), Path(target)
    mcap = storage_file(source) or source
    if not mcap.is_file() or mcap.suffix != '.mcap':
        raise HacError(f'{source} is not an MCAP recording (a .mcap file, or a rosbag2 directory '
                       'with one): nothing to recover')
    size = mcap.stat().st_size
    with mcap.open('rb') as handle:
        kept = complete_prefix(handle, size)
        if kept is None:
            raise HacError(f'{mcap} is whole (it ends with its footer) or is no MCAP file: '
                           'nothing to recover')
        if target.exists():
            raise HacError(f'output {target} exists: not overwritten')
        with staged_output(target) as staged:
            with staged.open('wb') as out:
                handle.seek(0)
                left = kept
                while left:
                    block = handle.read(min(COPY_BLOCK, left))
                    out.write(block)
                    left -= len(block)
                out.write(bytes([OP_DATA_END]) + struct.pack('<QI', 4, 0))
                out.write(bytes([OP_FOOTER]) + struct.pack('<QQQI', 20, 0, 0, 0) + MAGIC)
            messages = _messages(staged, mcap)
            if not messages:
                raise HacError(f'{mcap}: no complete message before the cut: nothing to recover')
    return Recovered(source, target, kept, size, messages)


def _messages(path: Path, source: Path) -> dict[str, int]:
    """Messages per topic of the recovered file ``path`` (read as any reader would: by a scan),
    HacError naming ``source`` when it cannot be read."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
            return {name: info.msgcount for name, info in reader.topics.items() if info.msgcount}
    except Exception as exc:  # rosbags raises several types for unreadable files
        raise HacError(f'{source}: its complete part cannot be read either: '
                       f'{first_line(exc)}') from exc
