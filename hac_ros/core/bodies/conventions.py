"""Input conventions other than the defaults (docs/inputs.md): body-frame SLAM poses
(``pose_to_optical``: a rotation, or a full transform for a body or base frame) and an HMR model
that assumed another focal length (``hmr_focal_px``).

Both are applied where the inputs enter the :class:`~hac_ros.core.calibrator.Calibrator`, so
everything after sees optical-frame poses and depths at the camera's own focal length. Pure numpy.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from hac_ros.core.basics.outputs import NoticeOut, Output
from hac_ros.core.layouts import JointLayout


def optical_transform(pose_to_optical: list[float]
                      ) -> tuple[np.ndarray, np.ndarray] | None:
    """The camera optical frame in the SLAM pose's child frame: R (3, 3) optical to child and t
    (3,) the optical origin in the child frame, in the pose's own units (zero for the 4-number
    form, x y z w: the position unchanged; the 7-number form is x y z qx qy qz qw). None for the
    identity (the SLAM publishes optical-frame poses)."""
    values = np.asarray(pose_to_optical, dtype=float)
    q = values[-4:] / np.linalg.norm(values[-4:])
    t = values[:3] if len(values) == 7 else np.zeros(3)
    if abs(abs(q[3]) - 1.0) < 1e-12 and not t.any():
        return None
    return Rotation.from_quat(q).as_matrix(), t


def to_optical(R_map_child: np.ndarray, c_map_child: np.ndarray,
               child_optical: tuple[np.ndarray, np.ndarray] | None
               ) -> tuple[np.ndarray, np.ndarray]:
    """The pose a wrapper reported for its child frame (pose_child = pose_camera · T⁻¹) back to the
    camera optical frame's, as it was before: R_map_optical = R_map_child · R (3, 3) and
    c_optical = c_child + R_map_child · t (3,), SLAM units."""
    if child_optical is None:
        return R_map_child, c_map_child
    R, t = child_optical
    return R_map_child @ R, c_map_child + R_map_child @ t


def refocus_depth(joints_cam: np.ndarray, fx: float, hmr_focal_px: float,
                  layout: JointLayout) -> np.ndarray:
    """Joints (P, K, 3) metres, camera optical frame, as an HMR model with focal length
    ``hmr_focal_px`` placed them, moved to the depth the camera's ``fx`` (pixels, CameraInfo's
    resolution) gives: each person at f/f_a times its root's depth, x and y unchanged, so every
    joint's z moves by z_root · (f/f_a − 1) (the root as the layout defines it)."""
    shift = layout.root_of(joints_cam)[:, 2:3] * (fx / hmr_focal_px - 1.0)  # (P, 1)
    out = joints_cam.copy()
    out[:, :, 2] += shift
    return out


NO_CAMERA_INFO = ('hmr_focal_px is set but no CameraInfo has arrived: HMR depths are used '
                  'uncorrected until it does')


def focal_note(fx: float, hmr_focal_px: float) -> str:
    """The start-up line saying that, and how, the HMR depths are corrected (hmr_focal_px set)."""
    return (f'HMR depth corrected from the focal length it assumed, {hmr_focal_px:.1f} px '
            f'(hmr_focal_px), to the camera\'s fx = {fx:.1f} px')


class Conventions:
    """The calibrator's door for poses and joints: ``pose_to_optical`` and ``hmr_focal_px``
    applied, with the notices they call for."""

    def __init__(self, pose_to_optical: list[float], hmr_focal_px: float,
                 layout: JointLayout) -> None:
        self.child_optical = optical_transform(pose_to_optical)
        self.layout = layout
        self.hmr_focal_px = float(hmr_focal_px)
        self._warned = False

    @property
    def optical_poses(self) -> bool:
        """The SLAM poses are the optical frame's (their child frame names the camera)."""
        return self.child_optical is None

    def pose(self, R_map_child: np.ndarray, c_map_child: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
        """The SLAM pose (R (3, 3) child to map, c (3,) SLAM units) -> the optical frame's."""
        return to_optical(R_map_child, c_map_child, self.child_optical)

    def camera_info_notes(self, stamp_ns: int, K: np.ndarray) -> list[Output]:
        """The first CameraInfo: with hmr_focal_px set, one line saying the correction it makes.
        Nothing with hmr_focal_px 0: the depths are used as they come, and a line on every correct
        run would say nothing a user must act on (docs/inputs.md says how a wrong focal shows)."""
        if not self.hmr_focal_px:
            return []
        return [NoticeOut(stamp_ns, 'hmr_focal', focal_note(float(K[0, 0]), self.hmr_focal_px),
                          'info')]

    def joints(self, stamp_ns: int, joints_cam: np.ndarray, K: np.ndarray | None
               ) -> tuple[np.ndarray, list[Output]]:
        """(P, J, 3) metres, optical frame -> at the camera's focal length (with a warning, once,
        while hmr_focal_px is set and no CameraInfo has come)."""
        if not self.hmr_focal_px:
            return joints_cam, []
        if K is not None:
            return refocus_depth(joints_cam, float(K[0, 0]), self.hmr_focal_px, self.layout), []
        if self._warned:
            return joints_cam, []
        self._warned = True
        return joints_cam, [NoticeOut(stamp_ns, 'hmr_focal_no_camera_info', NO_CAMERA_INFO, 'warn')]
