"""Lifting a person to metres in the camera frame (docs/method.md, "People from pixels").

A pose model gives, per person, landmarks in the image (pixels, with a visibility) and the same
landmarks in metres in a frame of its own around the hips (BlazePose GHUM 3D's world landmarks:
its axes need not be the camera's). The person's pose in the camera is the rigid motion (R, t)
that carries the metric landmarks W_i onto the rays of the image landmarks: with m_i the undistorted
normalised image point of landmark i (K⁻¹ and CameraInfo's D undone),

    X_i = R W_i + t,   π(X) = (X_x / X_z, X_y / X_z),   e_i = f (π(X_i) − m_i)   (pixels),
    (R, t) = argmin Σ_i v_i ρ(‖e_i‖)

over the landmarks inside the image, v_i their visibility, ρ Huber's loss (quadratic up to
:data:`ROBUST_PX`, linear beyond) and f the mean focal length. It is solved by iteratively
reweighted Gauss-Newton with a left-multiplied rotation update, started from the weak-perspective
fit (an affine camera m_i ≈ A W_i + b, A = [r1; r2] / t_z) and from its depth-mirrored twin, the
better of the two kept. Every landmark, in the image or not, is then placed: X_i = R W_i + t. A
person is not lifted (a reason is returned) when fewer than :data:`MIN_LANDMARKS` landmarks are in
the image, when no hip or no shoulder is, or when the fit fails (not converged, behind the camera,
residuals over :data:`MAX_RESIDUAL_REL` of the person's size in the image).

The depth of the result is the pose model's size prior: W_i's size. Pure numpy.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hac_ros.core.basics.errors import InputError

PLUMB_BOB, RATIONAL_POLYNOMIAL = 'plumb_bob', 'rational_polynomial'
DISTORTION_MODELS = (PLUMB_BOB, RATIONAL_POLYNOMIAL, '')  # '': none
UNDISTORT_ITERATIONS = 20  # fixed-point iterations of the inverse distortion (OpenCV uses 5)
UNDISTORT_TOL = 1e-12  # normalised units: stop when no point moves more

ROBUST_PX = 3.0  # Huber's threshold, pixels: a landmark further off counts linearly
MIN_VISIBILITY = 0.05  # a landmark whose visibility is below this is left out of the fit
MIN_LANDMARKS = 8  # landmarks in the image needed for a fit
MAX_ITERATIONS = 50
COST_TOL = 1e-6  # a step that lowers the robust cost by less than this share has converged (the
# landmarks then move < 1 mm: measured on the opencv-doc people against 1e-9)
START_ITERATIONS = 3  # steps from each start before the better one is kept
STEP_TOL = 1e-7  # radians / metres: a smaller Gauss-Newton step has converged
MAX_RESIDUAL_REL = 0.08  # a fit whose median residual is above this share of the person's size
MIN_DEPTH_M = 0.1  # the person's root must be in front of the camera by this much

@dataclass(frozen=True)
class Camera:
    """A pinhole camera with lens distortion (CameraInfo): ``K`` (3, 3) pixels, ``D`` the
    distortion coefficients of ``distortion_model`` (plumb_bob: k1, k2, p1, p2[, k3];
    rational_polynomial: k1, k2, p1, p2, k3, k4, k5, k6; empty: none), image ``width`` and
    ``height`` in pixels."""

    K: np.ndarray
    width: int
    height: int
    D: np.ndarray = field(default_factory=lambda: np.zeros(0))
    distortion_model: str = PLUMB_BOB

    def __post_init__(self) -> None:
        K = np.asarray(self.K, dtype=float)
        if K.shape != (3, 3) or not np.isfinite(K).all() or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise InputError(f'K: a finite (3, 3) camera matrix with fx, fy > 0, pixels; got '
                             f'{K.tolist()}')
        if self.width <= 0 or self.height <= 0:
            raise InputError(f'width, height: the image size in pixels, > 0; got {self.width} x '
                             f'{self.height}')
        D = np.asarray(self.D, dtype=float).ravel()
        if self.distortion_model not in DISTORTION_MODELS:
            raise InputError(f'distortion_model: {", ".join(m for m in DISTORTION_MODELS if m)} '
                             f'or none, not {self.distortion_model!r}')
        if not np.isfinite(D).all() or len(D) > (8 if self.distortion_model ==
                                                  RATIONAL_POLYNOMIAL else 5):
            raise InputError(f'D: distortion coefficients of {self.distortion_model} (finite); '
                             f'got {D.tolist()}')
        object.__setattr__(self, 'K', K)
        object.__setattr__(self, 'D', np.pad(D, (0, 8 - len(D))))

    @property
    def focal_px(self) -> float:
        """The mean focal length, pixels (residuals are measured in it)."""
        return 0.5 * float(self.K[0, 0] + self.K[1, 1])


def _radial_tangential(xy: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The radial factor (N,) and the tangential shift (N, 2) of normalised points (N, 2)."""
    k1, k2, p1, p2, k3, k4, k5, k6 = D
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    shift = np.stack([2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                      p1 * (r2 + 2 * y * y) + 2 * p2 * x * y], axis=1)
    return radial, shift


