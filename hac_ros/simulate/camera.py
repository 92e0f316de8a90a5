"""Camera rigs: a handheld camera following a person, a head-mounted camera, a static camera.

Every rig returns (R_wc (T, 3, 3) camera-to-world rotations of an optical camera — x right, y
down, z forward — and c (T, 3) camera centres, metres, world frame, z up).
"""
from __future__ import annotations

import numpy as np

K_DEFAULT = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
WIDTH, HEIGHT = 640, 480


def look_at(camera: np.ndarray, target: np.ndarray, roll: float = 0.0) -> np.ndarray:
    """Camera-to-world rotation of an optical camera at ``camera`` looking at ``target``."""
    z = target - camera
    z = z / np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z], axis=1)
    if roll:
        c, s = np.cos(roll), np.sin(roll)
        R = R @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return R


def _smooth(x: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average along axis 0 (edges padded with the end values)."""
    if window <= 1:
        return x
    pad = np.concatenate([np.repeat(x[:1], window, 0), x, np.repeat(x[-1:], window, 0)])
    kernel = np.ones(window) / window
    out = np.stack([np.convolve(pad[:, d], kernel, mode='same') for d in range(x.shape[1])], 1)
    return out[window:-window]


def follow(root: np.ndarray, t: np.ndarray, rng: np.random.Generator, distance: float = 3.5,
           height: float = 1.5, side_deg: float = 35.0,
           jitter: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """A handheld camera behind and beside a walker, looking at the body's middle.

    root: (T, 3) the person's pelvis, world metres; t: (T,) seconds.
    """
    rate = 1.0 / max(float(np.median(np.diff(t))), 1e-3) if len(t) > 1 else 30.0
    velocity = np.gradient(root[:, :2], axis=0)
    velocity = _smooth(velocity, int(rate))
    heading = np.arctan2(velocity[:, 1], velocity[:, 0])
    heading = np.unwrap(heading)
    look = heading + np.radians(side_deg)
    back = np.c_[np.cos(look), np.sin(look)]
    wobble = np.c_[np.sin(1.3 * t), np.sin(0.9 * t + 1.0), np.sin(1.7 * t + 2.0)] * jitter
    centre = np.c_[root[:, :2] - distance * back, np.full(len(t), height)] + wobble
    centre = _smooth(centre, int(rate // 2))
    target = np.c_[root[:, :2], np.full(len(t), 0.6)]
    rolls = np.radians(1.0) * np.sin(0.7 * t + rng.uniform(0, 6.28))
    R = np.stack([look_at(centre[i], target[i], rolls[i]) for i in range(len(t))])
    return R, centre


def head_mounted(partner_root: np.ndarray, t: np.ndarray, rng: np.random.Generator,
                 distance: float = 1.8, height: float = 1.62) -> tuple[np.ndarray, np.ndarray]:
    """Egocentric: walking with a partner, looking at them at eye level, the head pitching now and
    then (so their feet are out of view in most frames)."""
    R, centre = follow(partner_root, t, rng, distance=distance, height=height, side_deg=25.0,
                       jitter=0.01)
    phase = rng.uniform(0, 6.28)
    pitch = np.radians(3.0 + 14.0 * np.clip(np.sin(0.35 * t + phase), 0.0, 1.0) ** 3)
    out = np.empty_like(R)
    for i in range(len(t)):
        target = np.r_[partner_root[i, :2], height]  # eye level: level gaze
        base = look_at(centre[i], target)
        c, s = np.cos(pitch[i]), np.sin(pitch[i])
        # z tilts to +y: down
        out[i] = base @ np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])
    return out, centre


def side(root: np.ndarray, t: np.ndarray, offset_y: float, height: float = 1.5,
         follow: float = 0.8) -> tuple[np.ndarray, np.ndarray]:
    """A camera walking beside a person's line at ``offset_y`` metres, looking at their shins.

    For walkers that turn on the spot (shuttles), where a follower would swing round them.
    """
    centre = np.c_[root[:, 0] * follow, root[:, 1] + offset_y, np.full(len(t), height)]
    centre = _smooth(centre, 15)
    R = np.stack([look_at(centre[i], np.r_[root[i, :2], 0.5]) for i in range(len(t))])
    return R, centre


def static(target: np.ndarray, t: np.ndarray,
           position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A camera that does not move, looking at ``target``."""
    R = look_at(np.asarray(position, float), np.asarray(target, float))
    return np.repeat(R[None], len(t), 0), np.repeat(np.asarray(position, float)[None], len(t), 0)


def project(points_cam: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (..., 2) of camera-frame points (..., 3) and whether each is in front (z > 0.05 m)."""
    z = points_cam[..., 2]
    front = z > 0.05
    zs = np.where(front, z, 1.0)
    u = K[0, 0] * points_cam[..., 0] / zs + K[0, 2]
    v = K[1, 1] * points_cam[..., 1] / zs + K[1, 2]
    return np.stack([u, v], axis=-1), front
