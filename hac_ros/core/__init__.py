"""The estimation core: pure numpy/scipy, no ROS import.

The data path: arrays with their frame and unit in their names go into one
:class:`~hac_ros.core.calibrator.Calibrator`, which returns numpy results. Nothing here knows
whether it runs in the node or in a replay.

Its rooms, each reading only the ones before it: ``basics`` (errors, numbers, transforms, the
result records), ``layouts`` (which joint is which), ``rules`` (parameters, reasons, health),
``geometry`` (the map, planes, the floor), ``estimate`` (samples to a scale), ``bodies`` (the
people: contact, posture, checks, one sample), ``stream`` (poses, maps and metric outputs in stamp
order). Above them, here: the :class:`~hac_ros.core.calibrator.Calibrator`, its frame loop
(:mod:`frame_loop`), each person of a frame (:mod:`person_step`), the offline schedule
(:mod:`offline`) and the input arrays' checks (:mod:`input_checks`).
"""
from hac_ros.core.basics.errors import HacError, ParameterError
from hac_ros.core.rules.params import HacParams

__all__ = ['HacError', 'HacParams', 'ParameterError']
