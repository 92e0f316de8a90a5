"""Stamps ↔ integer nanoseconds, and headers.

``builtin_interfaces/msg/Time`` is (sec: int32, nanosec: uint32 < 1e9); stamps in this package are
int nanoseconds since the epoch of the message's clock.
"""
from __future__ import annotations

import operator
from typing import Any

from msg_adapters.errors import MessageError
from msg_adapters.types import MessageTypes

NS_PER_S = 1_000_000_000
INT32_MAX = 2**31 - 1  # the largest Time.sec


def stamp_to_ns(stamp: Any) -> int:
    """``builtin_interfaces/Time`` (sec, nanosec) → int nanoseconds (>= 0)."""
    try:
        sec, nanosec = operator.index(stamp.sec), operator.index(stamp.nanosec)
    except (AttributeError, TypeError) as exc:
        raise MessageError(f'stamp: expected integer sec and nanosec fields, '
                           f'got {stamp!r}') from exc
    return time_to_ns(sec, nanosec)


def time_to_ns(sec: int, nanosec: int) -> int:
    """A Time's (sec, nanosec) → int nanoseconds; :class:`MessageError` unless it is a ROS time
    (nanosec in [0, 1e9), sec not negative: rclpy's Time refuses one before the epoch too)."""
    if not 0 <= nanosec < NS_PER_S:
        raise MessageError(f'stamp: nanosec must be in [0, 1e9), got {nanosec}')
    if sec < 0:
        raise MessageError(f'stamp: negative time (sec {sec}) is not a ROS time')
    return sec * NS_PER_S + nanosec


def ns_to_stamp(ns: int, types: MessageTypes) -> Any:
    """int nanoseconds → ``builtin_interfaces/Time`` of ``types`` (not negative, sec must fit in
    int32)."""
    try:
        ns = operator.index(ns)
    except TypeError as exc:
        raise MessageError(f'stamp: expected integer nanoseconds, got {ns!r}') from exc
    sec, nanosec = divmod(ns, NS_PER_S)
    if sec < 0:
        raise MessageError(f'stamp: negative time ({ns} ns) is not a ROS time')
    if sec > INT32_MAX:
        raise MessageError(f'stamp: {ns} ns is outside the int32 seconds of '
                           'builtin_interfaces/Time')
    return types.get('builtin_interfaces/msg/Time')(sec=sec, nanosec=nanosec)


def make_header(ns: int, frame_id: str, types: MessageTypes) -> Any:
    """``std_msgs/Header`` with stamp ``ns`` (int nanoseconds) and ``frame_id``."""
    if not isinstance(frame_id, str):
        raise MessageError(f'header: frame_id must be a str, got {type(frame_id).__name__}')
    return types.get('std_msgs/msg/Header')(stamp=ns_to_stamp(ns, types), frame_id=frame_id)
