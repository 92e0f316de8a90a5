"""Feeding a recording to the core: its input messages, in the node's order, to one calibrator.

:class:`CoreFeeder` feeds every input message of a :class:`~hac_ros.recording.reader.Recording` to a
:class:`~hac_ros.core.calibrator.Calibrator` in log-time order with its header stamp
(docs/interface.md, "Processing order"), exactly as ``hac_node`` does (:mod:`hac_ros.bridge.inputs`:
the same decoders and the same map builder). The replay, the evaluation and the tests share it.
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any

import numpy as np

from hac_ros.bridge.inputs import (
    MapBuilder,
    MapBuilt,
    add_camera_info_msg,
    add_joints_msg,
    add_pose_msg,
    add_tf_msg,
)
from hac_ros.bridge.topics import INPUT_BY_KIND, InputKind, in_root
from hac_ros.core.basics.errors import ArgumentError, HacError
from hac_ros.core.basics.outputs import Output
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.rules.params import POSE_MSGTYPES, HacParams, PoseSource
from hac_ros.core.stream.tf_tree import TfPoses
from hac_ros.progress import ProgressBar
from hac_ros.recording.reader import Recording
from msg_adapters import MessageError, parse_cloud_cdr

# the recorded inputs' types (hac_ros.bridge.topics); the pose's is pose_type's
JOINTS_TYPE, CLOUD_TYPE, CAMERA_INFO_TYPE = (INPUT_BY_KIND[kind].msgtype for kind in (
    InputKind.JOINTS, InputKind.CLOUD, InputKind.CAMERA_INFO))

# Messages of the same log time are fed in this order (then any other topic): the camera's
# intrinsics and the map before the frame they serve, the pose (the clock) before its joints.
TIE_ORDER = {'camera_info': 0, 'cloud': 1, 'tf_static': 2, 'pose': 3, 'tf': 3, 'joints': 4}
TF_MSGTYPE = 'tf2_msgs/msg/TFMessage'
TF_TOPICS = ('/tf', '/tf_static')  # pose_source tf: TF as a recording holds it
MAPS_AHEAD = 3  # map clouds decoded and indexed ahead of the calibrator
MAP_WORKERS = 2  # threads indexing maps (scipy's k-d tree build releases the GIL)
LOOKAHEAD_MESSAGES = 400  # at most this many messages read ahead of the calibrator (13 s at 30 Hz)


@dataclass
class InputTopics:
    """The input topics of one replay (resolved against ``/``) and their message types
    (docs/interface.md, "Topics")."""

    pose: str
    pose_type: str
    joints: str
    cloud: str
    camera_info: str  # '' when off or absent from the recording
    tf: str = ''  # pose_source tf: /tf ('' otherwise; then pose is '')
    tf_static: str = ''  # pose_source tf: /tf_static when the recording holds it

    @classmethod
    def check(cls, recording: Recording, params: HacParams,
              pose_type: str | None = None) -> InputTopics:
        """The parameters' topics, checked against what the recording holds.

        The SLAM pose type is the recording's own (PoseStamped or Odometry, so recordings of both
        kinds replay as they are) unless ``pose_type`` overrides it; the parameters' ``pose_type``
        (the node's subscription type) only names the type expected of a pose topic that is
        neither. Raises :class:`ArgumentError` naming the argument or parameter to set.
        """
        pose_topic, joints_topic = in_root(params.pose_topic), in_root(params.joints_topic)
        cloud_topic = in_root(params.cloud_topic)
        if params.pose_source == PoseSource.TF:  # the SLAM pose from /tf and /tf_static
            recording.check_topic(TF_TOPICS[0], [TF_MSGTYPE], 'TF',
                                  ' (pose_source tf; or pose_source topic: the SLAM pose from '
                                  'pose_topic)')
            static = TF_TOPICS[1] if recording.has(TF_TOPICS[1], TF_MSGTYPE) else ''
            camera_info = cls._camera_info(recording, params)
            recording.check_topic(joints_topic, [JOINTS_TYPE], 'HMR joints',
                                  ' (use {joints_topic})', ('joints_topic',))
            recording.check_topic(cloud_topic, [CLOUD_TYPE], 'map cloud',
                                  ' (use {cloud_topic})', ('cloud_topic',))
            return cls('', '', joints_topic, cloud_topic, camera_info, TF_TOPICS[0], static)
        if params.static_camera:  # a fixed camera: the SLAM pose and the map are optional
            if pose_topic not in recording.topics:
                pose_topic = ''
            if cloud_topic not in recording.topics:
                cloud_topic = ''
        if not pose_topic:
            recording.check_topic(joints_topic, [JOINTS_TYPE], 'HMR joints',
                                  ' (use {joints_topic})', ('joints_topic',))
            if cloud_topic:
                recording.check_topic(cloud_topic, [CLOUD_TYPE], 'map cloud',
                                      ' (use {cloud_topic})', ('cloud_topic',))
            return cls('', '', joints_topic, cloud_topic, cls._camera_info(recording, params))
        recorded = recording.topics.get(pose_topic)
        if pose_type is None:
            pose_type = next((k for k, v in POSE_MSGTYPES.items() if v == recorded),
                             params.pose_type)
        elif pose_type not in POSE_MSGTYPES:
            raise ArgumentError(f'{{pose_type}} must be one of {", ".join(POSE_MSGTYPES)}, '
                                f'not {pose_type!r}', 'pose_type')
        other = next(k for k in POSE_MSGTYPES if k != pose_type)
        if recorded == POSE_MSGTYPES[other]:
            hint = (f' (use {{pose_type}} {other}, or no {{pose_type}}: it is read from the '
                    'recording)')
            recording.check_topic(pose_topic, [POSE_MSGTYPES[pose_type]], 'SLAM pose', hint,
                                  ('pose_type',))
        recording.check_topic(pose_topic, [POSE_MSGTYPES[pose_type]], 'SLAM pose',
                              ' (use {pose_topic})', ('pose_topic',))
        recording.check_topic(joints_topic, [JOINTS_TYPE], 'HMR joints',
                              ' (use {joints_topic})', ('joints_topic',))
        recording.check_topic(cloud_topic, [CLOUD_TYPE], 'map cloud',
                              ' (use {cloud_topic})', ('cloud_topic',))
        camera_info = cls._camera_info(recording, params)
        return cls(pose_topic, POSE_MSGTYPES[pose_type], joints_topic, cloud_topic, camera_info)

    @staticmethod
    def _camera_info(recording: Recording, params: HacParams) -> str:
        """The CameraInfo topic, '' when off or absent (checked when present)."""
        camera_info = in_root(params.camera_info_topic) if params.camera_info_topic else ''
        if camera_info and camera_info in recording.topics:
            recording.check_topic(camera_info, [CAMERA_INFO_TYPE], 'CameraInfo',
                                  ' (use {camera_info_topic}, or "" to turn it off)',
                                  ('camera_info_topic',))
            return camera_info
        return ''

    def kinds(self) -> dict[str, str]:
        """topic -> 'pose' | 'tf' | 'tf_static' | 'joints' | 'cloud' | 'camera_info'."""
        out = {self.joints: 'joints'}
        for topic, kind in ((self.cloud, 'cloud'), (self.pose, 'pose'),
                            (self.camera_info, 'camera_info'),
                            (self.tf, 'tf'), (self.tf_static, 'tf_static')):
            if topic:
                out[topic] = kind
        return out


class CoreFeeder:
    """Feeds a recording's input messages to one calibrator, the way ``hac_node`` feeds it.

    ``poses`` keeps the raw SLAM trajectory when asked (for the TUM export):
    [(stamp ns, R_wc (3, 3) camera to map, c (3,) SLAM units, map frame)].
    """

    def __init__(self, recording: Recording, topics: InputTopics, calibrator: Calibrator,
                 keep_poses: bool = False) -> None:
        self.recording = recording
        self.topics = topics
        self.kinds = topics.kinds()
        self.calibrator = calibrator
        self.poses: list[tuple[int, np.ndarray, np.ndarray]] | None = [] if keep_poses else None
        p = calibrator.params
        self.tf = TfPoses(p.slam_map_frame, p.slam_pose_frame) if topics.tf else None

    def run(self, on_outputs: Callable[[list[Output]], None],
            on_message: Callable[[str, int, Any], None] | None = None,
            progress: ProgressBar | None = None) -> None:
        """Feed every input message in log-time order, then flush. Map clouds are decoded and
        indexed ahead on the map builder's threads and handed over in order, at their place."""
        builder = MapBuilder(self.calibrator.build_index, workers=MAP_WORKERS)
        try:
            for topic, log_ns, item in self._lookahead(builder, on_message):
                if progress is not None:
                    progress.update(1)
                if topic is not None:
                    on_outputs(self.feed(self.kinds[topic], item, log_ns))
        finally:
            builder.close()
        on_outputs(self.calibrator.flush())

    def _lookahead(self, builder: MapBuilder, on_message: Callable[[str, int, Any], None] | None
                   ) -> Iterator[tuple[str | None, int, Any]]:
        """(topic, log time, item) in order: raw bytes, or the Future of a cloud's MapBuilt
        (submitted to the builder up to MAPS_AHEAD clouds ahead); topic None for a message that
        is only copied (``on_message``)."""
        wanted = list(self.recording.topics) if on_message is not None else list(self.kinds)
        queue: deque[tuple[str | None, int, Any]] = deque()
        maps_waiting = 0
        for topic, log_ns, raw in tie_ordered(self.recording.messages(wanted), self.kinds):
            if on_message is not None:
                on_message(topic, log_ns, raw)
            kind = self.kinds.get(topic)
            if kind == 'cloud':
                queue.append((topic, log_ns, self._submit(builder, topic, log_ns, raw)))
                maps_waiting += 1
            else:
                queue.append((topic if kind else None, log_ns, raw))
            while queue and (maps_waiting >= MAPS_AHEAD or len(queue) > LOOKAHEAD_MESSAGES):
                item = queue.popleft()
                maps_waiting -= isinstance(item[2], Future)
                yield item
        yield from queue

    def _submit(self, builder: MapBuilder, topic: str, log_ns: int, raw: Any) -> Future:
        """The header read here, the points decoded and indexed on the builder (as hac_node); a
        cloud whose header does not decode is rejected at its place in the order (stamp −1)."""
        try:
            cloud = parse_cloud_cdr(self.recording.to_cdr(raw, topic, log_ns))
        except MessageError as exc:
            failed: Future = Future()
            failed.set_result(MapBuilt(-1, None, str(exc)))
            return failed
        return builder.submit(cloud)

    def feed(self, kind: str, item: Any, log_ns: int) -> list[Output]:
        """One input message (raw bytes, or the Future of a built map) -> calibrator outputs."""
        cal = self.calibrator
        if kind == 'cloud':
            return item.result().hand_to(cal)
        topic = {'pose': self.topics.pose, 'joints': self.topics.joints,
                 'camera_info': self.topics.camera_info, 'tf': self.topics.tf,
                 'tf_static': self.topics.tf_static}[kind]
        # malformed bytes (msg None) are a counted rejection of their kind, as in the node
        msg = self.recording.deserialize_or_none(self.recording.to_cdr(item, topic, log_ns), topic)
        if kind in ('tf', 'tf_static'):
            assert self.tf is not None  # topics.tf is set
            taken = add_tf_msg(cal, self.tf, msg, kind == 'tf_static')
            if taken.errors:  # the replay stops here; the node counts and logs it
                raise HacError(taken.errors[0])
            if self.poses is not None:
                self.poses += taken.poses
            return taken.outputs
        if kind == 'pose':
            outputs, pose = add_pose_msg(cal, msg)
            if pose is not None and self.poses is not None:
                self.poses.append(pose)
            return outputs
        if kind == 'joints':
            return add_joints_msg(cal, msg)
        if msg is None:
            return cal.reject('camera_info_invalid', -1)
        return add_camera_info_msg(cal, msg)[0]


def tie_ordered(messages: Iterable[tuple[str, int, Any]], kinds: dict[str, str]
                ) -> Iterator[tuple[str, int, Any]]:
    """(topic, log time, raw) in log-time order, messages of equal log time in :data:`TIE_ORDER`.

    Storage formats differ in how they order messages of equal log time (a ROS 1 bag's index groups
    them by connection): a fixed order keeps the result independent of the storage. Otherwise the
    storage's order (the recorder's arrival order) is kept.
    """
    last = len(TIE_ORDER)
    group: list[tuple[str, int, Any]] = []
    for item in messages:
        if group and item[1] != group[0][1]:
            yield from sorted(group, key=lambda m: TIE_ORDER.get(kinds.get(m[0], ''), last))
            group = []
        group.append(item)
    yield from sorted(group, key=lambda m: TIE_ORDER.get(kinds.get(m[0], ''), last))


def offline_run(recording: Recording, params: HacParams) -> Calibrator:
    """An offline calibrator fed the whole ``recording``, to be resolved as the offline replay
    does, or with any scale schedule (:func:`hac_ros.core.offline.resolve_offline`)."""
    calibrator = Calibrator(params, offline=True)
    CoreFeeder(recording, InputTopics.check(recording, params), calibrator).run(lambda _: None)
    return calibrator
