"""The estimation core: pure numpy/scipy, no ROS import.

The data path: arrays with their frame and unit in their names go into one
:class:`~hac_ros.core.calibrator.Calibrator`, which returns numpy results. Nothing here knows
whether it runs in the node or in a replay.
"""
from hac_ros.core.errors import HacError, ParameterError
from hac_ros.core.params import HacParams

__all__ = ['HacError', 'HacParams', 'ParameterError']
