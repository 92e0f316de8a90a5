"""Where message classes come from: rclpy's generated classes or rosbags' dataclasses.

Builders take a :class:`MessageTypes` so that the same code makes messages for the node (rclpy)
and for recordings (rosbags). Readers are duck-typed and need no types at all. Nothing here imports
ROS at import time: :func:`rclpy_types` imports the generated packages when it is called.
"""
from __future__ import annotations

import importlib
from collections.abc import Callable
from functools import lru_cache
from typing import Any

from msg_adapters.errors import MessageError

RCLPY, ROSBAGS = 'rclpy', 'rosbags'


def _full_name(name: str) -> str:
    """'geometry_msgs/PoseStamped' or 'geometry_msgs/msg/PoseStamped' → the latter."""
    parts = str(name).split('/')
    if len(parts) == 2:
        parts.insert(1, 'msg')
    if len(parts) != 3 or not all(parts):
        raise MessageError(f"message type: expected 'package/msg/Name', got {name!r}")
    return '/'.join(parts)


class MessageTypes:
    """Message classes by ROS name (``'geometry_msgs/msg/PoseStamped'``), of one flavour.

    ``flavour`` is ``'rclpy'`` (generated classes: fields have defaults, uint8[] is
    ``array.array('B')``) or ``'rosbags'`` (dataclasses: every field is required, uint8[] and fixed
    float arrays are numpy arrays). Builders construct every message with all fields as keywords,
    which both flavours accept.
    """

    def __init__(self, lookup: Callable[[str], type], flavour: str) -> None:
        if flavour not in (RCLPY, ROSBAGS):
            raise MessageError(f"message types: flavour must be '{RCLPY}' or '{ROSBAGS}', "
                               f'got {flavour!r}')
        self._lookup = lookup
        self.flavour = flavour
        self._cache: dict[str, type] = {}

    def get(self, name: str) -> type:
        """The class of ``name``; MessageError if this flavour does not know it."""
        cls = self._cache.get(name)
        if cls is None:
            full = _full_name(name)
            try:
                cls = self._lookup(full)
            except (KeyError, AttributeError, ImportError) as exc:
                raise MessageError(f'message type {full!r} is unknown to the {self.flavour} '
                                   f'message types ({exc})') from exc
            self._cache[name] = cls
        return cls

    @property
    def is_rosbags(self) -> bool:
        """True for rosbags dataclasses (uint8[] fields must be numpy uint8 arrays)."""
        return self.flavour == ROSBAGS

    def __repr__(self) -> str:
        return f'MessageTypes({self.flavour})'


def _rclpy_lookup(name: str) -> type:
    package, kind, message = name.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), message)


@lru_cache(maxsize=1)
def rclpy_types() -> MessageTypes:
    """rclpy's generated message classes.

    Imports ``geometry_msgs.msg`` now (not when this module is imported), so a missing ROS
    installation shows here as an ImportError; other packages are imported on first use.
    """
    importlib.import_module('geometry_msgs.msg')
    return MessageTypes(_rclpy_lookup, RCLPY)


def rosbags_types(typestore: Any = None) -> MessageTypes:
    """rosbags' dataclasses of ``typestore`` (default: ROS 2 Jazzy, never LATEST; built once)."""
    if typestore is None:
        return _rosbags_jazzy()
    return MessageTypes(lambda name: typestore.types[name], ROSBAGS)


@lru_cache(maxsize=1)
def _rosbags_jazzy() -> MessageTypes:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    return MessageTypes(lambda name: store.types[name], ROSBAGS)
