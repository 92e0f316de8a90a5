"""The ``[video]`` extra: pycolmap (and the ``[people]`` extra), imported only here and by the
modules of :mod:`hac_ros.video` that need it, never by the core, the replay or the nodes.

:func:`require_pycolmap` says, as an :class:`~hac_ros.people.extra.ExtraMissing` naming the install
command, what is missing; ``hac video`` exits 2 with it.
"""
from __future__ import annotations

import importlib
import importlib.util
from types import ModuleType

from hac_ros.people.extra import ExtraMissing

PACKAGE = 'pycolmap>=4.2,<5'
INSTALL = "pip install 'hac_ros[video]'"  # from the repository: pip install -e '.[video]'


def available() -> bool:
    """pycolmap is importable (without importing it)."""
    try:
        return importlib.util.find_spec('pycolmap') is not None
    except (ImportError, ValueError):  # set to None in sys.modules: blocked
        return False


def require_pycolmap() -> ModuleType:
    """pycolmap, imported, its own log quiet below fatal errors; ExtraMissing naming the install
    command when it is missing."""
    if not available():
        raise ExtraMissing(f'hac video needs pycolmap (the [video] extra, {PACKAGE}): {INSTALL}')
    try:
        pycolmap = importlib.import_module('pycolmap')
    except ImportError as exc:
        raise ExtraMissing(f'pycolmap is installed but does not import ({exc}): {INSTALL}'
                           ) from exc
    pycolmap.logging.minloglevel = 3  # glog: fatal only (INFO per image; its errors are ours)
    pycolmap.logging.stderrthreshold = 3
    return pycolmap
