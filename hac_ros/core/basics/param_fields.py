"""The machinery of a parameter set: a dataclass whose fields carry their ROS description and range.

:class:`hac_ros.core.rules.params.HacParams` (``hac_node`` and the commands) and
:class:`hac_ros.people.params.PeopleParams` (``hac_people_node``) are both made of :func:`param`
fields on a :class:`ParamSet`: one way to declare, validate, copy, load and describe a parameter,
so that the nodes declare them, the docs print them and the files load them alike. Pure Python.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import field
from enum import Enum
from typing import Any, TypeVar

from hac_ros.core.basics.errors import ParameterError

Self = TypeVar('Self', bound='ParamSet')


class Choice(str, Enum):
    """One choice of a string parameter (its modes): equal to its string, printed as it
    (enum.StrEnum from Python 3.11; hac_ros runs on 3.10)."""

    def __str__(self) -> str:
        return str(self.value)


def param(default: Any, description: str, *, choices: tuple[str, ...] | None = None,
          low: float | None = None, high: float | None = None,
          length: int | tuple[int, ...] | None = None, kind: str = '') -> Any:
    """A dataclass field carrying its ROS parameter description and its allowed range
    (``length``: of a list of numbers, or the lengths it may have; ``kind='indices'``: a list of
    any length of joint indices, integers >= 0)."""
    meta = {'description': description, 'choices': choices, 'low': low, 'high': high,
            'length': length, 'kind': kind}
    if isinstance(default, list):
        return field(default_factory=lambda: list(default), metadata=meta)
    return field(default=default, metadata=meta)


class ParamSet:
    """The methods of a parameter dataclass: each field is checked against its :func:`param`
    range when the set is made; :meth:`check` adds the checks between fields."""

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`ParameterError` naming the first invalid field and why."""
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            check_field(f, getattr(self, f.name))
        self.check()

    def check(self) -> None:
        """The checks between fields (none by default)."""

    def replace(self: Self, **changes: Any) -> Self:
        """A validated copy with ``changes`` applied (all or nothing); unknown names are an
        error."""
        unknown = set(changes) - set(self.names())
        if unknown:
            raise ParameterError(f'unknown parameter(s): {", ".join(sorted(unknown))}')
        merged = {**self.as_dict(), **{k: self.coerce(k, v) for k, v in changes.items()}}
        return type(self)(**merged)

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)  # type: ignore[call-overload]

    @classmethod
    def from_dict(cls: type[Self], values: Mapping[str, Any]) -> Self:
        """Parameters from a flat mapping; unknown names are an error (typos must not pass)."""
        return cls().replace(**dict(values))

    @classmethod
    def names(cls) -> list[str]:
        """Every parameter name, in declaration order."""
        return [f.name for f in dataclasses.fields(cls)]  # type: ignore[arg-type]

    @classmethod
    def describe(cls, name: str) -> dict[str, Any]:
        """The description, default and range of one parameter (ParameterDescriptors, docs)."""
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            if f.name == name:
                return {'name': name, 'default': default_of(f), **f.metadata}
        raise ParameterError(f'unknown parameter: {name}')

    @classmethod
    def coerce(cls, name: str, value: Any) -> Any:
        """Accept what YAML and ROS hand us (ints for floats, tuples for lists)."""
        info = cls.describe(name)
        ref = info['default']
        if isinstance(ref, bool):
            return value
        if isinstance(ref, float) and isinstance(value, int) and not isinstance(value, bool):
            return float(value)
        if isinstance(ref, list) and (isinstance(value, (tuple, list)) or hasattr(value, 'tolist')):
            if info['kind'] == 'indices':
                return [int(v) if isinstance(v, (int, float)) and not isinstance(v, bool)
                        and float(v).is_integer() else v for v in list(value)]
            return [float(v) for v in list(value)]
        return value


def lengths_text(length: int | tuple[int, ...]) -> str:
    """'7', or '4 or 7': the lengths a list parameter may have."""
    lengths = length if isinstance(length, tuple) else (length,)
    return ' or '.join(str(n) for n in lengths)


def default_of(f: dataclasses.Field) -> Any:
    """A field's default value (a fresh one where a factory makes it)."""
    return f.default_factory() if callable(f.default_factory) else f.default


def check_field(f: dataclasses.Field, value: Any) -> None:
    """Raise :class:`ParameterError` when ``value`` is not of field ``f``'s type and range."""
    meta = f.metadata
    ref = default_of(f)
    name = f.name
    if isinstance(ref, bool):
        if not isinstance(value, bool):
            raise ParameterError(f'{name}: expected true or false, got {value!r}')
        return
    if isinstance(ref, str):
        if not isinstance(value, str):
            raise ParameterError(f'{name}: expected a string, got {value!r}')
        if meta.get('choices') and value not in meta['choices']:
            raise ParameterError(f'{name}: {value!r} is not one of {", ".join(meta["choices"])}')
        return
    if meta.get('kind') == 'indices':
        if not isinstance(value, list) or not all(
                isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in value):
            raise ParameterError(f'{name}: expected a list of joint indices (integers >= 0), '
                                 f'got {value!r}')
        return
    if isinstance(ref, list):
        lengths = meta['length'] if isinstance(meta['length'], tuple) else (meta['length'],)
        if not isinstance(value, list) or len(value) not in lengths or not all(
                isinstance(v, (int, float)) and math.isfinite(v) for v in value):
            raise ParameterError(f'{name}: expected {lengths_text(meta["length"])} finite numbers, '
                                 f'got {value!r}')
        return
    if isinstance(ref, int) and (not isinstance(value, int) or isinstance(value, bool)):
        raise ParameterError(f'{name}: expected an integer, got {value!r}')
    if isinstance(ref, float) and (not isinstance(value, (int, float)) or isinstance(value, bool)
                                   or not math.isfinite(value)):
        raise ParameterError(f'{name}: expected a finite number, got {value!r}')
    low, high = meta.get('low'), meta.get('high')
    if (low is not None and value < low) or (high is not None and value > high):
        raise ParameterError(f'{name}: {value!r} is outside [{low}, {high}]')
