"""Is a reconstruction fit to calibrate from? (docs/video.md, "Gates")

Structure from motion can report success with a wrong camera: on real frames of a flat board,
self-calibration converged to a focal of 72 px where the truth was 536. Each gate below names what
it measured and the bound it broke; ``hac video`` refuses (exit 2) when any fails, and says so
rather than write a trajectory it cannot stand behind.

- ``registered``: at least ``MIN_REGISTERED`` of the keyframes registered, in the model kept or
  another (a video that cuts to another scene breaks into models: the largest is used, and said);
- ``reprojection``: the mean reprojection error at most ``MAX_REPROJECTION_PX``;
- ``baseline``: the cameras' spread at least ``MIN_BASELINE`` of the median distance to the map
  (a camera that only turns, or stands still, sees no depth: that is ``static_camera``'s case);
- with self-calibration only: ``field_of_view`` (horizontal, between ``FOV_DEG``), ``depth``
  (the map not one plane: its thinnest spread at least ``MIN_THICKNESS`` of its widest; a plane
  leaves the focal free), ``views`` (the cameras' viewing directions spread at least
  ``MIN_TURN_DEG``: a camera that never turns leaves the focal and the depth trading off) and
  ``pairs`` (at least ``MIN_GENERAL_PAIRS`` of the matched pairs with a general two-view geometry:
  pairs that are a plane or a pure rotation say nothing of the focal; a room seen mostly by its
  back wall self-calibrated to 787 px for a true 500, every other gate passed).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hac_ros.video.sfm import Reconstruction

MIN_REGISTERED = 0.8
MAX_REPROJECTION_PX = 1.5
MIN_BASELINE = 0.05
FOV_DEG = (20.0, 130.0)
MIN_THICKNESS = 0.1
MIN_TURN_DEG = 5.0
MIN_GENERAL_PAIRS = 0.1  # the fooled room had 6 %; a camera walking toward the people 20 %


@dataclass
class Gate:
    """One gate: ``name``, the ``value`` measured, ``passed``, and ``text`` saying both."""

    name: str
    value: float
    passed: bool
    text: str


def _spread(points: np.ndarray) -> np.ndarray:
    """Standard deviations along the principal axes, largest first."""
    centred = points - np.median(points, axis=0)
    inner = np.abs(centred) <= 3.0 * np.percentile(np.abs(centred), 90, axis=0) + 1e-12
    kept = centred[inner.all(axis=1)]
    return np.sqrt(np.maximum(np.linalg.eigvalsh(np.cov(kept.T))[::-1], 0.0))


def baseline(model: Reconstruction) -> float:
    """The cameras' spread (RMS distance of the centres from their mean) over the median distance
    from a camera to the map's points."""
    if len(model.centres) < 2 or not len(model.points):
        return 0.0
    spread = float(np.sqrt(((model.centres - model.centres.mean(axis=0)) ** 2).sum(axis=1)
                           .mean()))
    step = max(1, len(model.points) // 2000)
    distance = np.linalg.norm(model.points[::step, None, :] - model.centres[None], axis=2)
    return spread / float(np.median(distance))


def judge(model: Reconstruction) -> list[Gate]:
    """Every gate of the module docstring, measured on ``model``."""
    gates = []
    registered = sum(model.model_sizes)
    share = registered / max(1, model.keyframes)
    models = (f' ({len(model.names)} in the model used, {registered - len(model.names)} in '
              f'{len(model.model_sizes) - 1} other(s))' if len(model.model_sizes) > 1 else '')
    gates.append(Gate('registered', share, share >= MIN_REGISTERED,
                      f'{registered} of {model.keyframes} keyframes registered{models} '
                      f'({share:.0%}; at least {MIN_REGISTERED:.0%})'))
    error = model.reprojection_px
    gates.append(Gate('reprojection', error, math.isfinite(error) and error <= MAX_REPROJECTION_PX,
                      f'mean reprojection error {error:.2f} px (at most '
                      f'{MAX_REPROJECTION_PX:g})'))
    ratio = baseline(model)
    gates.append(Gate('baseline', ratio, ratio >= MIN_BASELINE,
                      f'the camera moved {ratio:.3f} of its distance to the scene (at least '
                      f'{MIN_BASELINE:g}; a still or only turning camera: static_camera)'))
    if not model.self_calibrated:
        return gates
    fov = math.degrees(2.0 * math.atan(model.width / (2.0 * model.K[0, 0])))
    gates.append(Gate('field_of_view', fov, FOV_DEG[0] <= fov <= FOV_DEG[1],
                      f'self-calibrated focal {model.K[0, 0]:.0f} px: a horizontal field of view '
                      f'of {fov:.0f}° (plausible: {FOV_DEG[0]:g}–{FOV_DEG[1]:g}°)'))
    spread = _spread(model.points) if len(model.points) >= 10 else np.zeros(3)
    thickness = float(spread[2] / spread[0]) if spread[0] > 0 else 0.0
    gates.append(Gate('depth', thickness, thickness >= MIN_THICKNESS,
                      f'the map\'s thinnest spread is {thickness:.2f} of its widest (at least '
                      f'{MIN_THICKNESS:g}: a flat scene leaves the focal free)'))
    axes = model.R_wc[:, :, 2]
    turn = math.degrees(math.acos(min(1.0, float(np.linalg.norm(axes.mean(axis=0))))))
    gates.append(Gate('views', turn, turn >= MIN_TURN_DEG,
                      f'the viewing directions spread {turn:.1f}° (at least {MIN_TURN_DEG:g}°: '
                      'a camera that never turns leaves the focal free)'))
    share = model.general_pairs
    gates.append(Gate('pairs', share, share >= MIN_GENERAL_PAIRS,
                      f'{share:.0%} of the matched pairs have a general geometry (at least '
                      f'{MIN_GENERAL_PAIRS:.0%}: a plane or a pure rotation says nothing of the '
                      'focal)'))
    return gates


def failed(gates: list[Gate]) -> list[Gate]:
    return [gate for gate in gates if not gate.passed]
