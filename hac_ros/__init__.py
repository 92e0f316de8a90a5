"""hac_ros: metric scale for monocular SLAM from the people in view.

Importing this package imports nothing from ROS; the node lives in :mod:`hac_ros.ros.node`.
``from hac_ros import calibrate`` is the one-call API on numpy arrays (:mod:`hac_ros.api`),
imported when first asked for.
"""
from __future__ import annotations

from typing import Any

__version__ = '0.1.0'
__all__ = ['CalibrationResult', 'calibrate']


def __getattr__(name: str) -> Any:
    """``calibrate`` and ``CalibrationResult`` from :mod:`hac_ros.api`, imported on first use
    (numpy and scipy only when needed: ``import hac_ros`` stays cheap)."""
    if name in __all__:
        from hac_ros import api

        return getattr(api, name)
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
