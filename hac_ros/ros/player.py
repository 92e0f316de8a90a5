"""``hac play``: a recording's input topics published over DDS, as ``ros2 bag play`` would.

The ROS 2 wheels have no ``ros2 bag play`` (rosbag2 and ros2cli are not wheels), so this is the way
to drive ``hac_node`` from a recording without a ROS install. :class:`Player` reads the recording
with :class:`~hac_ros.recording.reader.Recording` (rosbag2 sqlite3 or mcap, or a ROS 1 bag) and
publishes each message's CDR bytes as they are (a ROS 1 message converted to its ROS 2 type):

- in log-time order, messages of one log time in the replay's order
  (:func:`hac_ros.replay.feeder.tie_ordered`: the intrinsics and the map before the pose, the pose
  before its joints), each at ``log time / rate`` after the first, on the monotonic clock;
- with the QoS ``hac_node`` expects: every topic reliable (which a best-effort subscriber matches
  too), maps (``sensor_msgs/msg/PointCloud2``), ``/tf_static`` and any topic recorded as transient
  local also transient local, so a node started late still gets the map;
- ``clock_hz`` > 0: ``/clock`` (``rosgraph_msgs/msg/Clock``) with the playback time, before each
  message and at that rate in between, for nodes run with ``use_sim_time``;
- ``loop``: from the start again at the end (the stamps then go back in time, as with
  ``ros2 bag play --loop``).

By default the topics played are hac_node's inputs present in the recording (``/slam/pose``,
``/slam/cloud``, ``/hmr/joints``, ``/camera/camera_info``, and ``/tf`` and ``/tf_static`` for
``pose_source: tf``); ground truth and outputs are not. ``topics`` names others; ``remap`` renames
them on the way out. A topic whose message type this Python cannot publish (``tf2_msgs`` is not in
the ROS wheels) is left out (:attr:`Player.skipped` says why, for the caller to report), or
refused when it was asked for by name.

:meth:`Player.run` stops between two messages when its ``stop`` event is set (the command's
signal handlers set it), so an interrupted play never leaves half a message. Errors name the
argument (``rate``, ``topics``, ``remap``); only :mod:`hac_ros.cli.play` names flags.

A video (a file OpenCV reads) or a folder of images (one without ``metadata.yaml``, sorted by
name) is played as a camera, the way ROS's image_publisher does, through
:class:`~hac_ros.ros.camera_source.CameraFrames` (OpenCV: the ``[people]`` extra):
``/camera/image_raw``
(``sensor_msgs/Image`` rgb8; with ``compressed``, ``/camera/image_raw/compressed``, a JPEG
``CompressedImage``) and ``/camera/camera_info`` (the frames' size, K, plumb_bob D), both
reliable, depth 10 (what ``hac_people_node`` subscribes with), the CameraInfo just before its image
with the same header. Frame i is stamped ``start + i / fps`` (the video's rate, or ``fps``), as
``hac people`` stamps it; with ``loop`` the stamps run on (pass k's frame i at
``start + (k N + i) / fps``), and every frame goes out at ``(stamp - first stamp) / rate`` after the
first: a decoder slower than that falls behind, no frame is skipped.
"""
from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hac_ros.core.basics.errors import ArgumentError, HacError, ParameterError
from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.printable import printable
from hac_ros.core.rules.params import POSE_MSGTYPES
from hac_ros.recording.reader import Recording
from hac_ros.replay.feeder import tie_ordered
from hac_ros.ros.camera_source import (
    CAMERA_DEPTH,
    COMPRESSED_TOPIC,
    DEFAULT_FRAME_ID,
    DEFAULT_START_S,
    IMAGE_TOPIC,
    RECORDING,
    RECORDING_SUFFIXES,
    CameraFrames,
    input_kind,
)
from msg_adapters import MessageError, ns_to_stamp, rclpy_types

log = logging.getLogger(__name__)

