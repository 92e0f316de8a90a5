"""hac_people_node's log tells the story of a run at INFO, one line each (docs/people.md, "The
log"), as hac_node's does (:mod:`hac_ros.ros.story`):

- the CameraInfo taken, when it is the first or differs from the one before: size, focal lengths,
  principal point, distortion, and whether K (+ D) or P (rectified) is used;
- the first image: its size, encoding and stamp;
- the first person found: how many in that image and how far;
- every ``log_period_s`` (wall clock; 0 = off) a status line: images received = processed +
  dropped (rate cap, overload, lost) + rejected + waiting, people published and dropped;
- images stopping (none for ``stale_after_s`` wall seconds after some came), at WARN, and their
  coming back.

Every string that came from outside (topic names, encodings) is escaped
(:func:`hac_ros.core.basics.printable.printable`). Calls come from the executor's thread
(:meth:`image`, :meth:`tick`, :meth:`camera_info`) and from the processing thread (:meth:`people`);
each line is
written whole.
"""
from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.printable import printable
from hac_ros.people.lifting import Camera


def describe_camera(camera: Camera, rectified: bool) -> str:
    """One line of a camera: size, K's focal lengths and principal point, distortion."""
    K = camera.K
    distortion = ('none (rectified: P)' if rectified else
                  f'{camera.distortion_model or "none"} {np.round(camera.D, 4).tolist()}'
                  if camera.D.any() else 'none')
    return (f'{camera.width} x {camera.height}, fx {K[0, 0]:.1f} fy {K[1, 1]:.1f} cx '
            f'{K[0, 2]:.1f} cy {K[1, 2]:.1f}, distortion {distortion}')


class PeopleStory:
    """What hac_people_node's log says (module docstring). ``logger``: the node's rclpy logger;
    ``image_topic``, ``camera_info_topic``: the resolved topics."""

    def __init__(self, logger: Any, image_topic: str, camera_info_topic: str) -> None:
        self.log = logger
        self.image_topic = printable(image_topic)
        self.camera_info_topic = printable(camera_info_topic)
        self._camera: str | None = None
        self._first_image = False
        self._first_person = False
        self._last_image_s: float | None = None  # time.monotonic of the last image
        self._stopped = False
        self._line_due_s = float('nan')

    def camera_info(self, camera: Camera, rectified: bool) -> None:
        """A valid CameraInfo was taken: told when it is the first or differs."""
        text = describe_camera(camera, rectified)
        if text != self._camera:
            self.log.info(f'{"camera" if self._camera is None else "camera changed"}: '
                          f'{self.camera_info_topic}: {text}')
            self._camera = text

    def image(self, width: int, height: int, encoding: str, stamp_ns: int) -> None:
        """An image arrived now (its size and encoding as far as known before decoding)."""
        self._last_image_s = time.monotonic()
        if self._stopped:
            self._stopped = False
            self.log.info(f'images on {self.image_topic} again (stamp {stamp_ns / NS:.3f} s)')
        if not self._first_image:
            self._first_image = True
            size = f'{width} x {height} ' if width and height else ''
            self.log.info(f'first image on {self.image_topic}: {size}{printable(encoding)}, '
                          f'stamp {stamp_ns / NS:.3f} s')

    def people(self, joints_cam: np.ndarray, stamp_ns: int) -> None:
        """An image's people went out: joints_cam (P, K, 3) metres, camera optical frame."""
        if self._first_person or not len(joints_cam):
            return
        self._first_person = True
        depths = ', '.join(f'{z:.1f}' for z in np.nanmedian(joints_cam[:, :, 2], axis=1))
        self.log.info(f'first person found: {len(joints_cam)} in the image of stamp '
                      f'{stamp_ns / NS:.3f} s, at {depths} m from the camera')

    def tick(self, counts: Mapping[str, int], waiting: int, log_period_s: float,
             stale_after_s: float) -> None:
        """Steady-clock timer: images stopping, the status line."""
        now = time.monotonic()
        if (self._last_image_s is not None and not self._stopped
                and now - self._last_image_s > stale_after_s):
            self._stopped = True
            self.log.warning(f'no image on {self.image_topic} for {stale_after_s:g} s: the '
                             'camera stopped? (hac_node gets no joints)')
        if log_period_s <= 0:
            self._line_due_s = float('nan')
            return
        if not now < self._line_due_s:
            if self._line_due_s == self._line_due_s:
                self.log.info(status_line(counts, waiting))
            self._line_due_s = now + log_period_s


def status_line(counts: Mapping[str, int], waiting: int) -> str:
    """images received = processed + dropped + rejected + waiting; people published, dropped."""
    dropped = {key.split('.', 1)[1]: n for key, n in counts.items() if key.startswith('dropped.')
               and key != 'dropped.lost'}  # lost ones were never received
    rejected = sum(n for key, n in counts.items() if key.startswith('rejected.'))
    people_dropped = sum(n for key, n in counts.items() if key.startswith('people_dropped.'))
    drops = ', '.join(f'{reason} {n}' for reason, n in sorted(dropped.items()))
    lost = counts.get('dropped.lost', 0)
    return (f'images received {counts.get("images_received", 0)} = processed '
            f'{counts.get("images_processed", 0)} + dropped {sum(dropped.values())}'
            + (f' ({drops})' if drops else '') + f' + rejected {rejected} + waiting {waiting}'
            + (f'; {lost} lost before the node saw them' if lost else '')
            + f'; people published {counts.get("people_published", 0)}, dropped '
            f'{people_dropped}')
