"""Only standing people measure the floor (docs/method.md, "Who measures: standing people").

A seated person's feet may rest on the floor or hang from a stool, a kneeling person touches the
floor with the knees, a lying one with the back: the body cannot tell planted feet from hanging
ones, so none of them gives a contact sample (``not_standing``), whatever the feet touch. The
posture is judged on the HMR body itself, scale-free, in the body's own frame:

- a *support leg* has its thigh (hip → knee) within STANDING_THIGH_MAX_DEG and its shin (knee →
  ankle) within STANDING_SHIN_MAX_DEG of the body's down axis (upper → lower joints of the
  layout's axis); a person stands when one leg is a support leg. Seated: the thighs are across the
  axis (about 90 degrees); kneeling: the shins are (about 90 degrees); walking, the stance leg is
  within 40 degrees on both. People on their hands keep their legs along the axis: they measure,
  as before (the hands are the contact).
- without a support leg, a person *balanced over their feet* stands on them (a squat, a crouch
  to pick something up): once the scene's down is known, the mean of their joints lies within
  BALANCE_MAX_M of their feet across it. A seated person's weight is on the seat, behind the feet
  (0.3 m and more), a kneeling one's on the knees.
- lying: the body's axis is across the scene's down (within LYING_MAX_DEG of horizontal), judged
  once down is known (:mod:`hac_ros.core.geometry.down_vote`): a lying body's legs are along its
  axis.

Jumps are not judged here: a jump's samples leave the estimator's gate. A layout without legs
(``custom`` without ``legs``) is judged by its axis alone. Measured on the CMU motions: every
frame of the walk 131_02 and of the hop 131_03 stands; 131_01 crouches for about 9 % of its
frames (the pelvis 0.5-0.8 m up: a seated shape, its weight within 9 cm of its feet): they stand
by balance (docs/method.md).
"""
from __future__ import annotations

import math

import numpy as np

from hac_ros.core.layouts import JointLayout

STANDING_THIGH_MAX_DEG = 65.0  # a support leg's thigh against the body's down axis
STANDING_SHIN_MAX_DEG = 50.0  # ... and its shin
LYING_MAX_DEG = 45.0  # a body axis within this of horizontal (scene's down known) is lying
BALANCE_MAX_M = 0.15  # the joints' mean within this of the feet, across down: on its feet

_THIGH_COS = math.cos(math.radians(STANDING_THIGH_MAX_DEG))
_SHIN_COS = math.cos(math.radians(STANDING_SHIN_MAX_DEG))
_LYING_COS = math.sin(math.radians(LYING_MAX_DEG))  # |cos| of axis vs down below this: lying


def posture_problem(layout: JointLayout, joints: np.ndarray, up: np.ndarray,
                    down: np.ndarray | None) -> str:
    """Why this body does not stand ('' when it does): 'seated or kneeling' (no support leg), or
    'lying' (its axis across ``down``).

    joints: (K, 3) metres, any frame (NaN rows: not seen; a leg with one is not judged, and
    without a leg seen whole nor the feet the body does not stand as far as it shows); up: (3,)
    the layout's lower → upper axis in that frame, any length; down: (3,) the scene's down, unit,
    same frame, or None while unknown.
    """
    norm = float(np.linalg.norm(up))
    if not math.isfinite(norm) or norm <= 0.0:
        return ''
    body_down = -up / norm
    if down is not None and abs(float(body_down @ down)) < _LYING_COS:
        return 'lying'
    if not layout.legs:
        return ''
    for hip, knee, ankle in layout.legs:
        thigh = joints[knee] - joints[hip]
        shin = joints[ankle] - joints[knee]
        t_norm, s_norm = float(np.linalg.norm(thigh)), float(np.linalg.norm(shin))
        if not (t_norm > 0.0 and s_norm > 0.0):  # NaN: a joint not seen
            continue
        if (float(thigh @ body_down) >= _THIGH_COS * t_norm
                and float(shin @ body_down) >= _SHIN_COS * s_norm):
            return ''
    if down is not None and layout.feet:
        seen = joints[np.isfinite(joints).all(axis=1)]
        feet = joints[list(layout.feet)]
        feet = feet[np.isfinite(feet).all(axis=1)]
        if not len(feet):
            return 'seated or kneeling'  # no foot seen: not known to stand
        offset = seen.mean(axis=0) - feet.mean(axis=0)
        across = offset - float(offset @ down) * down
        if float(np.linalg.norm(across)) <= BALANCE_MAX_M:
            return ''  # balanced over the feet: a squat, a crouch
    return 'seated or kneeling'
