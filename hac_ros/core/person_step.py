"""One person's scale sample inside the frame loop (docs/method.md, steps 1-5): the person's
joints judged (seen, in metres, in front, the contact seen, standing:
hac_ros.core.bodies.person_checks), the votes for down and the convention checks they feed, the
sample against the map or the floor
(hac_ros.core.bodies.sample), the floor's re-lock, and the bookkeeping (counts, the estimator, the
ground model's contacts).

:class:`PersonStep` is a part of :class:`hac_ros.core.frame_loop.FrameLoop`, kept apart so that
what happens to one person reads in one place; the state it uses is the loop's (annotated below).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from hac_ros.core.basics.outputs import NoticeOut, SampleOut
from hac_ros.core.bodies.convention_check import ConventionCheck
from hac_ros.core.bodies.person_checks import BODY_CHECKS, JOINT_CHECKS, Person, refusal
from hac_ros.core.bodies.sample import Scene, person_sample
from hac_ros.core.estimate.estimator import RollingScale
from hac_ros.core.geometry.ground import GroundModel
from hac_ros.core.layouts import JointLayout
from hac_ros.core.rules.params import HacParams
from hac_ros.core.stream.map_book import MapBook
from hac_ros.core.stream.pending import Record
from hac_ros.core.stream.services import ServiceRequests

if TYPE_CHECKING:
    from hac_ros.core.geometry.reference import MapIndex

STATIC_TURN_DEG = 1.0  # a fixed camera's floor turned by more: the estimate restarts


class PersonStep:
    """Each person of a frame, as FrameLoop runs them (module docstring)."""

    # the loop's state this part reads and writes (set by FrameLoop)
    params: HacParams
    layout: JointLayout
    ground: GroundModel
    estimator: RollingScale
    check: ConventionCheck
    maps: MapBook
    services: ServiceRequests
    people: int
    map_hits: int
    ground_fallbacks: int
    _K: np.ndarray | None
    _image_size: tuple[int, int]
    _cos_min: float
    _static_normal: np.ndarray | None
    _sources: deque[bool]

    if TYPE_CHECKING:  # FrameLoop's
        @property
        def map(self) -> MapIndex | None: ...

        def online_scale(self) -> float | None: ...

        def _reject(self, reason: str, stamp_ns: int = -1, detail: str = '') -> list[Record]: ...

    def _person(self, stamp: int, person: int, R_wc: np.ndarray, c_map: np.ndarray,
                joints: np.ndarray, followed: int = -1) -> list[Record]:
        """One person's scale sample (docs/method.md, steps 1–5; hac_ros.core.bodies.sample) and its
        bookkeeping; ``followed``: who they are across frames (a fixed camera without a map:
        their contacts refine the floor's normal person by person), -1 unknown."""
        self.people += 1
        # NaN joints are not seen (docs/inputs.md); the checks in order
        # (hac_ros.core.bodies.person_checks)
        body = Person(self.layout, joints, self.params.contact_mode)
        refused = refusal(JOINT_CHECKS, body)
        if refused:
            return self._rejected_sample(stamp, person, *refused)
        up_cam = self.layout.up_axis(joints)
        notes = self._vote_down(stamp, R_wc, c_map, joints, up_cam)
        down = self.ground.rough_down()
        self.check.add_person(stamp, self.layout, R_wc, joints, up_cam, down, self._K,
                              self._image_size)
        body.up_cam, body.down_cam = up_cam, None if down is None else R_wc.T @ down
        refused = refusal(BODY_CHECKS, body)
        if refused:
            return notes + self._rejected_sample(stamp, person, *refused)
        self.ground.add_body(R_wc, up_cam)
        up_norm = float(np.linalg.norm(up_cam))
        if down is None and math.isfinite(up_norm) and up_norm > 0.0:
            down = -(R_wc @ up_cam) / up_norm  # until the scene says: the body's own down
        scale_now = self.online_scale()
        scene = Scene(self.map, self.ground.plane(self.map), down, self.ground.trusted, self._K,
                      self._image_size, scale_now, self._cos_min)
        sample = person_sample(self.params, self.layout, scene, R_wc, c_map, joints)
        relock: list[Record] = notes
        if self.ground.judge_window(sample.floor_scale, scale_now, self.estimator.samples,
                                    self.params.min_samples, self.params.plausibility_rel_tol):
            self.estimator.restart()  # it locked on what the floor now refuses: judged afresh
            relock.append(NoticeOut(stamp, 'floor_relock', 'the floor found in the map disagrees '
                                    'with the estimate (an occluder taken for the contact?): '
                                    'estimate restarted', 'warn'))
            scale_now = None
            scene = replace(scene, scale=None)
            sample = person_sample(self.params, self.layout, scene, R_wc, c_map, joints)
        if self.params.static_camera and self.map is None and sample.contact_cam is not None:
            self.ground.camera_map = c_map
            self.ground.add_sole(R_wc @ sample.contact_cam, followed)  # metres: its normal
            relock += self._floor_turned(stamp)
        if sample.reason:
            return relock + self._rejected_sample(stamp, person, sample.reason)
        if sample.source == 'map':
            self.map_hits += 1
        else:
            self.ground_fallbacks += 1
        if self.services.holding:  # counted, not used
            self.services.samples += 1
            return [*relock, SampleOut(stamp, person, sample.scale, sample.source, False)]
        accepted = self.estimator.add(stamp, sample.scale)
        out: list[Record] = [*relock, SampleOut(stamp, person, sample.scale, sample.source,
                                                accepted)]
        if not accepted:
            out += self._reject('gated', stamp)
        else:
            self._sources.append(sample.source == 'ground')
            if sample.source == 'map' and scale_now is not None:
                contact_map = c_map + R_wc @ sample.contact_cam / scale_now
                self.ground.add_contact(contact_map, scale_now)
        return out

    def _floor_turned(self, stamp: int) -> list[Record]:
        """A fixed camera without a map: its floor is one unit below it across the normal the
        people's contacts refine; when that normal turns by more than STATIC_TURN_DEG the samples
        taken against the old floor are another floor's, and the estimate restarts."""
        if not (self.params.static_camera and self.map is None):
            return []
        normal = self.ground.normal()
        before, self._static_normal = self._static_normal, normal
        if normal is None or before is None:
            return []
        turned = math.degrees(math.acos(max(-1.0, min(1.0, float(normal @ before)))))
        if turned <= STATIC_TURN_DEG:
            self._static_normal = before  # small turns add up until they count
            return []
        self.estimator.restart()
        return [NoticeOut(stamp, 'floor_refined', f'the floor the people walk on turned '
                          f'{turned:.1f} deg as their contacts came: estimate restarted', 'info')]

    def _vote_down(self, stamp: int, R_wc: np.ndarray, c_map: np.ndarray, joints: np.ndarray,
                   up_cam: np.ndarray) -> list[Record]:
        """Every person (standing or not) tells which way is down while the scene has not said
        (hac_ros.core.geometry.down_vote); when it says that down is along the bodies' up (people on
        their hands), the samples taken with the bodies' own down are dropped."""
        up_norm = float(np.linalg.norm(up_cam))
        if not (self.ground.down.wanted and self.map is not None and math.isfinite(up_norm)
                and up_norm > 0.0):
            return []
        self.ground.down.add(self.layout, joints, R_wc, c_map, self.map, R_wc @ up_cam / up_norm,
                             self.maps.shape)
        if not (self.ground.down.along_up and self.estimator.samples):
            return []
        self.estimator.restart()
        return [NoticeOut(stamp, 'down_found', 'down is along the bodies\' up axis (people on '
                          'their hands): the estimate restarted', 'info')]

    def _rejected_sample(self, stamp: int, person: int, reason: str, detail: str = ''
                         ) -> list[Record]:
        return [SampleOut(stamp, person, float('nan'), reason, False),
                *self._reject(reason, stamp, detail)]
