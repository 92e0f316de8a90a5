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
"""
from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from hac_ros.core.contact import in_view, leg_lengths
from hac_ros.core.layouts import JointLayout
from hac_ros.core.numeric import NS
from hac_ros.core.outputs import NoticeOut
from hac_ros.core.reference import MapIndex

MAP_SAMPLE_POINTS = 1000  # map points checked against the view
MAP_CHECKS = 10  # checks (one per second) before judging; the median of the last ones decides
MAP_IN_VIEW_MIN = 0.01  # share of map points in view below which the pose convention is suspect
PEOPLE_MIN = 100  # people before judging the body axis and the joints in the image
INVERTED_MAX = 0.8  # share of people standing on their head above which the layout is suspect
LEG_ASYMMETRY_MAX = 0.25  # median |left - right| / longer leg above which the layout is suspect
LEG_LONG_M = 0.92  # legs longer than this (median) with the body axis down: suspect
LEG_RANGE_M = (0.35, 1.2)  # a median leg length outside: suspect whatever the axis
LEG_HISTORY = 1000  # people kept for the leg medians (memory stays flat)
JOINTS_IN_IMAGE_MIN = 0.3  # share of joints in the image below which the joints' frame is suspect
VIEW_COS = math.cos(math.radians(45.0))  # without intrinsics: in view = within 45° of the axis

TEXTS = {
    'pose_convention': ('the map is almost never in front of the camera (median {value:.1%} of '
                        'its points in view): the SLAM pose is probably not the camera optical '
                        'frame (x right, y down, z forward); set pose_to_optical (e.g. '
                        '[-0.5, 0.5, -0.5, 0.5] for an x-forward, z-up camera frame)'),
    'joint_layout': ('the joints do not form the skeleton of joint_layout ({value}): they are '
                     'probably in another order; check joint_layout'),
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

    def add_person(self, layout: JointLayout, R_wc: np.ndarray, joints_cam: np.ndarray,
                   up_cam: np.ndarray, down_map: np.ndarray | None, K: np.ndarray | None,
                   image_size: tuple[int, int]) -> None:
        """One person: joints_cam (K, 3) metres, camera optical frame, in ``layout``'s order;
        up_cam (3,) its body's up axis in the camera; R_wc (3, 3) camera-to-map; down_map (3,)
        the scene's down, unit, map frame (None while unknown: nobody is judged upside down); the
        intrinsics (None: the joints in the image are not judged)."""
        self._people += 1
        up_map = R_wc @ up_cam
        if down_map is not None and float(up_map @ down_map) > 0.5 * float(np.linalg.norm(up_map)):
            self._inverted += 1  # the body's up axis along the scene's down
        if K is not None:
            in_image = in_view(joints_cam, K, *image_size)
            self._joints += len(in_image)
            self._joints_in_image += sum(in_image)
        legs = leg_lengths(layout, joints_cam)
        if len(legs) == 2 and max(legs) > 0.0:
            self._legs[self._legs_seen % LEG_HISTORY] = (0.5 * (legs[0] + legs[1]),
                                                        abs(legs[0] - legs[1]) / max(legs))
            self._legs_seen += 1

    def _layout_evidence(self) -> str | None:
        """Why the joints are probably not in the layout's order, or None."""
        inverted = self._inverted / self._people
        if not self._legs_seen:  # a layout without legs: the body axis alone
            return f'{inverted:.0%} of people upside down' if inverted > INVERTED_MAX else None
        table = self._legs[:min(self._legs_seen, LEG_HISTORY)]
        leg, asymmetry = float(np.median(table[:, 0])), float(np.median(table[:, 1]))
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
            share = float(np.median(self._map_views))  # of the map's points in view
            if share < MAP_IN_VIEW_MIN:
                found['pose_convention'] = share
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
