"""The field's metrics (docs/interface.md, "Metrics"), pure numpy; the alignments by
:mod:`hac_ros.core.basics.similarity` (Umeyama). The human metrics follow the evaluation code of
TRAM/WHAM, which takes them from SLAHMR: ``first_align_joints``
(W-MPJPE), ``global_align_joints`` (WA-MPJPE), ``compute_rte`` (RTE) and the per-frame Procrustes
of ``batch_compute_similarity_transform`` (PA-MPJPE). Positions in metres in; errors out in the
unit each function names.
"""
from __future__ import annotations

import math

import numpy as np

from hac_ros.core.basics.errors import InputError
from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.similarity import apply_sim3, umeyama

M_TO_MM = 1000.0
CHUNK_FRAMES = 100  # TRAM/WHAM: W-MPJPE and WA-MPJPE over 100-frame chunks


def associate_stamps(stamps_a: np.ndarray, stamps_b: np.ndarray,
                     max_diff_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices (idx_a, idx_b) pairing each stamp of ``a`` with the nearest of ``b`` within max_diff.

    Like evo's ``sync.associate_trajectories`` for the common case of a sparse estimate against a
    dense reference. Stamps are int nanoseconds; ``b`` must be sorted.
    """
    a = np.asarray(stamps_a, dtype=np.int64)
    b = np.asarray(stamps_b, dtype=np.int64)
    if b.size == 0 or a.size == 0:
        return np.empty(0, dtype=int), np.empty(0, dtype=int)
    pos = np.clip(np.searchsorted(b, a), 1, len(b) - 1) if len(b) > 1 else np.zeros(len(a), int)
    left = np.clip(pos - 1, 0, len(b) - 1)
    nearest = np.where(np.abs(b[left] - a) <= np.abs(b[pos] - a), left, pos)
    keep = np.abs(b[nearest] - a) <= max_diff_ns
    return np.flatnonzero(keep), nearest[keep]


def ate(est_positions: np.ndarray, gt_positions: np.ndarray, with_scale: bool = True) -> float:
    """Mean (not RMSE, like evo's ``stats['mean']``) camera-centre error in metres after aligning
    the estimate onto the truth with Umeyama: Sim(3) ("ATE") or SE(3) ("ATE-S")."""
    s, R, t = umeyama(est_positions, gt_positions, with_scale)
    aligned = apply_sim3(s, R, t, est_positions)
    return float(np.mean(np.linalg.norm(aligned - gt_positions, axis=1)))


def ate_s(est_positions: np.ndarray, gt_positions: np.ndarray) -> float:
    """ATE after an SE(3) alignment (no scale): a wrong scale shows."""
    return ate(est_positions, gt_positions, with_scale=False)


def rpe(est_positions: np.ndarray, est_rotations: np.ndarray, gt_positions: np.ndarray,
        gt_rotations: np.ndarray, stamps_ns: np.ndarray,
        delta_s: float = 1.0) -> tuple[float, float]:
    """Relative pose error of the translation (evo's RPE, delta in time): for every pose i and the
    first pose j at least ``delta_s`` later, the step R_iᵀ (p_j − p_i) of the estimate against the
    truth's, both in the camera frame of pose i (no alignment needed: it is frame-invariant).

    est/gt positions (N, 3) metres, rotations (N, 3, 3) camera to their world frames, matched
    pose for pose; stamps_ns (N,). Returns (mean error, metres; 100 × the sum of errors over the
    sum of true step lengths, %); NaN without a pair.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    i = np.arange(len(stamps))
    j = np.searchsorted(stamps, stamps + int(delta_s * NS), side='left')
    keep = j < len(stamps)
    i, j = i[keep], j[keep]
    if not len(i):
        return math.nan, math.nan

    def steps(p: np.ndarray, R: np.ndarray) -> np.ndarray:
        return np.einsum('nji,nj->ni', R[i], p[j] - p[i])

    true = steps(np.asarray(gt_positions), np.asarray(gt_rotations))
    err = np.linalg.norm(steps(np.asarray(est_positions), np.asarray(est_rotations)) - true, axis=1)
    length = float(np.linalg.norm(true, axis=1).sum())
    return float(err.mean()), (100.0 * float(err.sum()) / length if length > 0 else math.nan)


def _align_chunk(pred: np.ndarray, gt: np.ndarray, frames: slice) -> np.ndarray:
    """pred (T, J, 3) aligned by the Sim(3) fitted on the joints of ``frames`` (pred onto gt)."""
    s, R, t = umeyama(pred[frames].reshape(-1, 3), gt[frames].reshape(-1, 3), with_scale=True)
    return apply_sim3(s, R, t, pred)


def _chunks(n: int, chunk: int) -> list[tuple[int, int]]:
    """TRAM's chunking: starts every ``chunk`` frames; the last chunk runs to the sequence's end
    (minus one frame, as TRAM does) when another full chunk would not fit. A sequence of at most one
    chunk is evaluated as one chunk (TRAM would skip it)."""
    if n <= chunk:
        return [(0, n)]
    out = []
    for start in range(0, n - chunk, chunk):
        end = start + chunk
        if start + 2 * chunk > n:
            end = n - 1
        out.append((start, end))
    return out


def _check_joints(pred: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pred = np.asarray(pred, dtype=float)
    gt = np.asarray(gt, dtype=float)
    if pred.shape != gt.shape or pred.ndim != 3 or pred.shape[2] != 3:
        raise InputError(f'expected two (T, J, 3) arrays of one person, got {pred.shape} and '
                         f'{gt.shape}')
    return pred, gt


def w_mpjpe(pred: np.ndarray, gt: np.ndarray, chunk: int = CHUNK_FRAMES) -> float:
    """World MPJPE (mm): each chunk aligned by the Sim(3) of its first two frames' joints.

    pred, gt: (T, J, 3) one person's joints in metres (world frames may differ). Per-frame errors
    of every chunk are concatenated and averaged (TRAM). For several people, call once per track.
    """
    pred, gt = _check_joints(pred, gt)
    errors = []
    for a, b in _chunks(len(pred), chunk):
        aligned = _align_chunk(pred[a:b], gt[a:b], slice(0, 2))
        errors.append(np.linalg.norm(aligned - gt[a:b], axis=2).mean(axis=1))
    return float(np.concatenate(errors).mean() * M_TO_MM)


def wa_mpjpe(pred: np.ndarray, gt: np.ndarray, chunk: int = CHUNK_FRAMES) -> float:
    """World-aligned MPJPE (mm): each chunk aligned by the Sim(3) fitted on the whole chunk."""
    pred, gt = _check_joints(pred, gt)
    errors = []
    for a, b in _chunks(len(pred), chunk):
        aligned = _align_chunk(pred[a:b], gt[a:b], slice(None))
        errors.append(np.linalg.norm(aligned - gt[a:b], axis=2).mean(axis=1))
    return float(np.concatenate(errors).mean() * M_TO_MM)


def rte(pred_root: np.ndarray, gt_root: np.ndarray) -> float:
    """Root translation error (%): a rigid (SE(3)) alignment of the whole root trajectory, each
    frame's error divided by the ground truth's path length, averaged, × 100 (TRAM compute_rte)."""
    pred_root = np.asarray(pred_root, dtype=float)
    gt_root = np.asarray(gt_root, dtype=float)
    s, R, t = umeyama(pred_root, gt_root, with_scale=False)
    aligned = apply_sim3(s, R, t, pred_root)
    path = float(np.sum(np.linalg.norm(np.diff(gt_root, axis=0), axis=1)))
    if not path > 0.0:
        raise InputError('rte: the ground-truth root does not move (path length 0)')
    return float(np.mean(np.linalg.norm(aligned - gt_root, axis=1)) / path * 100.0)


def pa_mpjpe(pred: np.ndarray, gt: np.ndarray) -> float:
    """Procrustes-aligned MPJPE (mm): every frame aligned by its own Sim(3)."""
    pred, gt = _check_joints(pred, gt)
    errors = [np.linalg.norm(apply_sim3(*umeyama(p, g, True), p) - g, axis=1).mean()
              for p, g in zip(pred, gt)]
    return float(np.mean(errors) * M_TO_MM)


def scale_error(est: np.ndarray | float, true: np.ndarray | float) -> np.ndarray:
    """|est / true − 1| × 100, elementwise (percent)."""
    return np.abs(np.asarray(est, dtype=float) / np.asarray(true, dtype=float) - 1.0) * 100.0
