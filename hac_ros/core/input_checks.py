"""The checks an input array passes before anything is calibrated: one set for every door.

``calibrate()`` (:mod:`hac_ros.api`) takes arrays, ``hac import`` (:mod:`hac_ros.files`) reads
them from files; both pass them through these functions, so the same bad array gives the same
message through both (``test/test_calibrate.py``). Each check raises
:class:`~hac_ros.core.basics.errors.InputError` as ``'{where}: {what is wrong}'``: ``where`` is how
the caller names the input (``joints_cam``, or ``joints run/joints.npz: joints``), the rest is the
check's own and says the shape and the unit expected.

- stamps: (N,) seconds, finite ROS times (0 to 2^31 s), strictly increasing; to int64 ns by
  round(t × 1e9) (docs/interface.md, "Conventions");
- joints: (T, P, K, 3) metres, K the layout's joints per person, no inf (an all-NaN (K, 3) block
  is an absent person), someone in some frame, and bodies the size of a body in metres (the median
  person's joints spread over 0.3 to 4 m: :func:`hac_ros.core.geometry.plausibility.span_problem`,
  the calibrator's own test: millimetre joints are refused here rather than counted there);
- map points: (M, 3), at least one finite point other than (0, 0, 0).
"""
from __future__ import annotations

import numpy as np

from hac_ros.core.basics.errors import InputError
from hac_ros.core.basics.numeric import NS, median_of
from hac_ros.core.geometry.plausibility import body_spans, span_problem

MAX_STAMP_S = 2.0**31  # builtin_interfaces/Time's sec is an int32; no ROS time is negative


def numbers(value: object, where: str, shape: str, unit: str) -> np.ndarray:
    """``value`` as a float64 array; InputError when it is not numbers."""
    try:
        array = np.asarray(value)
        if array.dtype.kind not in 'iuf':
            raise TypeError(f'{array.dtype} values')
        return array.astype(float)
    except (TypeError, ValueError) as exc:
        raise InputError(f'{where}: expected {shape} numbers ({unit}), got '
                         f'{type(value).__name__} ({exc})') from exc


def stamps_ns(value: object, where: str, labels: list[str] | None = None) -> np.ndarray:
    """(N,) seconds -> (N,) int64 nanoseconds by round(t × 1e9): non-empty, finite ROS times
    (:func:`ros_time_ns`), strictly increasing (:func:`increasing`). ``labels``: each stamp's
    place in a file (``line 12``), else ``[i]``."""
    t = numbers(value, where, '(N,)', 'seconds')
    if t.ndim != 1 or not len(t):
        raise InputError(f'{where}: expected a non-empty (N,) array of seconds, got shape '
                         f'{t.shape}')
    ns = ros_time_ns(t, where, labels)
    increasing(ns, where, labels)
    return ns


def ros_time_ns(t: np.ndarray, where: str, labels: list[str] | None = None) -> np.ndarray:
    """(N,) float seconds -> int64 ns by round(t × 1e9); InputError naming the first stamp that is
    not a ROS time (NaN, inf, negative, past 2^31 s)."""
    t = np.asarray(t, dtype=np.float64)
    bad = ~(np.isfinite(t) & (t >= 0.0) & (t < MAX_STAMP_S))
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f'{where}: {_label(labels, i)} = {float(t[i])!r} s is not a ROS time '
                         '(finite seconds, 0 to 2^31)')
    return np.round(t * NS).astype(np.int64)


def increasing(ns: np.ndarray, where: str, labels: list[str] | None = None) -> None:
    """InputError naming the first stamp (int ns) that is not after the one before."""
    back = np.flatnonzero(np.diff(ns) <= 0)
    if len(back):
        i = int(back[0]) + 1
        raise InputError(f'{where}: stamps must increase (seconds), but {_label(labels, i)} = '
                         f'{ns[i] / NS:.9f} is not after {_label(labels, i - 1)} = '
                         f'{ns[i - 1] / NS:.9f}')


def _label(labels: list[str] | None, i: int) -> str:
    return labels[i] if labels is not None else f'[{i}]'


def joints(value: object, where: str, joints_per_person: int | None = None, layout: str = '',
           frame: str = 'the camera optical frame') -> np.ndarray:
    """(T, P, K, 3) metres in ``frame`` -> float64, checked (module docstring); K must be
    ``joints_per_person`` (the layout ``layout``'s) when given."""
    k = f' with K = {joints_per_person}' + (f' ({layout})' if layout else '') \
        if joints_per_person is not None else ''
    array = numbers(value, where, '(T, P, K, 3)', f'metres, {frame}')
    if array.ndim != 4 or array.shape[3] != 3 or 0 in array.shape[:3] or (
            joints_per_person is not None and array.shape[2] != joints_per_person):
        raise InputError(f'{where}: expected (T, P, K, 3) metres in {frame}{k}, got shape '
                         f'{array.shape}')
    if np.isinf(array).any():
        raise InputError(f'{where}: holds inf values (metres; NaN blocks mark absent people)')
    if np.isnan(array).all():
        raise InputError(f'{where}: no person in any frame (every (K, 3) block is NaN)')
    return array


def joints_unit(array: np.ndarray, where: str) -> int:
    """The people of (T, P, K, 3) joints are metres: InputError when the median person is not the
    size of a body in metres (naming the likely unit); the number of people who are not."""
    spans = body_spans(array)
    problem = span_problem(median_of(spans)) if len(spans) else ''
    if problem:
        raise InputError(f'{where}: {problem} (the median of {len(spans)} people)')
    return sum(bool(span_problem(float(span))) for span in spans)


def frames_match(stamps: np.ndarray, array: np.ndarray, stamps_where: str,
                 joints_where: str) -> None:
    """As many stamps as joints frames."""
    if len(stamps) != len(array):
        raise InputError(f'{stamps_where}: {len(stamps)} stamps (seconds) but {joints_where} has '
                         f'{len(array)} frames (shape {array.shape}); they must match')


def map_points(value: object, where: str) -> np.ndarray:
    """(M, 3) map points, SLAM units -> the finite ones other than (0, 0, 0) (as from a
    PointCloud2); InputError when none is left."""
    points = numbers(value, where, '(M, 3)', 'SLAM units')
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(f'{where}: expected (M, 3) map points in SLAM units, got shape '
                         f'{points.shape}')
    points = points[np.isfinite(points).all(axis=1) & (points != 0.0).any(axis=1)]
    if not len(points):
        raise InputError(f'{where}: no finite map point other than (0, 0, 0) (SLAM units)')
    return points
