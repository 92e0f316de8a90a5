"""The similarity that best maps one point set onto another (Umeyama 1991), pure numpy: the
importer fits a trajectory's unit to its ground truth with it, the metrics align with it.

It follows evo's ``core/geometry.py::umeyama_alignment``. Points (N, 3) in any one unit each.
"""
from __future__ import annotations

import numpy as np

from hac_ros.core.basics.errors import InputError


def umeyama(src: np.ndarray, dst: np.ndarray,
            with_scale: bool = True) -> tuple[float, np.ndarray, np.ndarray]:
    """The similarity (s, R, t) minimising ‖dst − (s R src + t)‖² (Umeyama 1991).

    src, dst: (N, 3) corresponding points. Without scale, s = 1 (an SE(3) fit).
    """
    src = np.asarray(src, dtype=float)
    dst = np.asarray(dst, dtype=float)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3:
        raise InputError(f'umeyama: expected two (N, 3) arrays, got {src.shape} and {dst.shape}')
    if len(src) < 3:
        raise InputError(f'umeyama: needs at least 3 point pairs, got {len(src)}')
    mean_src, mean_dst = src.mean(axis=0), dst.mean(axis=0)  # eq. 34 and 35
    src_c, dst_c = src - mean_src, dst - mean_dst
    var_src = float(np.mean(np.sum(src_c ** 2, axis=1)))  # eq. 36
    if not var_src > 0.0:
        raise InputError('umeyama: the source points are all equal (degenerate)')
    cov = dst_c.T @ src_c / len(src)  # eq. 38
    U, D, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0.0:  # eq. 39: a reflection
        S[2, 2] = -1.0
    R = U @ S @ Vt  # eq. 40
    s = float(np.trace(np.diag(D) @ S) / var_src) if with_scale else 1.0  # eq. 42
    t = mean_dst - s * R @ mean_src  # eq. 41
    return s, R, t


def apply_sim3(s: float, R: np.ndarray, t: np.ndarray, points: np.ndarray) -> np.ndarray:
    """s R p + t for points (..., 3)."""
    return s * np.asarray(points) @ np.asarray(R).T + t
