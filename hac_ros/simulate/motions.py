"""People: a procedural gait with correct foot contacts, a handstand, a skater, or real motion.

Every function returns joints (T, 24, 3) in metres, world frame (z up), SMPL-24 order. In the gait
the stance foot stays where it landed, the swing foot travels in an arc to the next footprint, the
knees follow by two-bone inverse kinematics (thigh 0.41 m, shank 0.39 m), and the pelvis bobs 2 cm
per step. The stance foot is not always planted (:class:`FootRoll`): its foot joint is lifted at
heel strike (toe up) and rises again towards toe-off, so the lowest joint of the body stands on
the walking surface only in mid-stance, as in real gait (the CMU walks: :data:`FootRoll`).
"""
from __future__ import annotations

import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hac_ros.core.basics.errors import InputError
from hac_ros.core.basics.printable import printable
from hac_ros.simulate.world import World

THIGH_M, SHANK_M = 0.41, 0.39
STEP_PERIOD_S = 0.55  # one step (half a gait cycle)
SWING_HEIGHT_M = 0.10
PELVIS_BOB_M = 0.02
FOOT_LATERAL_M = 0.11
# ankle relative to the foot joint (fwd, left, up): in a real CMU motion-capture walk the stance
# ankle is about 3 cm above the lowest (foot) joint, in SMPL about 4.5 cm
ANKLE_ABOVE_FOOT = np.array([-0.11, 0.0, 0.06])


@dataclass(frozen=True)
class FootRoll:
    """How far the stance foot's foot joint is lifted off its footprint during a step, metres:
    ``heel_strike`` when it lands (toe up), easing to 0 by HEEL_STRIKE_END of the step (flat),
    then rising from TOE_OFF_START to ``toe_off`` when the foot leaves (heel up). The swing foot
    leaves at ``toe_off`` and lands at ``heel_strike`` above its footprints. ``FootRoll()`` is a
    foot always planted in stance.

    The real walks (CMU subject 131, re-floored to SMPL's foot height) have their lowest joint
    above its 5th percentile by 0.5-0.9 cm at the quartile, 0.9-1.2 cm at the median and 2.8 cm
    at the 95th percentile (131_02, 131_03; 131_01: 2.0, 2.7 and 4.0 cm). The scenarios draw each
    walker's roll from ROLL_HEEL_STRIKE_M and ROLL_TOE_OFF_M: lifts of 0.1-0.3 cm, 0.5-1.2 cm and
    2.5-4 cm at those percentiles (test_simulate.py measures them).
    """

    heel_strike: float = 0.0
    toe_off: float = 0.0

    def stance_lift(self, phase: float) -> float:
        """The stance foot joint's lift (metres) at ``phase`` (0..1) of its step."""
        if phase < HEEL_STRIKE_END:
            return self.heel_strike * (1.0 - phase / HEEL_STRIKE_END) ** 2
        if phase > TOE_OFF_START:
            return self.toe_off * ((phase - TOE_OFF_START) / (1.0 - TOE_OFF_START)) ** 2
        return 0.0  # flat


# the landed foot is flat from this phase of its step until the next (a moment: it rolls on)
HEEL_STRIKE_END = TOE_OFF_START = 0.6
ROLL_HEEL_STRIKE_M = (0.03, 0.06)  # each walker's heel-strike lift, drawn uniformly
ROLL_TOE_OFF_M = (0.01, 0.04)  # ... and toe-off lift

# Standing template: (forward, left, up) metres, feet on the floor.
STANDING = np.array([
    [0.00, 0.00, 0.93], [0.00, 0.09, 0.86], [0.00, -0.09, 0.86], [-0.01, 0.00, 1.05],
    [0.02, 0.10, 0.47], [0.02, -0.10, 0.47], [-0.01, 0.00, 1.18], [-0.01, 0.11, 0.08],
    [-0.01, -0.11, 0.08], [-0.01, 0.00, 1.26], [0.10, 0.11, 0.00], [0.10, -0.11, 0.00],
    [0.00, 0.00, 1.45], [0.00, 0.07, 1.38], [0.00, -0.07, 1.38], [0.03, 0.00, 1.62],
    [0.00, 0.18, 1.40], [0.00, -0.18, 1.40], [0.00, 0.22, 1.12], [0.00, -0.22, 1.12],
    [0.03, 0.24, 0.86], [0.03, -0.24, 0.86], [0.05, 0.25, 0.78], [0.05, -0.25, 0.78]])

