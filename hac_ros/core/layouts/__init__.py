"""Joint layouts (the ``joint_layout`` parameter; docs/inputs.md, "Joint layouts"): which joint is
which in an HMR model's output.

One module per built-in layout (``smpl24.py``, ``coco17.py``, ...), each defining ``LAYOUT``, a
:class:`~hac_ros.core.layouts.base.JointLayout`: its roles for the core, its joint names, the
models that write it and how the simulator writes it. This package is the one list of layouts:
the parameter's choices, ``hac simulate --joint-layout``, the texts that name layouts and their
joint counts, and the docs' table are made from :data:`BUILT_IN` (the doc test holds the docs to
it). A new layout is a new module here plus its tests.
"""
from __future__ import annotations

import importlib
import pkgutil

from hac_ros.core.layouts.base import (
    CUSTOM,
    CUSTOM_ROLES,
    SHOD_ANKLE_REL,
    JointLayout,
    custom_layout,
    problems,
)
from hac_ros.core.layouts.smpl24 import LAYOUT as SMPL24

DEFAULT = SMPL24.name
_NOT_LAYOUTS = {'base'}


def _discover() -> dict[str, JointLayout]:
    """Every module of this package but ``base``: its ``LAYOUT``, the default first, then by
    name. A module whose layout is inconsistent (:func:`problems`) is an error at import."""
    found: dict[str, JointLayout] = {}
    for info in pkgutil.iter_modules(__path__):
        if info.name in _NOT_LAYOUTS:
            continue
        layout = importlib.import_module(f'{__name__}.{info.name}').LAYOUT
        if layout.name != info.name:
            raise ImportError(f'{__name__}.{info.name} defines layout {layout.name!r}: a layout '
                              'module is named after its layout')
        wrong = problems(layout)
        if wrong:
            raise ImportError('; '.join(wrong))
        found[layout.name] = layout
    return {name: found[name] for name in sorted(found, key=lambda n: (n != DEFAULT, n))}


BUILT_IN: dict[str, JointLayout] = _discover()
LAYOUTS: tuple[str, ...] = (*BUILT_IN, CUSTOM)


def joints_per_person(name: str) -> int | None:
    """K of a built-in layout (None for ``custom``); for file checks (``hac import``)."""
    layout = BUILT_IN.get(name)
    return layout.joints_per_person if layout else None


def names_text(conjunction: str = 'or', custom: bool = True) -> str:
    """The layouts' names for a sentence: ``smpl24, blazepose33, ... or custom``."""
    names = [*BUILT_IN, *([CUSTOM] if custom else [])]
    return ', '.join(names[:-1]) + f' {conjunction} ' + names[-1]


def counts_text() -> str:
    """Each built-in layout's joints per person for a sentence: ``smpl24: 24, ...``, and
    ``custom: joints_per_person``."""
    return ', '.join([f'{name}: {layout.joints_per_person}' for name, layout in BUILT_IN.items()]
                     + [f'{CUSTOM}: joints_per_person'])


def _joints(layout: JointLayout, indices: tuple[int, ...]) -> str:
    names = [layout.joint_names[i] for i in indices]
    return names[0] if len(names) == 1 else 'mean of ' + ', '.join(names)


def markdown_table() -> str:
    """docs/inputs.md's table of the built-in layouts (held to this by test_docs.py)."""
    rows = ['| `joint_layout` | K | written by | root | body axis (lower → upper) | '
            'contact candidates (height above the sole, fraction of the leg) |',
            '| --- | --- | --- | --- | --- | --- |']
    for name, layout in BUILT_IN.items():
        contact = ', '.join(
            layout.joint_names[j] + (f' ({layout.sole_height_rel[j]:.3f})'
                                     if j in layout.sole_height_rel else '')
            for j in layout.contact) or 'every joint' + (
            '; sole heights: ' + ', '.join(f'{layout.joint_names[j]} {h:.3f}'
                                           for j, h in layout.sole_height_rel.items())
            if layout.sole_height_rel else '')
        rows.append(f'| `{name}` | {layout.joints_per_person} | {layout.written_by} | '
                    f'{_joints(layout, layout.root)} | {_joints(layout, layout.axis_lower)} → '
                    f'{_joints(layout, layout.axis_upper)} | {contact} |')
    return '\n'.join(rows)


__all__ = ['BUILT_IN', 'CUSTOM', 'CUSTOM_ROLES', 'DEFAULT', 'LAYOUTS', 'SHOD_ANKLE_REL', 'SMPL24',
           'JointLayout', 'counts_text', 'custom_layout', 'joints_per_person', 'markdown_table',
           'names_text', 'problems']
