"""``hac_people_node``: a camera's images → each person's metric landmarks (``hmr/joints``,
``joint_layout: blazepose33``), on a CPU (docs/people.md).

It subscribes to ``camera/image_raw`` (``sensor_msgs/Image``) or, with ``image_transport:
compressed``, ``camera/image_raw/compressed`` (``CompressedImage``), and ``camera/camera_info``;
for each image it processes it publishes one ``PoseArray`` with the image's header (stamp, optical
frame): 33 positions per person in metres (:mod:`hac_ros.people.frontend`), none when nobody was
found. Nothing is published for an image without a CameraInfo of its size.

Threads: the executor's thread receives; an image waits in a slot of one, a newer one replacing
it (``dropped.overload``), so the newest is always the one taken; one processing thread runs the
model and publishes. ``max_rate_hz`` skips images by stamp before they wait (``dropped.rate_cap``;
by arrival time while stamps are zero or go backwards, which are counted). Every fault is counted
under its reason in ``/diagnostics`` (1 Hz) and logged once; none stops the node. The log tells
the run's story (:mod:`hac_ros.people.story`). ``num_threads`` pins the process
(``hac_people_node`` itself, not a node embedded in another program) to that many cores.
"""
from __future__ import annotations

import sys
import threading
import time
import traceback
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from hac_ros.core.basics.errors import InputError
from hac_ros.people import extra
from hac_ros.people.arguments import USAGE
from hac_ros.people.frontend import PeopleFromImages, size_matches
from hac_ros.people.lifting import Camera
from hac_ros.people.params import NODE_NAME, PeopleParams, describe, names, rectified
from hac_ros.people.reasons import REJECTIONS, WARNINGS
from hac_ros.people.story import PeopleStory, describe_camera
from hac_ros.ros.arguments import run
from hac_ros.ros.parameters import descriptor_of
from msg_adapters import (
    MessageError,
    camera_info_to_intrinsics,
    joints_to_pose_array,
    rclpy_types,
    stamp_to_ns,
)
from msg_adapters.image import ImageError, camera_info_distortion
from msg_adapters.stamps import make_header

TYPES = rclpy_types()
DIAGNOSTICS_TOPIC = '/diagnostics'
DIAGNOSTICS_PERIOD_S = 1.0
IMAGE_DEPTH = 10  # images kept by the middleware until the executor takes them (it is quick)
OUTPUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
STEADY = Clock(clock_type=ClockType.STEADY_TIME)
OK, WARN, ERROR = b'\x00', b'\x01', b'\x02'