Path2D = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]  # t (T,) -> xy (T, 2), heading (T,)


def circle_path(centre: tuple[float, float], radius: float, speed: float,
                phase: float = 0.0) -> Path2D:
    """Walking a circle counter-clockwise at ``speed`` m/s."""
    def path(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        angle = phase + speed * np.asarray(t) / radius
        xy = np.c_[centre[0] + radius * np.cos(angle), centre[1] + radius * np.sin(angle)]
        return xy, angle + np.pi / 2
    return path


def shuttle_path(start: tuple[float, float], end: tuple[float, float], speed: float) -> Path2D:
    """Back and forth on a line (turning at the ends)."""
    a, b = np.asarray(start, float), np.asarray(end, float)
    length = float(np.linalg.norm(b - a))
    heading = float(np.arctan2(*(b - a)[::-1]))

    def path(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = (speed * np.asarray(t)) % (2 * length)
        forward = s < length
        d = np.where(forward, s, 2 * length - s)
        xy = a + d[:, None] * (b - a) / length
        return xy, np.where(forward, heading, heading + np.pi)
    return path


def _frame(heading: float) -> np.ndarray:
    """Columns: forward, left, up of a person with this heading (world frame)."""
    c, s = np.cos(heading), np.sin(heading)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _knee(hip: np.ndarray, ankle: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """Two-bone IK: the knee bends forward; a leg that is too long is straight."""
    v = ankle - hip
    d = min(float(np.linalg.norm(v)), THIGH_M + SHANK_M - 1e-4)
    u = v / max(np.linalg.norm(v), 1e-9)
    cos_a = (THIGH_M ** 2 + d ** 2 - SHANK_M ** 2) / (2 * THIGH_M * d)
    sin_a = np.sqrt(max(0.0, 1 - cos_a ** 2))
    f = forward - (forward @ u) * u
    f /= max(np.linalg.norm(f), 1e-9)
    return hip + THIGH_M * (cos_a * u + sin_a * f)


def gait(t: np.ndarray, path: Path2D, world: World, phase_s: float = 0.0,
         roll: FootRoll = FootRoll()) -> np.ndarray:
    """A walker following ``path`` over the world's walkable surfaces (floor, stair steps), its
    feet rolling as ``roll`` says."""
    t = np.asarray(t, dtype=float)
    tk = t + phase_s
    k = np.floor(tk / STEP_PERIOD_S).astype(int)
    step_phase = tk / STEP_PERIOD_S - k  # 0..1 within the step
    kmin, kmax = int(k.min()) - 2, int(k.max()) + 2
    steps = np.arange(kmin, kmax + 1)
    # footprint of step j: where the pelvis will be mid-stance, to the side of the foot that lands
    land_xy, land_heading = path(steps * STEP_PERIOD_S + 0.5 * STEP_PERIOD_S - phase_s)
    side = np.where(steps % 2 == 0, 1.0, -1.0)  # even steps: left foot
    lateral = np.c_[-np.sin(land_heading), np.cos(land_heading)] * (side * FOOT_LATERAL_M)[:, None]
    forward = np.c_[np.cos(land_heading), np.sin(land_heading)] * 0.10
    prints_xy = land_xy + lateral + forward
    prints_z = world.height_at(prints_xy)
    prints = np.c_[prints_xy, prints_z]
    xy, heading = path(t)
    out = np.empty((len(t), 24, 3))
    for i in range(len(t)):
        j = k[i] - kmin
        stance, swing_from, swing_to = prints[j], prints[j - 1], prints[j + 1]
        ph = step_phase[i]
        ease = 0.5 - 0.5 * np.cos(np.pi * ph)
        swing = swing_from + (swing_to - swing_from) * ease
        swing[2] += (SWING_HEIGHT_M * np.sin(np.pi * ph) + (1.0 - ease) * roll.toe_off
                     + ease * roll.heel_strike)
        stance = stance + [0.0, 0.0, roll.stance_lift(ph)]
        left_is_stance = steps[j] % 2 == 0
        feet = {10: stance if left_is_stance else swing, 11: swing if left_is_stance else stance}
        R = _frame(heading[i])
        ground = 0.5 * (stance[2] + min(swing_from[2], swing_to[2]))
        pelvis = np.r_[xy[i], ground + STANDING[0, 2] - PELVIS_BOB_M * np.sin(np.pi * ph)]
        body = pelvis + (STANDING - STANDING[0]) @ R.T
        arm = 0.15 * np.sin(np.pi * (k[i] + ph))  # arms swing against the legs
        for jnt, sgn in ((18, 1), (20, 1), (22, 1), (19, -1), (21, -1), (23, -1)):
            body[jnt] += R[:, 0] * (sgn * arm * (0.5 if jnt in (18, 19) else 1.0))
        for foot, ankle, hip, knee in ((10, 7, 1, 4), (11, 8, 2, 5)):
            body[foot] = feet[foot]
            body[ankle] = feet[foot] + R @ ANKLE_ABOVE_FOOT
            body[knee] = _knee(body[hip], body[ankle], R[:, 0])
        out[i] = body
    return out


def skate(t: np.ndarray, path: Path2D) -> np.ndarray:
    """A standing pose gliding along ``path``: both feet on the floor, no steps."""
    xy, heading = path(np.asarray(t, dtype=float))
    out = np.empty((len(xy), 24, 3))
    for i in range(len(xy)):
        out[i] = np.r_[xy[i], 0.0] + STANDING @ _frame(heading[i]).T
    return out


def handstand(t: np.ndarray, path: Path2D, world: World) -> np.ndarray:
    """Walking on the hands: the hands take the feet's footprints, the body upside down above
    them."""
    walker = gait(t, path, world)
    xy, heading = path(np.asarray(t, dtype=float))
    arms_up = STANDING.copy()
    arms_up[[18, 19], 2], arms_up[[20, 21], 2], arms_up[[22, 23], 2] = 1.70, 1.96, 2.04
    arms_up[[18, 20, 22], 1] = [0.20, 0.21, 0.21]
    arms_up[[19, 21, 23], 1] = [-0.20, -0.21, -0.21]
    arms_up[18:24, 0] = 0.0
    flipped = arms_up.copy()
    flipped[:, 2] = 2.04 - arms_up[:, 2]  # hands at 0, feet at 2.04 m
    flipped[:, 1] = -arms_up[:, 1]  # a half turn about the forward axis swaps left and right
    out = np.empty_like(walker)
    for i in range(len(xy)):
        R = _frame(heading[i])
        body = np.r_[xy[i], 0.0] + flipped @ R.T
        bob = walker[i, 0, 2] - STANDING[0, 2]
        body[:, 2] += bob
        for hand, wrist, elbow, shoulder, foot in ((22, 20, 18, 16, 10), (23, 21, 19, 17, 11)):
            body[hand] = walker[i, foot]
            body[wrist] = walker[i, foot] + np.array([0.0, 0.0, 0.08])
            body[elbow] = 0.5 * (body[wrist] + body[shoulder])
        out[i] = body
    return out


def seated(t: np.ndarray, xy: tuple[float, float], heading: float, seat_m: float,
           rng: np.random.Generator) -> np.ndarray:
    """A person seated on a seat ``seat_m`` high (the seat itself is not in the world, as a stool
    a SLAM did not map): thighs level, shins hanging, the feet wherever the leg puts them (above
    the floor on a high seat); the upper body as it stands, swaying a few centimetres."""
    hip_m = seat_m + 0.08  # the hip joints above the seat
    body = STANDING.copy()
    body[:, 2] += hip_m - STANDING[1, 2]  # the upper body as it stands, hips at hip_m
    for hip, knee, ankle, foot in ((1, 4, 7, 10), (2, 5, 8, 11)):
        side = STANDING[hip, 1]
        body[hip] = (0.0, side, hip_m)
        body[knee] = (THIGH_M, side * 1.1, hip_m)
        body[ankle] = (THIGH_M - 0.02, side * 1.2, hip_m - SHANK_M)
        body[foot] = body[ankle] + (0.11, 0.0, -0.06)
    return _placed(t, body, xy, heading, rng)


def lying(t: np.ndarray, xy: tuple[float, float], heading: float, bed_m: float,
          rng: np.random.Generator) -> np.ndarray:
    """A person lying on the back on a bed ``bed_m`` high (not in the world), head towards
    ``heading``, breathing and shifting a few centimetres."""
    body = STANDING.copy()
    flat = np.c_[body[:, 2] - STANDING[0, 2], body[:, 1], bed_m + 0.10 + body[:, 0]]
    return _placed(t, flat, xy, heading, rng)


def _placed(t: np.ndarray, body: np.ndarray, xy: tuple[float, float], heading: float,
            rng: np.random.Generator) -> np.ndarray:
    """``body`` (24, 3) (forward, left, up) at ``xy`` facing ``heading``, for every stamp of t,
    swaying slowly by a few centimetres (a still person is never quite still)."""
    t = np.asarray(t, dtype=float)
    phase = rng.uniform(0.0, 2 * np.pi, 3)
    sway = 0.02 * np.sin(np.outer(t, [0.3, 0.37, 0.23]) + phase)
    placed = np.r_[xy, 0.0] + body @ _frame(heading).T
    return placed[None] + sway[:, None, :]


def _read_motion(path: Path) -> tuple[np.ndarray, float]:
    """The joints (T, 24, 3) metres and fps of a motion ``.npz``; InputError naming the file when
    it is not one (no pickles are loaded)."""
    where = f'motion file {printable(path)}'
    try:
        data = np.load(path, allow_pickle=False)
        if not isinstance(data, np.lib.npyio.NpzFile):
            raise ValueError('a single array, not an archive of named arrays')
        with data:
            joints = np.asarray(data['joints'], dtype=float)
            fps = float(data['fps'])
    except KeyError as exc:
        raise InputError(f'{where}: no {exc} array (expected joints (T, 24, 3) metres and '
                         'fps)') from exc
    except (OSError, ValueError, TypeError, EOFError, zipfile.BadZipFile) as exc:
        raise InputError(f'{where}: not a readable motion .npz ({printable(exc)})') from exc
    if joints.ndim != 3 or joints.shape[1:] != (24, 3) or len(joints) < 2 \
            or not np.isfinite(joints).all() or not 0.0 < fps < float('inf'):
        raise InputError(f'{where}: expected joints (T >= 2, 24, 3) finite metres and fps > 0, '
                         f'got joints {joints.shape} and fps {fps:g}')
    return joints, fps


def load_motion(path: str | Path, t: np.ndarray) -> np.ndarray:
    """Real motion (a ``cmu_mocap`` npz: joints (T, 24, 3) y-up, floor y = 0, metres) at stamps t,
    z-up, played forwards then backwards to fill ``t``, its mean root over the origin."""
    joints, fps = _read_motion(Path(path))
    joints = np.stack([joints[..., 0], -joints[..., 2], joints[..., 1]], axis=-1)
    n = len(joints)
    frame = np.asarray(t, dtype=float) * fps
    cycle = 2 * (n - 1)
    f = np.mod(frame, cycle)
    f = np.where(f <= n - 1, f, cycle - f)
    lo = np.floor(f).astype(int)
    hi = np.minimum(lo + 1, n - 1)
    w = (f - lo)[:, None, None]
    out = (1 - w) * joints[lo] + w * joints[hi]
    centre = joints[:, 0].mean(axis=0) * [1, 1, 0]
    return out - centre