# hac_node's input topics as a recording holds them (resolved in the root namespace)
DEFAULT_TOPICS = ('/slam/cloud', '/slam/pose', '/camera/camera_info', '/hmr/joints', '/tf',
                  '/tf_static')
CLOCK = ('/clock', 'rosgraph_msgs/msg/Clock')
CLOUD_MSGTYPE = 'sensor_msgs/msg/PointCloud2'
TF_STATIC = '/tf_static'
RELIABLE_DEPTH = 100  # messages a reliable publisher keeps for a slow subscriber (3 s at 30 Hz)
STATIC_DEPTH = 100  # /tf_static messages kept for late subscribers (each holds some transforms)
ACK_TIMEOUT_S = 5.0  # at the end, the longest wait for subscribers to acknowledge the last messages
# ... and then how long the publishers stay up: a best-effort subscriber (hac_node's default
# input_qos) acknowledges nothing, and a publisher destroyed at once loses what is still in
# flight (seen on a loaded machine: the last joints frame of a recording never arrived)
LINGER_S = 1.0
WAIT_POLL_S = 0.05
# the tie order of messages of one log time (hac_ros.replay.feeder.TIE_ORDER), by message type
KIND_OF_TYPE = {'sensor_msgs/msg/CameraInfo': 'camera_info', CLOUD_MSGTYPE: 'cloud',
                'geometry_msgs/msg/PoseArray': 'joints',
                **{msgtype: 'pose' for msgtype in POSE_MSGTYPES.values()}}
INSTALL_HINT = {'tf2_msgs': 'ros-jazzy-tf2-msgs (comes with tf2_ros)'}



@dataclass
class PlayTopic:
    """One topic played: its name in the recording, the name it is published on, its message
    type, and whether its publisher is transient local (latched)."""

    name: str
    published_as: str
    msgtype: str
    latched: bool
    depth: int = RELIABLE_DEPTH  # the history of a publisher that is not latched


@dataclass
class PlayStats:
    """What one :meth:`Player.run` published: messages per published topic, loops started, wall
    seconds, and whether it was stopped before the end."""

    published: Counter[str] = field(default_factory=Counter)
    loops: int = 0
    wall_s: float = 0.0
    stopped: bool = False
    skipped: list[str] = field(default_factory=list)  # topics left out (type not publishable)

    @property
    def total(self) -> int:
        return sum(self.published.values())

    def text(self) -> str:
        topics = ', '.join(f'{t} {n}' for t, n in sorted(self.published.items())) or 'nothing'
        how = 'stopped' if self.stopped else 'done'
        loops = f', {self.loops} loops' if self.loops > 1 else ''
        return f'{how} after {self.wall_s:.1f} s{loops}: published {topics}'


def check_rate(rate: float) -> float:
    """``rate``, a finite number > 0 (ParameterError naming ``rate`` otherwise)."""
    try:
        value = float(rate)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f'rate: expected a number > 0, got {rate!r}') from exc
    if not 0.0 < value < float('inf'):
        raise ParameterError(f'rate: expected a number > 0, got {rate!r}')
    return value


