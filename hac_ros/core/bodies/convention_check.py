"""Geometric checks that catch an input convention the parameters do not describe (the
parameters ``pose_to_optical``, ``joint_layout``; docs/inputs.md).

A wrong convention does not make inputs invalid, it makes the scale confidently wrong: SLAM poses
of an x-forward, z-up body frame read as optical poses calibrate 60–85 % off on every simulated
scene. Each check gathers evidence over many frames and, when it is conclusive, gives one warning
naming the likely parameter; the warning stays in /diagnostics (:attr:`ConventionCheck.suspects`).

- **The map is not in front of the camera.** A SLAM map holds what the camera saw, so a share of
  its points lies in the current view (measured on the simulated scenes: 8–99 % at the 10th
  percentile of poses). Read with the wrong rotation, the "view" points at the ceiling or the
  sky: 0 % on every scene. Checked once per second of stamp time on a sample of the map.
- **The skeleton is not the layout's.** Read in another order (an H36M-17 model read as COCO-17,
  both 17 joints), the layout's legs are other joints: left and right differ by 70 % (COCO-17
  read as H36M-17: the "legs" run through the face), or they are 1.03-1.13 m long and the body
  axis points down (H36M-17 read as COCO-17), where a correct layout's legs measure 0.74-0.86 m
  and differ by under 12 % (10th-90th percentiles on every simulated scene). A body axis
  pointing down alone is not enough: people walk on their hands (the handstand scene). A layout
  without legs (custom) is judged by the body axis alone.
- **The joints fall outside the image** (with CameraInfo): HMR joints that are not in the camera
  optical frame (x right, y down, z forward).
- **The bodies line up only with the poses inverted.** People stand upright in the world, so their
  body axes (ankles to the top of the layout's axis), carried into the map by the camera's
  rotation, keep one direction however the camera turns. A SLAM pose given the other way round
  (the world in the camera, T_cw, read as the camera in the map) carries them with the transposed
  rotation, and as the camera turns they scatter. The spread of the axes (sign-agnostic: 1 minus
  the largest eigenvalue of their mean orientation tensor) under the rotation as given and under
  its transpose (one frame's people per AXES_PERIOD_NS), measured on the bench's scenes (every
  simulated scenario and real-data composite, 30 Hz and keyframes, 3 seeds: 102 runs): the given
  one is at most 1.12 times the transposed one (about 1 where the camera hardly turns, at most
  0.53 on the composites' real trajectories), none judged inverted; with the poses inverted on
  purpose, 1.9-5.2 times on the turning `ego` scene and 1.9-9.1 times on the composites (all
  judged inverted once they hold AXES_PEOPLE_MIN people: 32 of 54 runs; the others are keyframe
  runs of fewer), but 1.04-1.40 on `walk` and `crowd`, whose camera hardly turns (those runs
  never said OK either). A camera that never turns cannot tell. Poses of
  another frame (x forward, z up) scatter the axes too: this check waits for the map check to
  have passed, so that they are named by theirs (``pose_to_optical``).
"""
from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from hac_ros.core.basics.numeric import NS, median_of
from hac_ros.core.basics.outputs import NoticeOut
from hac_ros.core.bodies.contact import in_view, leg_lengths
from hac_ros.core.geometry.reference import MapIndex
from hac_ros.core.layouts import JointLayout

MAP_SAMPLE_POINTS = 1000  # map points checked against the view
MAP_CHECKS = 10  # checks (one per second) before judging; the median of the last ones decides
MAP_IN_VIEW_MIN = 0.01  # share of map points in view below which the pose convention is suspect
PEOPLE_MIN = 100  # people before judging the body axis and the joints in the image
INVERTED_MAX = 0.8  # share of people standing on their head above which the layout is suspect
LEG_ASYMMETRY_MAX = 0.25  # median |left - right| / longer leg above which the layout is suspect
LEG_LONG_M = 0.92  # legs longer than this (median) with the body axis down: suspect
LEG_RANGE_M = (0.35, 1.2)  # a median leg length outside: suspect whatever the axis
LEG_HISTORY = 1000  # people kept for the leg medians (memory stays flat)
# share of joints in the image below which the joints' frame is suspect: none in a frame turned
# into a body frame (x forward, z up), 26-38 % on the composites of real walks whose walker is
# partly out of view (bench/composite.py)
JOINTS_IN_IMAGE_MIN = 0.1
VIEW_COS = math.cos(math.radians(45.0))  # without intrinsics: in view = within 45° of the axis
# the bodies' axes spread more than this many times as much under the given rotation as under its
# transpose, and by more than the gap, once AXES_PEOPLE_MIN people were seen: the pose is suspect
POSE_INVERTED_RATIO = 1.5
AXES_PEOPLE_MIN = 30  # people before the axes are judged (their spread is steady from ~20)
AXES_PERIOD_NS = 250_000_000  # the people of one frame per this much stamp time are taken
POSE_INVERTED_MIN_GAP = 0.001  # of the spread (1 - the largest eigenvalue; walkers lean: ~0.002)