def distort(normalised: np.ndarray, camera: Camera) -> np.ndarray:
    """Undistorted normalised points (N, 2) (x/z, y/z, camera optical frame) -> distorted pixels
    (N, 2): the camera's projection (OpenCV's and ROS's plumb_bob / rational_polynomial)."""
    xy = np.asarray(normalised, dtype=float).reshape(-1, 2)
    radial, shift = _radial_tangential(xy, camera.D)
    d = xy * radial[:, None] + shift
    return d @ camera.K[:2, :2].T + camera.K[:2, 2]


def undistort(pixels: np.ndarray, camera: Camera) -> np.ndarray:
    """Pixels (N, 2) -> undistorted normalised points (N, 2) (x/z, y/z, camera optical frame): K
    undone, then the distortion by fixed-point iteration (OpenCV's ``undistortPoints`` scheme,
    iterated to :data:`UNDISTORT_TOL`)."""
    px = np.asarray(pixels, dtype=float).reshape(-1, 2)
    d = np.linalg.solve(camera.K[:2, :2], (px - camera.K[:2, 2]).T).T
    if not camera.D.any():
        return d
    xy = d.copy()
    for _ in range(UNDISTORT_ITERATIONS):
        radial, shift = _radial_tangential(xy, camera.D)
        new = (d - shift) / radial[:, None]
        moved = float(np.abs(new - xy).max(initial=0.0))
        xy = new
        if moved < UNDISTORT_TOL:
            break
    return xy


@dataclass(frozen=True)
class Lifted:
    """One person lifted: ``joints_cam`` (K, 3) metres, camera optical frame (every landmark,
    in the image or not); ``R`` (3, 3) and ``t`` (3,) metres, the model's frame to the camera's;
    ``residual_px`` the median reprojection error of the landmarks used; ``used`` how many."""

    joints_cam: np.ndarray
    R: np.ndarray
    t: np.ndarray
    residual_px: float
    used: int