def plan_topics(recording: Recording, topics: Sequence[str] | None = None,
                remap: Mapping[str, str] | None = None) -> tuple[list[PlayTopic], list[str]]:
    """The topics to play and the ones left out (their type cannot be published here).

    topics: names in the recording (default: :data:`DEFAULT_TOPICS` that it holds); remap: name in
    the recording -> name to publish on. HacError when a named topic is not in the recording, a
    remap names a topic not played, or nothing is left to play.
    """
    remap = dict(remap or {})
    present = recording.topics
    if topics:
        wanted = [t if t.startswith('/') else '/' + t for t in topics]
        missing = [t for t in wanted if t not in present]
        if missing:
            raise ArgumentError(f'{{topics}}: {printable(", ".join(missing))} not in '
                                f'{printable(recording.path)}; it '
                                f'holds: {recording.describe()}', 'topics')
    else:
        wanted = [t for t in DEFAULT_TOPICS if t in present]
        if not wanted:
            raise ArgumentError(f'{printable(recording.path)} holds none of the input topics '
                                f'({", ".join(DEFAULT_TOPICS)}); name the ones to play '
                                f'({{topics}}) and {{remap}} them to the node\'s names. It '
                                f'holds: {recording.describe()}', 'topics', 'remap')
    unknown = [old for old in remap if old not in wanted]
    if unknown:
        raise ArgumentError(f'{{remap}}: {printable(", ".join(unknown))} is not a topic played '
                            f'(played: {printable(", ".join(wanted))})', 'remap')
    plan, skipped = [], []
    types = rclpy_types()
    offered = _latched_topics(recording)
    for name in wanted:
        msgtype = present[name]
        try:
            if msgtype is None:
                raise MessageError('its message type is not known')
            types.get(msgtype)
        except MessageError as exc:
            package = (msgtype or '?').split('/')[0]
            hint = INSTALL_HINT.get(package, f'the ROS 2 package {package}')
            reason = (f'{printable(name)} ({printable(msgtype)}) cannot be published here: '
                      f'install {printable(hint)} ({exc})')
            if topics:
                raise HacError(f'topics: {reason}') from exc
            skipped.append(reason)
            continue
        latched = msgtype == CLOUD_MSGTYPE or name == TF_STATIC or name in offered
        plan.append(PlayTopic(name, remap.get(name, name), msgtype, latched))
    if not plan:
        raise HacError('nothing to play: ' + '; '.join(skipped))
    return plan, skipped


def _latched_topics(recording: Recording) -> set[str]:
    """Topics the recording says were offered transient local (rosbag2 offered QoS profiles)."""
    latched = set()
    for connection in recording.reader.connections:
        ext = getattr(connection, 'ext', None)
        for qos in getattr(ext, 'offered_qos_profiles', None) or []:
            if 'TRANSIENT_LOCAL' in str(getattr(qos, 'durability', '')):
                latched.add(connection.topic)
    return latched


# ------------------------------------------------------------------ a video or images as a camera
def plan_camera_topics(frames: CameraFrames, topics: Sequence[str] | None = None,
                       remap: Mapping[str, str] | None = None) -> list[PlayTopic]:
    """The camera topics to play (default both), as :func:`plan_topics` plans a recording's."""
    remap = dict(remap or {})
    given = ', '.join(frames.topics)
    if topics:
        wanted = [t if t.startswith('/') else '/' + t for t in topics]
        missing = [t for t in wanted if t not in frames.topics]
        if missing:
            other = (f' ({COMPRESSED_TOPIC} with {{compressed}})' if not frames.compressed
                     else f' ({IMAGE_TOPIC} without {{compressed}})')
            raise ArgumentError(f'{{topics}}: {printable(", ".join(missing))} not played from '
                                f'{printable(frames.path)} (a {frames.kind}: it gives {given}'
                                f'{other})', 'topics', 'compressed')
        wanted = [t for t in frames.topics if t in wanted]  # the CameraInfo first
    else:
        wanted = list(frames.topics)
    unknown = [old for old in remap if old not in wanted]
    if unknown:
        raise ArgumentError(f'{{remap}}: {printable(", ".join(unknown))} is not a topic played '
                            f'(played: {printable(", ".join(wanted))})', 'remap')
    return [PlayTopic(name, remap.get(name, name), frames.topics[name], False, CAMERA_DEPTH)
            for name in wanted]


