"""Stamps ↔ integer nanoseconds, and headers."""
from __future__ import annotations

from typing import Any

from msg_adapters.errors import MessageError
from msg_adapters.types import MessageTypes

NS = 1_000_000_000


def stamp_to_ns(stamp: Any) -> int:
    """``builtin_interfaces/Time`` (sec, nanosec) → int nanoseconds."""
    try:
        sec, nanosec = int(stamp.sec), int(stamp.nanosec)
    except (AttributeError, TypeError, ValueError) as exc:
        raise MessageError(f'stamp: expected sec and nanosec fields, got {stamp!r}') from exc
    if not 0 <= nanosec < NS:
        raise MessageError(f'stamp: nanosec {nanosec} is outside [0, 1e9)')
    return sec * NS + nanosec


def ns_to_stamp(ns: int, types: MessageTypes) -> Any:
    """int nanoseconds → ``builtin_interfaces/Time`` of ``types``."""
    sec, nanosec = divmod(int(ns), NS)
    return types.get('builtin_interfaces/msg/Time')(sec=sec, nanosec=nanosec)


def make_header(ns: int, frame_id: str, types: MessageTypes) -> Any:
    return types.get('std_msgs/msg/Header')(stamp=ns_to_stamp(ns, types), frame_id=frame_id)