def _rotation(omega: np.ndarray) -> np.ndarray:
    """exp([ω]×) (Rodrigues), ω (3,) radians."""
    angle = float(np.linalg.norm(omega))
    if angle < 1e-12:
        return np.eye(3)
    x, y, z = omega / angle
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def _weak_perspective(W: np.ndarray, m: np.ndarray, v: np.ndarray
                      ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Starting poses from the affine camera m ≈ A W + b fitted by weighted least squares: the
    nearest scaled rotation rows give R's first two rows and the depth t_z = 1 / scale; the
    depth-mirrored twin (the same image under a flip of the body in depth) is the second start."""
    sw = np.sqrt(v)[:, None]
    design = np.c_[W, np.ones(len(W))] * sw
    coef, *_ = np.linalg.lstsq(design, m * sw, rcond=None)  # (4, 2)
    A, b = coef[:3].T, coef[3]
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    scale = float(s.mean())
    if scale <= 0:
        return []
    rows = U @ Vt  # (2, 3) orthonormal rows
    starts = []
    for flip in (np.array([1.0, 1.0, 1.0]), np.array([1.0, 1.0, -1.0])):
        r1, r2 = rows[0] * flip, rows[1] * flip
        R = np.stack([r1, r2, np.cross(r1, r2)])
        t_z = 1.0 / scale
        starts.append((R, np.r_[b * t_z, t_z]))
    return starts


def _refine(W: np.ndarray, m: np.ndarray, v: np.ndarray, focal: float, R: np.ndarray,
            t: np.ndarray, iterations: int = MAX_ITERATIONS
            ) -> tuple[np.ndarray, np.ndarray, float, bool]:
    """Iteratively reweighted Gauss-Newton (Levenberg-Marquardt damped) on the pixel residuals,
    at most ``iterations`` steps: (R, t, the robust cost, converged)."""
    damping = 1e-6

    def cost_of(R: np.ndarray, t: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        X = W @ R.T + t
        if (X[:, 2] <= 1e-6).any():
            return np.inf, X, np.zeros_like(m)
        e = focal * (X[:, :2] / X[:, 2:3] - m)
        norm = np.linalg.norm(e, axis=1)
        huber = np.where(norm <= ROBUST_PX, 0.5 * norm ** 2, ROBUST_PX * (norm - 0.5 * ROBUST_PX))
        return float((v * huber).sum()), X, e

    cost, X, e = cost_of(R, t)
    if not np.isfinite(cost):
        return R, t, cost, False
    for _ in range(iterations):
        norm = np.linalg.norm(e, axis=1)
        w = v * np.minimum(1.0, ROBUST_PX / np.maximum(norm, 1e-12))  # IRLS weights of Huber
        # e = f (π(X) − m): d e / d X rows (f / z, 0, −f x / z²) and (0, f / z, −f y / z²);
        # d X / d t = I, d X / d ω = −[p]× with p = R W (a left rotation increment ω), so a row
        # a of d e / d X gives a (−[p]×) = (p × a)ᵀ, written out (np.cross costs a third of
        # the fit at this size: bench/people_speed.py's overhead ratio)
        x, y, z = X[:, 0], X[:, 1], X[:, 2]
        px, py, pz = (X - t).T
        fz, gx, gy = focal / z, -focal * x / (z * z), -focal * y / (z * z)
        zero = np.zeros_like(z)
        J = np.stack([np.stack([py * gx, pz * fz - px * gx, -py * fz, fz, zero, gx], axis=1),
                      np.stack([py * gy - pz * fz, -px * gy, px * fz, zero, fz, gy], axis=1)],
                     axis=1)  # (N, 2, 6): d e / d (ω, t)
        H = np.einsum('n,nij,nik->jk', w, J, J)
        g = np.einsum('n,nij,ni->j', w, J, e)
        while True:
            step = -np.linalg.solve(H + damping * np.diag(np.diag(H) + 1e-12), g)
            if float(np.abs(step).max()) < STEP_TOL:
                return R, t, cost, True  # converged
            R_new, t_new = _rotation(step[:3]) @ R, t + step[3:]
            new_cost, X_new, e_new = cost_of(R_new, t_new)
            if new_cost <= cost:
                damping = max(damping / 10, 1e-9)
                if cost - new_cost <= COST_TOL * cost:
                    return R_new, t_new, new_cost, True  # converged: the cost no longer moves
                break
            damping *= 10
            if damping > 1e6:
                return R, t, cost, True  # no step lowers the cost: a minimum
        R, t, cost, X, e = R_new, t_new, new_cost, X_new, e_new
    return R, t, cost, False


def lift_person(pixels: np.ndarray, visibility: np.ndarray, world: np.ndarray, camera: Camera,
                hips: tuple[int, ...], shoulders: tuple[int, ...]) -> Lifted | str:
    """One person's landmarks placed in the camera frame, or the reason (a key of
    :data:`hac_ros.people.reasons.PEOPLE_DROPPED`) why not.

    pixels: (K, 2) image landmarks, pixels of the distorted image (x right, y down); visibility:
    (K,) in [0, 1]; world: (K, 3) the same landmarks in metres in the model's frame; camera: the
    image's camera; hips, shoulders: the landmark indices of each (one of each must be in the
    image). Landmarks outside the image or below :data:`MIN_VISIBILITY` are left out of the fit.
    """
    px = np.asarray(pixels, dtype=float)
    vis = np.asarray(visibility, dtype=float)
    W = np.asarray(world, dtype=float)
    inside = (np.isfinite(px).all(1) & np.isfinite(W).all(1) & (vis >= MIN_VISIBILITY)
              & (px[:, 0] >= 0) & (px[:, 0] <= camera.width)
              & (px[:, 1] >= 0) & (px[:, 1] <= camera.height))
    if int(inside.sum()) < MIN_LANDMARKS:
        return 'too_few_landmarks'
    if not inside[list(hips)].any() or not inside[list(shoulders)].any():
        return 'no_hips_shoulders'
    m = undistort(px[inside], camera)
    v = np.clip(vis[inside], MIN_VISIBILITY, 1.0)
    # a few steps from each start tell the right one (the mirrored start of a correct one
    # wanders for many steps); then the better goes on to convergence
    trials = [_refine(W[inside], m, v, camera.focal_px, R0, t0, START_ITERATIONS)
              for R0, t0 in _weak_perspective(W[inside], m, v)]
    trials = [trial for trial in trials if np.isfinite(trial[2])]
    if not trials:
        return 'fit_failed'
    R, t, _, converged = min(trials, key=lambda trial: trial[2])
    if not converged:
        R, t, _, converged = _refine(W[inside], m, v, camera.focal_px, R, t)
    if not converged:
        return 'fit_failed'
    X = W @ R.T + t
    residual = camera.focal_px * np.linalg.norm(X[inside, :2] / X[inside, 2:3] - m, axis=1)
    size = float(np.ptp(px[inside], axis=0).max())
    if (float(np.median(residual)) > MAX_RESIDUAL_REL * size
            or float(X[list(hips)].mean(axis=0)[2]) < MIN_DEPTH_M):
        return 'fit_failed'
    return Lifted(joints_cam=X, R=R, t=t, residual_px=float(np.median(residual)),
                  used=int(inside.sum()))