class PeopleNode(Node):
    """hac_people_node: images and CameraInfo in, metric people out (docs/people.md)."""

    PROGRAM = NODE_NAME
    SUMMARY = ('People from pixels: each person\'s metric landmarks from a camera\'s images '
               '(MediaPipe BlazePose GHUM 3D on a CPU), the joints hac_node needs.')
    USAGE = USAGE
    INSTALL = extra.INSTALL
    PIN_THREADS = False  # hac_people_node's process pins itself (num_threads); a test does not

    def __init__(self, node_name: str = NODE_NAME, params_files: Sequence[str] = (),
                 **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        for name in names():
            info = describe(name)
            self.declare_parameter(name, info['default'],
                                   descriptor_of(info, info['description'], read_only=True))
        self.params = PeopleParams.from_dict(
            {name: self.get_parameter(name).value for name in names()})
        if self.PIN_THREADS:
            extra.limit_threads(self.params.num_threads)
        from hac_ros.people.model import PoseModel

        self.people = PeopleFromImages(PoseModel.from_params(self.params),
                                       self.params.landmark_min_visibility)
        self.counts: Counter[str] = Counter()
        self._told: set[str] = set()
        self._lock = threading.Lock()  # counts, camera, the slot
        self._wake = threading.Condition(self._lock)
        self._slot: tuple[Any, int] | None = None
        self._camera: tuple[Camera, str] | None = None  # and its frame_id
        self._camera_invalid = ''  # why the last CameraInfo was refused, while none is in use
        self._rectified = rectified(self.params)
        self._kept: tuple[int, int] | None = None  # (stamp, arrival) ns of the last image let
        # through the rate cap
        self._previous_stamp: int | None = None  # of the last image received
        self._busy = False  # an image is being processed
        self._period: Counter[str] = Counter()  # this diagnostics period's counts
        self._timing: list[tuple[float, float, float]] = []  # (total, model, lift) seconds
        self._stopping = False
        self._compressed = self.params.image_transport == 'compressed'
        topic = self.params.image_topic + ('/compressed' if self._compressed else '')
        msgtype = ('sensor_msgs/msg/CompressedImage' if self._compressed
                   else 'sensor_msgs/msg/Image')
        self.image_topic = topic
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=IMAGE_DEPTH,
                         reliability=ReliabilityPolicy.RELIABLE
                         if self.params.image_qos == 'reliable' else ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.VOLATILE)
        events = SubscriptionEventCallbacks(message_lost=self._on_lost,
                                            incompatible_qos=self._on_incompatible)
        self.create_subscription(TYPES.get(msgtype), topic, self._on_image, qos,
                                 event_callbacks=events)
        self.create_subscription(TYPES.get('sensor_msgs/msg/CameraInfo'),
                                 self.params.camera_info_topic, self._on_camera_info, qos,
                                 event_callbacks=SubscriptionEventCallbacks(
                                     incompatible_qos=self._on_incompatible))
        self._joints = self.create_publisher(TYPES.get('geometry_msgs/msg/PoseArray'),
                                             self.params.joints_topic, OUTPUT_QOS)
        self._diagnostics = self.create_publisher(
            TYPES.get('diagnostic_msgs/msg/DiagnosticArray'), DIAGNOSTICS_TOPIC, OUTPUT_QOS)
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics, clock=STEADY)
        self.story = PeopleStory(self.get_logger(), self.resolve_topic_name(topic),
                                 self.resolve_topic_name(self.params.camera_info_topic))
        self.create_timer(0.5, self._tick, clock=STEADY)
        self._worker = threading.Thread(target=self._work, name='hac_people', daemon=True)
        self._worker.start()
        rate = (f'at most {self.params.max_rate_hz:g} images/s of stamp time'
                if self.params.max_rate_hz > 0 else 'every image')
        self.get_logger().info(
            f'people from {topic} ({"rectified: P" if self._rectified else "raw: K and D"}) with '
            f'{self.params.camera_info_topic} -> {self.params.joints_topic} (joint_layout '
            f'blazepose33), {rate}, person detector {self.params.person_detector}')

    def destroy_node(self) -> None:
        with self._lock:
            self._stopping = True
            self._wake.notify_all()
        self._worker.join(timeout=30.0)
        self.people.model.close()
        super().destroy_node()

    # ------------------------------------------------------------------ inputs
    def _on_camera_info(self, msg: Any) -> None:
        try:
            K, width, height = camera_info_to_intrinsics(msg, rectified=self._rectified)
            model, D = ('', np.zeros(0)) if self._rectified else camera_info_distortion(msg)
            camera = Camera(K=K, width=width, height=height, D=D, distortion_model=model)
        except (MessageError, InputError) as exc:
            with self._lock:
                if self._camera is None:
                    self._camera_invalid = str(exc)
            self._reject('camera_info_invalid', str(exc))
            return
        with self._lock:
            self._camera = (camera, str(msg.header.frame_id))
        self.story.camera_info(camera, self._rectified)

    def _on_lost(self, info: Any) -> None:
        """Images the middleware received but dropped before the node saw them (its queue of
        IMAGE_DEPTH was full: images faster than the executor takes them)."""
        with self._lock:
            self._count('dropped.lost', max(int(info.total_count_change), 0))

    def _on_incompatible(self, info: Any) -> None:
        """A publisher whose QoS cannot match (a best-effort camera while image_qos is
        reliable): counted, said once."""
        with self._lock:
            self._count('qos_incompatible')
            first = 'qos_incompatible' not in self._told
            self._told.add('qos_incompatible')
        if first:
            self.get_logger().warning(
                f'a publisher on {self.image_topic} or {self.params.camera_info_topic} cannot '
                f'match this node\'s {self.params.image_qos} subscription: its images never '
                'arrive; set image_qos to best_effort for a best-effort camera (counted as '
                'qos_incompatible in /diagnostics; said once)')

    def _on_image(self, msg: Any) -> None:
        """Executor thread: the stamp's checks and the rate cap, then the slot (the newest image
        waits there)."""
        arrival = time.monotonic_ns()
        with self._lock:
            self._count('images_received')
        try:
            stamp = stamp_to_ns(msg.header.stamp)
        except MessageError as exc:
            self._reject('corrupt_image', f'an image header without a valid stamp ({exc})')
            return
        self.story.image(int(getattr(msg, 'width', 0)), int(getattr(msg, 'height', 0)),
                         str(getattr(msg, 'encoding', '') or getattr(msg, 'format', '')), stamp)
        with self._lock:
            previous, self._previous_stamp = self._previous_stamp, stamp
            untrusted = ('stamp_zero' if stamp == 0 else 'stamp_backwards'
                         if previous is not None and stamp < previous else '')
            period_ns = (1e9 / self.params.max_rate_hz) if self.params.max_rate_hz > 0 else 0.0
            capped = False
            if self._kept is not None and period_ns > 0:
                kept_stamp, kept_arrival = self._kept
                trusted = not untrusted and kept_stamp > 0
                elapsed = stamp - kept_stamp if trusted else arrival - kept_arrival
                capped = elapsed < period_ns
            if capped:
                self._count('dropped.rate_cap')
            else:
                self._kept = (stamp, arrival)
                if self._slot is not None:
                    self._count('dropped.overload')
                self._slot = (msg, stamp)
                self._wake.notify()
        if untrusted:
            self._warn(untrusted, f'stamp {stamp / 1e9:.3f} s' + (
                f' after {previous / 1e9:.3f} s' if untrusted == 'stamp_backwards' and
                previous is not None else ''))

    # ------------------------------------------------------------------ processing
    def _work(self) -> None:
        """The processing thread: takes the newest waiting image until the node stops."""
        while True:
            with self._lock:
                while self._slot is None and not self._stopping:
                    self._wake.wait()
                if self._stopping:
                    return
                msg, stamp = self._slot  # type: ignore[misc]
                self._slot = None
                self._busy = True
                camera = self._camera
            try:
                self._process(msg, stamp, camera)
            except Exception:  # never stop the node; counted and logged
                self._reject('processing_error', traceback.format_exc())
            finally:
                with self._lock:
                    self._busy = False

    def _process(self, msg: Any, stamp: int, camera: tuple[Camera, str] | None) -> None:
        start = time.perf_counter()
        from hac_ros.people.images import message_to_rgb

        try:
            rgb = message_to_rgb(msg, self._compressed)
        except ImageError as exc:
            self._reject(exc.reason, str(exc))
            return
        if camera is None:
            with self._lock:
                invalid = self._camera_invalid
            self._reject('no_camera_info', f'no valid CameraInfo on '
                         f'{self.params.camera_info_topic} yet' + (
                             f' (the last was invalid: {invalid})' if invalid else '')
                         + ': nothing metric is published without K')
            return
        if not size_matches(rgb, camera[0]):
            self._reject('camera_info_size_mismatch', f'an image of {rgb.shape[1]} x '
                         f'{rgb.shape[0]} on {self.image_topic} while the CameraInfo says '
                         f'{camera[0].width} x {camera[0].height}: it is skipped')
            return
        frame = self.people.process(rgb, camera[0])
        if frame.too_small:
            self._warn('image_too_small', f'{rgb.shape[1]} x {rgb.shape[0]} on '
                       f'{self.image_topic}')
        frame_id = self.params.camera_frame or str(msg.header.frame_id) or camera[1]
        self._joints.publish(joints_to_pose_array(frame.joints_cam, stamp, frame_id, TYPES))
        self.story.people(frame.joints_cam, stamp)
        with self._lock:
            self._count('images_processed')
            self._count('people_published', len(frame.lifted))
            self._count('people_from_crops', frame.from_crop)
            self._count('landmarks_unseen', frame.unseen)
            for reason, count in frame.dropped.items():
                self._count(f'people_dropped.{reason}', count)
            self._timing.append((time.perf_counter() - start, frame.model_s, frame.lift_s))

    # ------------------------------------------------------------------ status
    def _count(self, key: str, n: int = 1) -> None:
        """Counts a key (the lock held)."""
        self.counts[key] += n
        self._period[key] += n

    def _warn(self, key: str, text: str) -> None:
        """An image processed all the same, with a warning of :data:`WARNINGS`."""
        with self._lock:
            self._count(key)
            first = key not in self._told
            self._told.add(key)
        if first:
            self.get_logger().warning(f'{WARNINGS[key]}: {text} (counted as {key} in '
                                      '/diagnostics; said once)')

    def _tick(self) -> None:
        with self._lock:
            counts = dict(self.counts)
            waiting = int(self._slot is not None) + int(self._busy)
        self.story.tick(counts, waiting, self.params.log_period_s, self.params.stale_after_s)

    def _reject(self, reason: str, text: str) -> None:
        with self._lock:
            self._count(f'rejected.{reason}')
            first = reason not in self._told
            self._told.add(reason)
        if first:
            self.get_logger().warning(f'{REJECTIONS[reason]}: {text} (counted as rejected.'
                                      f'{reason} in /diagnostics; said once)')

    def status(self) -> tuple[bytes, str, list[tuple[str, str]]]:
        """The level, message and key-values of /diagnostics now; starts a new period."""
        with self._lock:
            period, self._period = self._period, Counter()
            timing, self._timing = self._timing, []
            counts = dict(self.counts)
            camera = self._camera[0] if self._camera is not None else None
            invalid = self._camera_invalid
        problems = sorted(k.split('.', 1)[1] for k in period if k.startswith('rejected.'))
        warned = sorted(k for k in period if k in WARNINGS)
        if counts.get('qos_incompatible'):
            level, message = WARN, 'a camera publisher\'s QoS does not match image_qos'
        elif problems or warned:
            level, message = WARN, '; '.join(
                (['images rejected: ' + ', '.join(problems)] if problems else [])
                + (['images with warnings: ' + ', '.join(warned)] if warned else []))
        elif camera is None:
            level, message = WARN, (f'the CameraInfo on {self.params.camera_info_topic} is '
                                    f'invalid' if invalid else
                                    f'no CameraInfo on {self.params.camera_info_topic}')
        elif not period.get('images_received'):
            level, message = WARN, f'no image on {self.image_topic}'
        else:
            level, message = OK, (f'{period.get("images_processed", 0)} images, '
                                  f'{period.get("people_published", 0)} people')
        values = [(key, str(counts[key])) for key in sorted(counts)]
        values.append(('camera_info', describe_camera(camera, self._rectified)
                       if camera is not None else f'invalid: {invalid}' if invalid else 'none'))
        if timing:
            for k, name in enumerate(('processing_ms', 'model_ms', 'lift_ms')):
                values.append((name, f'{1e3 * sum(t[k] for t in timing) / len(timing):.1f}'))
        return level, message, values

    def _publish_diagnostics(self) -> None:
        level, message, values = self.status()
        KeyValue = TYPES.get('diagnostic_msgs/msg/KeyValue')
        status = TYPES.get('diagnostic_msgs/msg/DiagnosticStatus')(
            level=level, name=f'{self.get_name()}: people', message=message,
            hardware_id=self.image_topic,
            values=[KeyValue(key=key, value=value) for key, value in values])
        now = self.get_clock().now().nanoseconds
        self._diagnostics.publish(TYPES.get('diagnostic_msgs/msg/DiagnosticArray')(
            header=make_header(now, '', TYPES), status=[status]))


class _PinnedPeopleNode(PeopleNode):
    PIN_THREADS = True


def main(args: list[str] | None = None) -> int:
    """``hac_people_node``: exit 2 with the install command without the [people] extra."""
    if not extra.available():
        print(f'{NODE_NAME}: people from images need the [people] extra ({extra.PACKAGE}): '
              f'{extra.INSTALL}', file=sys.stderr)
        return 2
    return run(_PinnedPeopleNode, args)


if __name__ == '__main__':
    sys.exit(main())
