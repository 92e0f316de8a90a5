"""``hac_node``: the ROS 2 node, a thin shell around :class:`~hac_ros.core.calibrator.Calibrator`.

It subscribes to the SLAM pose, the SLAM map cloud, the HMR joints and (optionally) the CameraInfo,
forwards every message to the calibrator with its header stamp, and publishes exactly the messages
:class:`~hac_ros.bridge.messages.OutputMessages` makes of the calibrator's outputs (the same
messages ``hac replay`` writes). It has no estimation logic of its own; docs/interface.md ("Topics",
"Processing order") and docs/node.md.

Threads. The executor's thread receives: every input message goes at once into the node's
inbox (:mod:`hac_ros.ros.intake`), and services, parameters and timers run there. One processing
thread takes the inbox in arrival order and feeds the calibrator; everything that touches the
calibrator holds one lock, so the calibrator sees one caller at a time. When input comes faster
than it is processed, the inbox drops the oldest joints frames (``frames_dropped``) and coalesces
poses that wait (``poses_coalesced``): no backlog builds, and without either the calibrator sees
what the replay's feed gives it. Map clouds are decoded and indexed on a thread of their own
(:mod:`hac_ros.ros.map_intake`); **while a map is being built, frames use the latest map already
handed over**, the other place where the node may differ from ``hac replay``, which always has
the map at its stamp. Output serializers are made at configure (:mod:`hac_ros.ros.warm`).

Status. ``/diagnostics`` follows stamp time as in the replay (:mod:`hac_ros.core.rules.health`),
with what only the node knows added (:mod:`hac_ros.ros.liveness`): how far behind it is, its
backlog, and warnings when one kind of input stopped coming. A timer on the steady clock (it runs
under ``use_sim_time`` without ``/clock`` too, as the input-type check does) publishes STALE when no
input at all has come for ``stale_after_s``: a last OK never stands for a live status. The log tells
the story of the run at INFO (:mod:`hac_ros.ros.story`); services and runtime parameter changes are
:mod:`hac_ros.ros.control`'s.

Names. Topics are relative (``slam/pose`` in, ``hac/pose`` out: a namespace moves them all),
``/diagnostics`` and ``/tf`` absolute, the services private: ``~/reset``, ``~/freeze``.

Run: ``ros2 run hac_ros hac_node --ros-args --params-file config/hac.yaml`` or
``python -m hac_ros.ros.node --ros-args ...``; the managed variant is ``hac_lifecycle_node``
(:mod:`hac_ros.ros.lifecycle_node`).
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import sys
import threading
import time
import traceback
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Any, cast

from rclpy.clock import Clock, ClockType
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.serialization import deserialize_message

from hac_ros.bridge.inputs import add_camera_info_msg, add_joints_msg, add_pose_msg
from hac_ros.bridge.messages import DIAGNOSTICS, OUTPUT_TOPICS, OutputMessages
from hac_ros.bridge.topics import INPUTS, InputKind, input_msgtype, input_topic
from hac_ros.core.basics.outputs import (
    DiagnosticsOut,
    NoticeOut,
    OdometryOut,
    Output,
    PoseOut,
    ResetOut,
    ScaleOut,
)
from hac_ros.core.basics.printable import printable, printable_lines
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.geometry.reference import MapIndex
from hac_ros.core.rules.health import Finding
from hac_ros.core.rules.params import NODE_NAME, POSE_MSGTYPES, HacParams, PoseSource, names
from hac_ros.core.rules.reasons import REASONS
from hac_ros.ros.arguments import run
from hac_ros.ros.control import RuntimeControl
from hac_ros.ros.graph_watch import GRAPH_CHECK_S, NAME_CHECK_S, GraphWatch, NameWatch
from hac_ros.ros.intake import Inbox, Item, Processor, arrival_s, header_stamp_ns
from hac_ros.ros.liveness import Liveness
from hac_ros.ros.map_intake import MapIntake
from hac_ros.ros.parameters import (
    declare_parameters,
    startup_warnings,
)
from hac_ros.ros.qos import cloud_qos, input_qos, output_qos
from hac_ros.ros.story import Input, Story, WatchedHealth
from hac_ros.ros.tf_broadcast import TfSender
from hac_ros.ros.tf_input import TfPoseInput
from hac_ros.ros.warm import warm_outputs
from msg_adapters import MessageError, rclpy_types, stamp_to_ns

TYPES = rclpy_types()  # rclpy's message classes by ROS name
# Environment variables naming a Fast DDS XML profile (config/fastdds_large_data.xml): Fast DDS
# 2.x reads the first, 3.x the second; read once per process, when rclpy starts
DDS_PROFILE_VARIABLES = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')

STALE_CHECK_S = 0.5  # wall seconds between looks at whether input stopped coming
STEADY = Clock(clock_type=ClockType.STEADY_TIME)  # timers that must run without /clock
# The outputs have no QoS event handlers (rclpy's default warns of an incompatible subscriber,
# which that subscriber's own side says too): each is a waitable that the executor adds to its
# wait set for every message it takes, and the 16 of the 8 outputs cost more than a third of the
# executor thread's time at 1 kHz of poses (docs/node.md, "Performance").
NO_EVENTS = PublisherEventCallbacks(use_default_callbacks=False)


# ---------------------------------------------------------------------------------------- the shell
class HacShell(RuntimeControl):
    """Everything ``hac_node`` does, shared by :class:`HacNode` and the managed
    :class:`hac_ros.ros.lifecycle_node.HacLifecycleNode`; mixed into an rclpy ``Node``.

    Its life in four steps (the lifecycle's transitions; HacNode takes them all at start-up):
    :meth:`_declare` (parameters and their callbacks), :meth:`_configure` (reads the parameters,
    makes the calibrator and the map builder), :meth:`_activate` (publishers, subscriptions,
    services, TF), :meth:`_deactivate` (drops those and keeps the state) and :meth:`_cleanup`
    (drops the state).
    """

    PROGRAM = 'hac_node'  # the command, and the first line of its --help
    SUMMARY = ('The ROS 2 node of hac_ros: a metric scale for monocular SLAM from the people in '
               'view.')
    calibrator: Calibrator | None = None
    active = False

    # ------------------------------------------------------------------ life
    def _declare(self, params_files: Sequence[str] = ()) -> None:
        """Declares the parameters and warns about what ROS would ignore in silence: misspelt
        names, misspelt node sections of ``params_files`` (the node's ``--params-file`` paths)."""
        declare_parameters(self)
        self.names = NameWatch(self)  # another node of this name (hac_ros.ros.graph_watch)
        self._name_check = self.create_timer(NAME_CHECK_S, self.names.check, clock=STEADY)
        for warning in startup_warnings(self, params_files):  # names from a file: escaped
            self.get_logger().warning(printable(warning))
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

    def _configure(self) -> None:
        """Reads the parameters (ParameterError with the reason) and makes the state."""
        values = {name: self.get_parameter(name).value for name in names()}
        self.params = HacParams().replace(**values)
        self.calibrator = Calibrator(self.params)
        self.outputs = OutputMessages(self.params)
        warm_outputs(self.params)  # the serializers made now, not at the first frame's outputs
        self.notices: Counter[str] = Counter()  # causes of the NoticeOut logged (once each)
        self.graph = GraphWatch(self, self._reject)  # QoS, lost messages, wrong types
        self._camera_info: tuple[Any, int, int] | None = None  # (K, width, height) last valid
        self._failed_callbacks: set[str] = set()
        self._output_publishers: dict[str, Any] = {}
        self._subscriptions_by_kind: dict[str, Any] = {}
        self._hac_services: list[Any] = []
        self.tf: TfSender | None = None
        self.tf_input: TfPoseInput | None = None  # pose_source tf (hac_ros.ros.tf_input)
        # the intake (hac_ros.ros.intake): every access to the calibrator holds the lock
        self.lock = threading.RLock()
        self.liveness = Liveness()
        self._inbox = Inbox(self.params.joints_backlog_max, self.params.pose_coalesce_s)
        self.story = Story(self.get_logger(), self._inbox)  # the log's story (hac_ros.ros.story)
        self.story.pose_needed = not self.params.static_camera
        self.outputs.health = WatchedHealth(self.outputs.health.gravity_wanted,
                                            self.story.on_health)
        self._processor = Processor(self._inbox, self._handle, self._on_dropped,
                                    self._on_coalesced, self.lock, self.liveness.load)
        # map clouds built off the executor's thread (hac_ros.ros.map_intake)
        self._maps_ready = self.create_guard_condition(lambda: self.maps.ready())
        self.maps = MapIntake(self._build_index, self._inbox, lambda: self._maps_ready.trigger())
        self.outputs.extra_status = self._node_status

    def _activate(self) -> None:
        for topic, msgtype in OUTPUT_TOPICS:
            self._output_publishers[topic] = self.create_publisher(
                TYPES.get(msgtype), topic, output_qos(topic), event_callbacks=NO_EVENTS)
        for each in INPUTS:
            self._subscribe(each.kind)
        self._hac_services = [self.create_service(TYPES.get('std_srvs/srv/Trigger'), '~/reset',
                                              self._on_reset),
                          self.create_service(TYPES.get('std_srvs/srv/SetBool'), '~/freeze',
                                              self._on_freeze)]
        self._update_tf()
        self._type_check = self.create_timer(
            GRAPH_CHECK_S, lambda: self.graph.check_types(self._subscriptions_by_kind,
                                                          self.params.pose_type), clock=STEADY)
        self._stale_check = self.create_timer(STALE_CHECK_S, self._check_stale, clock=STEADY)
        self.active = True
        p = self.params
        tf = p.pose_source == PoseSource.TF
        poses = (f'TF {p.slam_map_frame} -> {p.slam_pose_frame}' if tf else
                 f'{self.resolve_topic_name(p.pose_topic)} ({p.pose_type})')
        self.get_logger().info(printable(
            f'{self.get_name()}: {poses} + '
            f'{self.resolve_topic_name(p.joints_topic)} + {self.resolve_topic_name(p.cloud_topic)}'
            f' -> {self.resolve_topic_name("hac")}/* in {p.metric_frame!r} '
            f'({p.metric_frame_alignment}) and {p.odom_frame!r} (contact_mode {p.contact_mode}, '
            f'input_qos {p.input_qos}, cloud_qos {p.cloud_qos})'))

    def _deactivate(self) -> None:
        self.active = False
        for kind in list(self._subscriptions_by_kind):
            self.destroy_subscription(self._subscriptions_by_kind.pop(kind))
        for service in self._hac_services:
            self.destroy_service(service)
        self._hac_services = []
        self.destroy_timer(self._type_check)
        if self.tf_input is not None:
            self.tf_input.close()
            self.tf_input = None
        self.destroy_timer(self._stale_check)
        for publisher in self._output_publishers.values():
            self.destroy_publisher(publisher)
        self._output_publishers = {}
        self.tf = None

    def _cleanup(self) -> None:
        if self.calibrator is None:
            return
        self._processor.close()
        self.maps.close()
        self.destroy_guard_condition(self._maps_ready)
        self.calibrator = None

    # ------------------------------------------------------------------ subscriptions
    def _subscribe(self, kind: str) -> None:
        """(Re-)create the subscription of ``kind`` from the current parameters."""
        old = self._subscriptions_by_kind.pop(kind, None)
        if old is not None:
            self.destroy_subscription(old)
        p = self.params
        if kind == InputKind.POSE and self.tf_input is not None:
            self.tf_input.close()
            self.tf_input = None
        self.story.inputs.pop(kind, None)
        # pose_source tf: tf2_ros' listener instead of pose_topic
        if kind == InputKind.POSE and p.pose_source == PoseSource.TF:
            self.tf_input = TfPoseInput(self, p, lambda: self.core, self._emit, self._queued)
            self.story.inputs[kind] = Input(f'TF {p.slam_map_frame} -> {p.slam_pose_frame}',
                                            'tf2_msgs/msg/TFMessage')
            return
        topic = input_topic(p, kind)
        msg_type = TYPES.get(input_msgtype(kind, p.pose_type))
        qos = cloud_qos(p) if kind == InputKind.CLOUD else input_qos(p, kind)
        raw = kind != InputKind.CAMERA_INFO  # deserialized by rclpy only for CameraInfo
        if not topic:
            return  # camera_info_topic "" turns it off
        self.story.inputs[kind] = Input(self.resolve_topic_name(topic),
                                        input_msgtype(kind, p.pose_type))
        callback = {InputKind.POSE: self._on_pose, InputKind.JOINTS: self._on_joints,
                    InputKind.CAMERA_INFO: self._on_camera_info,
                    InputKind.CLOUD: self._on_cloud}[InputKind(kind)]
        events = SubscriptionEventCallbacks(
            incompatible_qos=functools.partial(self.graph.incompatible_qos, kind, topic),
            message_lost=functools.partial(self.graph.message_lost, kind),
            use_default_callbacks=False)  # (the wrong type is graph_watch's)
        self._subscriptions_by_kind[kind] = self.create_subscription(
            # rclpy hands the message info to a callback of two arguments (its typing says one)
            msg_type, topic, cast(Callable[[Any], None], self._guarded(kind, callback)), qos,
            event_callbacks=events, raw=raw)

    def subscription(self, kind: str) -> Any:
        """The rclpy Subscription of input ``kind`` (``pose``, ``joints``, ``camera_info``,
        ``cloud``), or None when it is turned off."""
        return self._subscriptions_by_kind.get(kind)

    def _reject(self, reason: str, text: str = '') -> None:
        """Count one rejection of the ``reason`` (hac_ros.ros.graph_watch's faults); ``text``, when
        given, is what its first notice says."""
        with self.lock:
            outputs = self.core.reject(reason, -1)
        for notice in outputs:  # the first time: say what to change
            if text and isinstance(notice, NoticeOut):
                notice.text = text
        self._emit(outputs)

    def _guarded(self, kind: str, callback: Callable[[Any, float], None]
                 ) -> Callable[[Any, Any], None]:
        """The subscription callback of input ``kind``: ``callback(msg, arrived_s)``, where
        ``arrived_s`` (time.monotonic) is when the middleware received the message, so that the
        time it waited for the executor counts in the node's lag (docs/node.md, Overload). The
        node never dies on input: an unexpected error is logged once and counted."""
        def run(msg: Any, info: Any) -> None:
            try:
                callback(msg, arrival_s(info))
            except Exception:
                with self.lock:
                    self._internal_error(kind)
        return run

    # ------------------------------------------------------------------ inputs
    # A message that cannot be decoded (msg_adapters.MessageError, an invalid stamp included) is
    # rejected with its kind's reason: pose_nonfinite, joints_malformed, camera_info_invalid.
    # Poses and joints arrive as CDR bytes (raw subscriptions) and are deserialized here by
    # rclpy, so that bytes that do not deserialize are a counted rejection too, never an
    # exception in the executor.
    def _on_pose(self, data: bytes, arrived_s: float) -> None:
        self._take('pose', data, arrived_s)

    def _on_joints(self, data: bytes, arrived_s: float) -> None:
        self._take('joints', data, arrived_s)

    def _on_camera_info(self, msg: Any, arrived_s: float) -> None:
        self._take('camera_info', msg, arrived_s)

    def _take(self, kind: str, data: Any, arrived_s: float | None = None) -> None:
        """Executor thread: into the inbox, in arrival order (hac_ros.ros.intake); a pose with
        its header stamp, read from its bytes (for coalescing)."""
        self.liveness.arrival(kind)
        self.story.seen(kind)
        self._inbox.put(kind, data, header_stamp_ns(data) if kind == 'pose' else None, arrived_s)

    def _handle(self, item: Item) -> None:
        """Processing thread, holding the lock: one input to the calibrator, its outputs out.
        The node never dies on input: an unexpected error is logged once and counted."""
        try:
            if item.kind == 'pose':
                msg = _deserialize(item.data, TYPES.get(POSE_MSGTYPES[self.params.pose_type]))
                self._emit(add_pose_msg(self.core, msg)[0])
            elif item.kind == 'joints':
                msg = _deserialize(item.data, TYPES.get('geometry_msgs/msg/PoseArray'))
                self._emit(add_joints_msg(self.core, msg))
                if msg is not None and self.story.first_joints_ns is None:
                    with contextlib.suppress(MessageError):  # counted by add_joints_msg
                        self.story.joints_frame(stamp_to_ns(msg.header.stamp))
            elif item.kind == 'camera_info':
                outputs, intrinsics = add_camera_info_msg(self.core, item.data)
                if intrinsics is not None:
                    self._camera_info = intrinsics
                self._emit(outputs)
            elif item.kind == 'map':
                index = item.data.index
                if index is not None:
                    self.story.first_map(len(index), index.frame_id, index.stamp_ns,
                                         item.data.build_s)
                self._emit(item.data.hand_to(self.core))
            elif item.kind == 'call':  # a transform of pose_source tf, in arrival order
                item.data()
        except Exception:
            self._internal_error(item.kind)

    def _internal_error(self, kind: str) -> None:
        """An unexpected error handling a ``kind`` input (holding the lock): counted as
        ``internal_error``, its traceback logged the first time for each kind."""
        self._emit(self.core.reject('internal_error', -1))
        if kind not in self._failed_callbacks:
            self._failed_callbacks.add(kind)
            self.get_logger().error(printable_lines(
                f'error handling a {kind} message (further ones are counted as '
                f'rejected.internal_error):\n{traceback.format_exc()}'))

    def _queued(self, kind: str, callback: Callable[[Any], None]) -> Callable[[Any], None]:
        """``callback`` run on the processing thread, in arrival order with the other inputs
        (the transforms of pose_source tf); an error in it is counted as any input's."""
        def take(msg: Any) -> None:
            self.liveness.arrival('pose')  # the SLAM poses come this way
            self.story.seen('pose')
            self._inbox.put('call', lambda: callback(msg))
        return take

    def _on_dropped(self, item: Item) -> None:
        """A joints frame the inbox dropped (input faster than processing), holding the lock;
        the first notice says how long a frame takes against the input period."""
        cost, period = self._inbox.frame_cost_s, self._inbox.input_period_s()
        measured = (f'processing takes {1e3 * cost:.1f} ms per frame (the median of the recent '
                    f'frames, with the poses between them) against an input period of '
                    f'{1e3 * period:.1f} ms' if cost == cost and period == period else
                    'frames came faster than the first ones were processed')
        self._reject('frames_dropped', f'rejected input (frames_dropped): joints frames dropped, '
                     f'the oldest waiting: {measured}; joints_backlog_max '
                     f'{self.params.joints_backlog_max}; further ones are counted in /diagnostics')

    def _on_coalesced(self, item: Item) -> None:
        """A SLAM pose the inbox coalesced into the next one (a stream faster than one pose per
        pose_coalesce_s), holding the lock: counted; the first said once, at INFO."""
        outputs = self.core.reject('poses_coalesced', -1)
        for notice in outputs:
            if isinstance(notice, NoticeOut):
                notice.level = 'info'
                notice.text = (
                    'poses_coalesced: SLAM poses come more often than one per pose_coalesce_s '
                    f'({1e3 * self.params.pose_coalesce_s:g} ms): the calibrator gets one at '
                    f'least every {1e3 * self.params.pose_coalesce_s:g} ms of stamp time, the '
                    'newest and the one before each joints frame, so the node keeps up; the '
                    "others' /hac/odometry and /hac/pose are not published (counted as "
                    'rejected.poses_coalesced; pose_coalesce_s 0 processes every pose)')
        self._emit(outputs)

    def _on_cloud(self, data: bytes, arrived_s: float) -> None:
        """Raw CDR bytes: the header read here, decoded and indexed on the builder's thread."""
        self.story.seen('cloud')
        if not self.maps.receive(data, self.params.cloud_mode):
            with self.lock:
                self._emit(self.core.reject('cloud_malformed', -1))

    def _build_index(self, stamp_ns: int, points_map: Any, frame_id: str) -> MapIndex:
        """The builder thread's index, with the current calibrator's parameters."""
        return self.core.build_index(stamp_ns, points_map, frame_id)

    # ------------------------------------------------------------------ outputs
    def _emit(self, outputs: Sequence[Output]) -> None:
        """Log notices, publish the messages of every other output (exactly OutputMessages')."""
        for output in outputs:
            if isinstance(output, NoticeOut):
                self._log_notice(output)
                continue
            if isinstance(output, ResetOut):
                self.story.reset()  # its NoticeOut announces it; counted in diagnostics
                continue
            if isinstance(output, ScaleOut):
                self.story.scale(output.stamp_ns, self.core.status)
            if self.tf is not None and isinstance(output, (OdometryOut, PoseOut)):
                self.tf.send(output)
            if isinstance(output, DiagnosticsOut):
                self.liveness.status_sent_s = time.monotonic()
            for message in self.outputs.convert(output):
                self._output_publishers[message.topic].publish(message.msg)

    def _log_notice(self, notice: NoticeOut) -> None:
        """A notice at its level, escaped; a warning ends with what to do about its reason
        (hac_ros.core.rules.reasons) unless it already says so."""
        self.notices[notice.cause] += 1
        text = printable(notice.text)
        remedy = REASONS[notice.cause].remedy if notice.cause in REASONS else ''
        # one call site per severity: rclpy refuses a call site whose severity changes
        if notice.level == 'info':
            self.get_logger().info(text)
        elif notice.level == 'error':
            self.get_logger().error(text)
        else:
            if remedy and remedy != 'none' and remedy not in text:
                text += f' (what to do: {remedy})'
            self.get_logger().warning(text)

    # ------------------------------------------------------------------ status
    def _node_status(self) -> tuple[list[Finding], list[tuple[str, str]]]:
        """The node's own findings and key-values for each /diagnostics status (liveness, and
        the joints messages received: sent minus received is what DDS lost)."""
        oldest = self._inbox.oldest_arrival_s()
        lag = 0.0 if oldest is None else max(time.monotonic() - oldest, 0.0)
        found, values = self.liveness.findings(self.params, lag)
        found += [f for f in (self.names.finding(), self.graph.finding()) if f is not None]
        return found, [*values, ('joints_received', str(self._inbox.received.get('joints', 0)))]

    def _check_stale(self) -> None:
        """Steady-clock timer: when no stamp-time status has gone out for ``stale_after_s``,
        the last status goes out as STALE with the reason (a last OK never stands for a live
        status). It never waits for the processing thread, which may be in the calibrator for
        long when the node is far behind (the executor would stop taking input): then the last
        status assessed goes out again, with how far behind the node is."""
        self.story.tick(self.params.log_period_s)
        stale = self.liveness.stale(self.params)
        if stale is None or not self.active:
            return
        if self.lock.acquire(blocking=False):
            try:
                status = self.core.status()
            finally:
                self.lock.release()
        elif self.story.status is not None:
            status = dataclasses.replace(self.story.status)
        else:
            return
        found, values = self._node_status()
        status.stamp_ns = max(self.get_clock().now().nanoseconds, status.stamp_ns)
        data = self.outputs.diagnostics(status, [*found, stale], values, take=False)
        self._output_publishers[DIAGNOSTICS[0]].publish(data)


class HacNode(HacShell, Node):
    """hac_node: subscribes to the inputs, feeds the calibrator, publishes its outputs
    (docs/node.md)."""

    def __init__(self, node_name: str = NODE_NAME, params_files: Sequence[str] = (),
                 **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self._declare(params_files)
        self._configure()
        self._activate()

    def destroy_node(self) -> None:
        self._cleanup()
        super().destroy_node()


def _deserialize(data: bytes, msg_type: type) -> Any:
    """rclpy's message of ``data``, or None when the bytes do not deserialize as ``msg_type``."""
    try:
        return deserialize_message(data, msg_type)
    except Exception:
        return None


# ---------------------------------------------------------------------------------------- main
def main(args: list[str] | None = None) -> int:
    """``hac_node``: :func:`run` of :class:`HacNode`."""
    return run(HacNode, args)


if __name__ == '__main__':
    sys.exit(main())