TEXTS = {
    'pose_convention': ('the map is almost never in front of the camera (median {value:.1%} of '
                        'its points in view): the SLAM pose is probably not the camera optical '
                        'frame (x right, y down, z forward); set pose_to_optical (e.g. '
                        '[-0.5, 0.5, -0.5, 0.5] for an x-forward, z-up camera frame)'),
    'joint_layout': ('the joints do not form the skeleton of joint_layout ({value}): they are '
                     'probably in another order; check joint_layout'),
    'pose_inverted': ('the people\'s body axes scatter in the map as the camera turns and line up '
                      'when each SLAM pose is inverted (spread {value[0]:.4f} as given, '
                      '{value[1]:.4f} inverted): the SLAM pose is probably the world in the camera '
                      '(T_cw), not the camera in the map; publish its inverse'),
    'joints_frame': ('only {value:.0%} of HMR joints project into the image: the joints are '
                     'probably not in the camera optical frame (x right, y down, z forward, '
                     'metres)'),
}


class ConventionCheck:
    """Evidence about the input conventions and the warnings it gives (each once)."""

    def __init__(self) -> None:
        self._map_views: deque[float] = deque(maxlen=MAP_CHECKS)
        self._next_map_check_ns: int | None = None
        self._people = self._inverted = 0
        self._joints = self._joints_in_image = 0
        # the last LEG_HISTORY people's (mean leg m, left/right asymmetry), a ring: judged every
        # frame, so no list-to-array conversion on the way
        self._legs = np.empty((LEG_HISTORY, 2))
        self._legs_seen = 0
        # the bodies' unit axes' orientation tensors in the map (sums of u uᵀ): [0] carried by the
        # rotation as given, [1] by its transpose; and how many people they hold
        self._axes = np.zeros((2, 3, 3))
        self._axes_people = 0
        self._axes_frame_ns = self._next_axes_check_ns = -1  # the last frame taken, the check
        self.suspects: dict[str, str] = {}  # check -> warning text, for /diagnostics

    # ------------------------------------------------------------------ evidence
    def view_map(self, stamp_ns: int, map_index: MapIndex | None, R_wc: np.ndarray,
                 c_map: np.ndarray, K: np.ndarray | None, image_size: tuple[int, int]) -> None:
        """Once per second of stamp time: the share of the map's points (a sample, SLAM units)
        in the view of the camera R_wc (3, 3) camera-to-map, c_map (3,) SLAM units: in the image
        with intrinsics K (3, 3) pixels, else within 45° of the optical axis."""
        if map_index is None or not map_index.size or (
                self._next_map_check_ns is not None and stamp_ns < self._next_map_check_ns):
            return
        self._next_map_check_ns = stamp_ns + NS
        points_map = map_index.sample
        if len(points_map) > MAP_SAMPLE_POINTS:
            points_map = points_map[:: len(points_map) // MAP_SAMPLE_POINTS]
        cam = (points_map - c_map) @ R_wc  # camera optical frame
        z = cam[:, 2]
        front = z > 0.0
        if K is None:
            inside = front & (z > VIEW_COS * np.linalg.norm(cam, axis=1))
        else:
            zs = np.where(front, z, 1.0)
            u = (K[0, 0] * cam[:, 0] + K[0, 1] * cam[:, 1]) / zs + K[0, 2]
            v = K[1, 1] * cam[:, 1] / zs + K[1, 2]
            width, height = image_size
            inside = front & (u >= 0) & (u < width) & (v >= 0) & (v < height)
        self._map_views.append(float(inside.mean()) if len(inside) else 0.0)

    def add_person(self, stamp_ns: int, layout: JointLayout, R_wc: np.ndarray,
                   joints_cam: np.ndarray, up_cam: np.ndarray, down_map: np.ndarray | None,
                   K: np.ndarray | None, image_size: tuple[int, int]) -> None:
        """One person: joints_cam (K, 3) metres, camera optical frame, in ``layout``'s order;
        up_cam (3,) its body's up axis in the camera; R_wc (3, 3) camera-to-map; down_map (3,)
        the scene's down, unit, map frame (None while unknown: nobody is judged upside down); the
        intrinsics (None: the joints in the image are not judged)."""
        self._people += 1
        up_map = R_wc @ up_cam
        if down_map is not None and float(up_map @ down_map) > 0.5 * float(np.linalg.norm(up_map)):
            self._inverted += 1  # the body's up axis along the scene's down
        if K is not None:  # the joints seen (NaN: not seen, not judged)
            in_image = in_view(joints_cam[np.isfinite(joints_cam).all(axis=1)], K, *image_size)
            self._joints += len(in_image)
            self._joints_in_image += sum(in_image)
        if self._axes_taken(stamp_ns):
            self._add_axis(layout, R_wc, joints_cam, up_cam)
        legs = leg_lengths(layout, joints_cam)
        if len(legs) == 2 and all(math.isfinite(leg) for leg in legs) and max(legs) > 0.0:
            self._legs[self._legs_seen % LEG_HISTORY] = (0.5 * (legs[0] + legs[1]),
                                                        abs(legs[0] - legs[1]) / max(legs))
            self._legs_seen += 1

    def _axes_taken(self, stamp_ns: int) -> bool:
        """Whether the people of the frame at ``stamp_ns`` add their axes: one frame per
        AXES_PERIOD_NS of stamp time (the evidence needs the camera to turn, not many frames)."""
        if stamp_ns != self._axes_frame_ns:
            if self._axes_frame_ns < stamp_ns < self._axes_frame_ns + AXES_PERIOD_NS:
                return False  # (a stamp before the last frame taken: time went back, taken)
            self._axes_frame_ns = stamp_ns
        return True

    def _add_axis(self, layout: JointLayout, R_wc: np.ndarray, joints_cam: np.ndarray,
                  up_cam: np.ndarray) -> None:
        """One body's long axis, ankles to the top of the layout's axis (steadier than the
        torso's in a stride; the layout's axis without legs), into both orientation tensors."""
        ankles = [leg[2] for leg in layout.legs]
        axis = (joints_cam[list(layout.axis_upper)].mean(axis=0) - joints_cam[ankles].mean(axis=0)
                if ankles else up_cam)
        norm = float(np.linalg.norm(axis))
        if norm > 0.0 and math.isfinite(norm):
            given, transposed = R_wc @ axis / norm, R_wc.T @ axis / norm
            self._axes[0] += np.outer(given, given)
            self._axes[1] += np.outer(transposed, transposed)
            self._axes_people += 1

    def new_map_frame(self) -> None:
        """The SLAM re-initialised in a new frame: the axes seen in the old one are forgotten."""
        self._axes[:] = 0.0
        self._axes_people = 0

    def _pose_evidence(self) -> tuple[float, float] | None:
        """(spread as given, spread transposed) when the bodies' axes say the SLAM pose is
        inverted (module docstring), else None."""
        if self._axes_people < AXES_PEOPLE_MIN:
            return None
        given, transposed = (1.0 - float(np.linalg.eigvalsh(t / self._axes_people)[-1])
                             for t in self._axes)
        if given > POSE_INVERTED_RATIO * transposed and given - transposed > POSE_INVERTED_MIN_GAP:
            return given, transposed
        return None

    def _layout_evidence(self) -> str | None:
        """Why the joints are probably not in the layout's order, or None."""
        inverted = self._inverted / self._people
        if not self._legs_seen:  # a layout without legs: the body axis alone
            return f'{inverted:.0%} of people upside down' if inverted > INVERTED_MAX else None
        table = self._legs[:min(self._legs_seen, LEG_HISTORY)]
        leg, asymmetry = median_of(table[:, 0]), median_of(table[:, 1])
        if asymmetry > LEG_ASYMMETRY_MAX:
            return f'left and right legs differ by {asymmetry:.0%}'
        if not LEG_RANGE_M[0] <= leg <= LEG_RANGE_M[1] or (inverted > INVERTED_MAX
                                                             and leg > LEG_LONG_M):
            return f'legs {leg:.2f} m long, {inverted:.0%} of people upside down'
        return None

    # ------------------------------------------------------------------ judgement
    def notices(self, stamp_ns: int) -> list[NoticeOut]:
        """A warning for each check that has become conclusive (once per check)."""
        found: dict[str, Any] = {}
        if len(self._map_views) == MAP_CHECKS:
            share = median_of(self._map_views)  # of the map's points in view
            if share < MAP_IN_VIEW_MIN:
                found['pose_convention'] = share
        map_seen = (len(self._map_views) == MAP_CHECKS and 'pose_convention' not in found
                    and 'pose_convention' not in self.suspects)
        if (map_seen and 'pose_inverted' not in self.suspects
                and stamp_ns >= self._next_axes_check_ns):
            self._next_axes_check_ns = stamp_ns + NS  # judged once per second of stamp time
            inverted = self._pose_evidence()
            if inverted is not None:
                found['pose_inverted'] = inverted
        if self._people >= PEOPLE_MIN:
            evidence = self._layout_evidence()
            if evidence is not None:
                found['joint_layout'] = evidence
            if self._joints and self._joints_in_image / self._joints < JOINTS_IN_IMAGE_MIN:
                found['joints_frame'] = self._joints_in_image / self._joints
        out = []
        for key, value in found.items():
            if key not in self.suspects:
                self.suspects[key] = TEXTS[key].format(value=value)
                out.append(NoticeOut(stamp_ns, f'convention_{key}', self.suspects[key], 'warn'))
        return out