class Player:
    """Publishes a recording's topics, or a video's or a folder of images' frames as a camera
    (:class:`CameraFrames`: ``camera``, ``fps``, ``start``, ``frame_id``, ``compressed``, refused
    for a recording), from a node of its own in ``context`` (the default context when None; rclpy
    must be initialised). See the module docstring; ``wait_s``: before playing, wait up to this
    long until every topic played has a subscriber (0: start at once, as ``ros2 bag play``
    does)."""

    def __init__(self, path: str | Path, *, rate: float = 1.0, loop: bool = False,
                 clock_hz: float = 0.0, topics: Sequence[str] | None = None,
                 remap: Mapping[str, str] | None = None, wait_s: float = 0.0,
                 context: Any = None, node_name: str = 'hac_play', camera: str | None = None,
                 fps: float | None = None, start: float | None = None,
                 frame_id: str | None = None, compressed: bool = False) -> None:
        import rclpy

        self.rate = check_rate(rate)
        if not 0.0 <= float(clock_hz) < float('inf'):
            raise ParameterError(f'clock_hz: expected a number >= 0, got {clock_hz!r}')
        if not 0.0 <= float(wait_s) < float('inf'):
            raise ParameterError(f'wait_s: expected a number >= 0, got {wait_s!r}')
        self.loop, self.clock_hz, self.wait_s = loop, float(clock_hz), float(wait_s)
        self.kind = input_kind(path)
        self.recording: Recording | None = None
        self.frames: CameraFrames | None = None
        if self.kind == RECORDING:
            given = [name for name, value in (('camera', camera), ('fps', fps), ('start', start),
                                              ('frame_id', frame_id), ('compressed', compressed))
                     if value is not None and value is not False]
            if given:
                raise ArgumentError(', '.join('{' + n + '}' for n in given) + ': for a video or '
                                    f'a folder of images; {printable(path)} is read as a '
                                    'recording', *given)
            self.recording = _open_recording(path)
            try:
                self.plan, self.skipped = plan_topics(self.recording, topics, remap)
            except BaseException:
                self.recording.close()
                raise
        else:
            self.frames = CameraFrames(
                path, self.kind, camera=camera, fps=fps,
                start=DEFAULT_START_S if start is None else start,
                frame_id=DEFAULT_FRAME_ID if frame_id is None else frame_id, compressed=compressed)
            try:
                self.plan, self.skipped = plan_camera_topics(self.frames, topics, remap), []
            except BaseException:
                self.frames.close()
                raise
        self.node = rclpy.create_node(node_name, context=context,
                                      start_parameter_services=False)
        types = rclpy_types()
        self._publishers = {t.name: self.node.create_publisher(
            types.get(t.msgtype), t.published_as, _qos(t)) for t in self.plan}
        self._clock = (self.node.create_publisher(types.get(CLOCK[1]), CLOCK[0], 10)
                       if self.clock_hz > 0 else None)
        self._kinds = {t.name: KIND_OF_TYPE.get(t.msgtype, '') for t in self.plan}
        self._timeline: tuple[int, float] | None = None  # frames: (first stamp, its wall time)

    # ------------------------------------------------------------------ playing
    def run(self, stop: threading.Event | None = None) -> PlayStats:
        """Play (every loop when ``loop``) until the end or until ``stop`` is set."""
        stop = stop or threading.Event()
        stats = PlayStats(skipped=list(self.skipped))
        start = time.monotonic()
        self._wait_for_subscribers(stop)
        while not stop.is_set():
            stats.loops += 1
            if self.frames is not None:
                played = self._play_frames(stop, stats)
            else:
                self._play_once(stop, stats)
                played = True
            if not self.loop or not played:
                break
        stats.stopped = stop.is_set()
        if not stats.stopped:
            self._wait_for_acks()
        stats.wall_s = time.monotonic() - start
        return stats

    def _messages(self) -> Iterator[tuple[str, int, Any]]:
        assert self.recording is not None
        return tie_ordered(self.recording.messages(list(self._publishers)), self._kinds)

    def _play_once(self, stop: threading.Event, stats: PlayStats) -> None:
        """One pass over the recording: each message at its log time / rate."""
        first_ns: int | None = None
        wall0 = 0.0
        for topic, log_ns, raw in self._messages():
            if first_ns is None:
                first_ns, wall0 = log_ns, time.monotonic()
            due = wall0 + (log_ns - first_ns) / NS / self.rate
            if not self._sleep_until(due, stop, first_ns, wall0):
                return
            self._publish_clock(log_ns)
            assert self.recording is not None
            data = self.recording.to_cdr(raw, topic, log_ns)
            self._publishers[topic].publish(bytes(data))
            stats.published[self._publishers[topic].topic_name] += 1

    def _play_frames(self, stop: threading.Event, stats: PlayStats) -> bool:
        """One pass over the frames, each at (its stamp - the first frame's) / rate after the
        first frame of the first pass (a pass goes on where the last one ended); False when the
        pass had no frame."""
        assert self.frames is not None
        played = False
        for stamp_ns, messages in self.frames.messages([t.name for t in self.plan]):
            played = True
            if self._timeline is None:
                self._timeline = (stamp_ns, time.monotonic())
            first_ns, wall0 = self._timeline
            due = wall0 + (stamp_ns - first_ns) / NS / self.rate
            if not self._sleep_until(due, stop, first_ns, wall0):
                return True
            self._publish_clock(stamp_ns)
            for topic, msg in messages:
                self._publishers[topic].publish(msg)
                stats.published[self._publishers[topic].topic_name] += 1
        return played

    def _sleep_until(self, due: float, stop: threading.Event, first_ns: int,
                     wall0: float) -> bool:
        """Wait until the monotonic time ``due`` (publishing /clock meanwhile); False when
        ``stop`` was set first."""
        while True:
            now = time.monotonic()
            if stop.is_set():
                return False
            if now >= due:
                return True
            step = due - now
            if self._clock is not None:
                step = min(step, 1.0 / self.clock_hz)
            if stop.wait(step):
                return False
            if self._clock is not None and time.monotonic() < due:
                elapsed_ns = (time.monotonic() - wall0) * self.rate * NS
                self._publish_clock(first_ns + int(elapsed_ns))

    def _publish_clock(self, stamp_ns: int) -> None:
        if self._clock is None:
            return
        types = rclpy_types()
        self._clock.publish(types.get(CLOCK[1])(clock=ns_to_stamp(stamp_ns, types)))

    def connected(self) -> bool:
        """Every topic played has a subscriber."""
        return all(p.get_subscription_count() > 0 for p in self._publishers.values())

    def _wait_for_subscribers(self, stop: threading.Event) -> None:
        if self.wait_s <= 0:
            return
        deadline = time.monotonic() + self.wait_s
        while not stop.is_set() and time.monotonic() < deadline:
            if self.connected():
                return
            stop.wait(WAIT_POLL_S)
        lonely = [p.topic_name for p in self._publishers.values()
                  if p.get_subscription_count() == 0]
        if lonely and not stop.is_set():
            log.warning('no subscriber after %.1f s on %s: playing anyway', self.wait_s,
                        printable(', '.join(lonely)))

    def _wait_for_acks(self) -> None:
        """Give subscribers a moment to acknowledge the last messages, and best-effort ones
        LINGER_S to receive them (destroying a publisher drops what is still in flight)."""
        from rclpy.duration import Duration

        for publisher in self._publishers.values():
            publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
        time.sleep(LINGER_S)  # best-effort subscribers acknowledge nothing (LINGER_S)

    def close(self) -> None:
        self.node.destroy_node()
        if self.recording is not None:
            self.recording.close()
        if self.frames is not None:
            self.frames.close()

    def __enter__(self) -> Player:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _qos(topic: PlayTopic) -> Any:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    if topic.latched:
        depth = STATIC_DEPTH if topic.name == TF_STATIC else 1
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=topic.depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


def _open_recording(path: str | Path) -> Recording:
    """Recording(path); a file that is neither a recording nor a video says both."""
    try:
        return Recording(path)
    except HacError as exc:
        if Path(path).is_file() and Path(path).suffix.lower() not in RECORDING_SUFFIXES:
            raise HacError(f'{exc}; nor a video OpenCV (the [people] extra) opens') from exc
        raise
