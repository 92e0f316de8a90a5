"""Where message classes come from: rclpy's generated classes or rosbags' dataclasses.

Builders take a :class:`MessageTypes` so that the same code makes messages for the node (rclpy)
and for recordings (rosbags). Readers are duck-typed and need no types at all.
"""
from __future__ import annotations

import dataclasses
import importlib
from functools import lru_cache
from typing import Any, Callable


class MessageTypes:
    """Message classes by ROS name (``'geometry_msgs/msg/PoseStamped'``)."""

    def __init__(self, lookup: Callable[[str], type], flavour: str) -> None:
        self._lookup = lookup
        self.flavour = flavour  # 'rclpy' | 'rosbags'
        self._cache: dict[str, type] = {}

    def get(self, name: str) -> type:
        cls = self._cache.get(name)
        if cls is None:
            cls = self._cache[name] = self._lookup(name)
        return cls

    @property
    def is_rosbags(self) -> bool:
        return self.flavour == 'rosbags'


def _rclpy_lookup(name: str) -> type:
    package, kind, message = name.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), message)


@lru_cache(maxsize=1)
def rclpy_types() -> MessageTypes:
    """rclpy's message classes (imported lazily: this module never imports ROS at import time)."""
    return MessageTypes(_rclpy_lookup, 'rclpy')


@lru_cache(maxsize=4)
def _default_typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def rosbags_types(typestore: Any = None) -> MessageTypes:
    """rosbags' dataclasses of ``typestore`` (default: ROS 2 Jazzy, never LATEST)."""
    if typestore is None:
        return _rosbags_jazzy()
    return MessageTypes(lambda name: typestore.types[name], 'rosbags')


@lru_cache(maxsize=1)
def _rosbags_jazzy() -> MessageTypes:
    store = _default_typestore()
    return MessageTypes(lambda name: store.types[name], 'rosbags')


def is_dataclass_message(cls: type) -> bool:
    return dataclasses.is_dataclass(cls)
