"""hac_node's topics, in two tables: its inputs (:data:`INPUTS`: each kind, the parameter naming
its topic, its type) and its outputs (:data:`TOPICS`: each topic's name, type, frame, QoS and what
it carries).

The node's publishers and their QoS (:mod:`hac_ros.ros.qos`), the replay's connections, ``hac
live``, the executables' ``--help``, README's list of outputs and the tables of docs/interface.md
and docs/node.md (``make docs``) are all made from :data:`TOPICS`; the tests take their topic lists
from it too. Plain data (no ROS, no rosbags), so that anything may import it.

Names are relative (a namespaced node moves them all) except ``/diagnostics``; the replay writes
them resolved against ``/`` (:func:`in_root`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hac_ros.core.basics.param_fields import Choice
from hac_ros.core.rules.params import POSE_MSGTYPES, HacParams


class InputKind(Choice):
    """The kinds of input hac_node subscribes to (docs/interface.md, "Topics")."""

    POSE = 'pose'
    JOINTS = 'joints'
    CAMERA_INFO = 'camera_info'
    CLOUD = 'cloud'


@dataclass(frozen=True)
class InputTopic:
    """One input: its ``kind``, the parameter naming its topic (``topic_param``) and its ROS 2
    type (``msgtype``; the pose's is the ``pose_type`` parameter's: '')."""

    kind: InputKind
    topic_param: str
    msgtype: str


INPUTS = (
    InputTopic(InputKind.POSE, 'pose_topic', ''),
    InputTopic(InputKind.JOINTS, 'joints_topic', 'geometry_msgs/msg/PoseArray'),
    InputTopic(InputKind.CAMERA_INFO, 'camera_info_topic', 'sensor_msgs/msg/CameraInfo'),
    InputTopic(InputKind.CLOUD, 'cloud_topic', 'sensor_msgs/msg/PointCloud2'),
)
INPUT_BY_KIND: dict[str, InputTopic] = {i.kind: i for i in INPUTS}


def input_msgtype(kind: str, pose_type: str) -> str:
    """The message type of input ``kind`` (an :class:`InputKind`)."""
    return POSE_MSGTYPES[pose_type] if kind == InputKind.POSE else INPUT_BY_KIND[kind].msgtype


def input_topic(params: HacParams, kind: str) -> str:
    """The topic of input ``kind`` that ``params`` name ('' when it is off)."""
    return str(getattr(params, INPUT_BY_KIND[kind].topic_param))


@dataclass(frozen=True)
class OutputTopic:
    """One output topic.

    ``name`` relative or absolute; ``msgtype`` the ROS 2 type; ``frame`` the parameter naming its
    ``header.frame_id`` ('' when the message has none); ``depth`` its QoS history (keep last);
    ``latched`` transient local (a late subscriber gets the last message), else volatile; every
    output is reliable. ``switches``: parameters that must all be true for it to be published or
    written. ``node``: hac_node publishes it; ``replay``: ``hac replay`` writes it. ``summary``:
    one line (``--help``, README); ``detail``: docs/interface.md's cell."""

    key: str
    name: str
    msgtype: str
    frame: str
    depth: int
    latched: bool
    summary: str
    detail: str
    switches: tuple[str, ...] = ()
    node: bool = True
    replay: bool = True

    @property
    def pair(self) -> tuple[str, str]:
        """(name, msgtype)."""
        return self.name, self.msgtype

    @property
    def rooted(self) -> str:
        """The name resolved against ``/`` (:func:`in_root`)."""
        return in_root(self.name)

    def enabled(self, params: Any) -> bool:
        """Whether ``params`` (HacParams) publish it: every one of its switches is on."""
        return all(getattr(params, switch) for switch in self.switches)

    def qos_text(self) -> str:
        """Its QoS in words, as docs/node.md writes it."""
        durability = 'transient local, ' if self.latched else ''
        return f'reliable, {durability}keep last {self.depth}'


STREAM_DEPTH = 100  # odometry/pose/joints/scale/markers: 3 s at 30 Hz for slow subscribers
DIAGNOSTICS_DEPTH = 10

ODOMETRY = OutputTopic(
    'odometry', 'hac/odometry', 'nav_msgs/msg/Odometry', 'odom_frame', STREAM_DEPTH, False,
    'continuous metric odometry',
    '**continuous** metric odometry for every SLAM pose: it starts at the first `hac/pose` and '
    'then adds each SLAM step at the scale of its moment, so it never jumps, not when the '
    'estimate moves, not when the alignment is refined, not at a SLAM reset (the step across a '
    'reset counts as zero; while the new segment converges it waits, then adds the gap\'s steps '
    'with the new scale). Child frame: the camera, or `base_frame`. Twist: metric velocity in the '
    'child frame; covariance grows with the distance travelled. Judge it by relative error (RPE)')
POSE = OutputTopic(
    'pose', 'hac/pose', 'geometry_msgs/msg/PoseWithCovarianceStamped', 'metric_frame',
    STREAM_DEPTH, False, 'the globally consistent metric pose',
    'the **globally consistent** metric pose of the same frame: the current scale times the SLAM '
    'position, through the segment\'s anchor (a new segment starts on the last published pose) '
    'and the metric frame\'s alignment. It moves when the estimate moves, as a localisation '
    'correction does. Covariance from the scale\'s spread and the distance from the anchor, plus '
    'a floor for SLAM noise. ATE, ATE-S, `hac eval`, `hac plot` and `hac export` take the camera '
    'from it')
HUMAN_JOINTS = OutputTopic(
    'human_joints', 'hac/human_joints', 'geometry_msgs/msg/PoseArray', 'metric_frame',
    STREAM_DEPTH, False, 'the people in the metric frame',
    'the input joints in the metric frame, same stamp, same order and blocks; identity '
    'orientations (with `human_filter: smooth` each person\'s root is smoothed, the pose '
    'untouched); a joint not seen (NaN in the input) is NaN here '
    '(docs/inputs.md, "Joints not seen")')
SCALE = OutputTopic(
    'scale', 'hac/scale', 'std_msgs/msg/Float64', '', STREAM_DEPTH, False,
    'the scale, metres per SLAM unit',
    'the current estimate, metres per SLAM unit, after each processed joints frame')
CLOUD = OutputTopic(
    'cloud', 'hac/cloud', 'sensor_msgs/msg/PointCloud2', 'metric_frame', 1, True,
    'the map in metres',
    'the current map in metres (x y z float32), thinned evenly to `cloud_out_max_points`; sent '
    'when a new map is used, when the estimate moved by more than `cloud_republish_rel` or the '
    'alignment by more than 1° or 1 cm, at most once per `cloud_min_period_s` of stamp time, '
    'stamped with the frame that triggered it', switches=('publish_cloud',))
OBSTACLES = OutputTopic(
    'obstacles', 'hac/obstacles', 'sensor_msgs/msg/PointCloud2', 'metric_frame', 1, True,
    'the map\'s points above the floor',
    'with each `hac/cloud`, its points between `obstacle_min_height` and `obstacle_max_height` '
    'above the floor (gravity alignment only)', switches=('publish_cloud', 'publish_obstacles'))
MARKERS = OutputTopic(
    'markers', 'hac/markers', 'visualization_msgs/msg/MarkerArray', 'metric_frame',
    STREAM_DEPTH, False, 'skeletons, floor and camera path for RViz',
    'skeletons with every frame, the ground plane and the camera path at most once per second '
    'of stamp time, for RViz', switches=('publish_markers',))
DIAGNOSTICS = OutputTopic(
    'diagnostics', '/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', '',
    DIAGNOSTICS_DEPTH, False, 'the estimator\'s state',
    'the estimator\'s state once per second of stamp time (the status\'s `hardware_id` is '
    '`metric_frame`): its keys in docs/node.md, "Diagnostics"')
SAMPLES = OutputTopic(
    'samples', 'hac/samples', 'std_msgs/msg/Float64MultiArray', '', STREAM_DEPTH, False,
    'every scale sample (replay only)',
    'one message per processed frame, at its stamp: data = [person, scale, source, accepted] per '
    'person, scale in metres per SLAM unit (NaN when rejected), source 0 = map hit, 1 = '
    'ground-plane fallback, 2 = rejected', node=False)

# in the order the node creates its publishers and the replay its connections
TOPICS = (ODOMETRY, POSE, HUMAN_JOINTS, SCALE, CLOUD, OBSTACLES, MARKERS, DIAGNOSTICS, SAMPLES)
NODE_TOPICS = tuple(topic for topic in TOPICS if topic.node)
BY_KEY = {topic.key: topic for topic in TOPICS}
BY_NAME = {topic.name: topic for topic in TOPICS}
# not a topic of the table: the transforms go out through tf2_ros' broadcaster
TF_ROW = ('| `/tf` (`publish_tf`, `publish_odom_tf`) | | | tf2_ros\'s | when tf2_ros is '
          'importable: `metric_frame` → `odom_frame` (the correction that composes '
          '`hac/odometry` into `hac/pose`; leave it off when an EKF publishes map → odom) and '
          '`odom_frame` → the child frame. The replay writes no TF |')


def in_root(topic: str) -> str:
    """A topic name resolved in the root namespace (``hac/pose`` -> ``/hac/pose``), as the replay
    writes and reads it; absolute names are kept. ``~`` (private) names have no meaning there."""
    if topic.startswith('~'):
        raise ValueError(f'{topic!r}: a private (~) topic name needs a node')
    return topic if topic.startswith('/') else '/' + topic


def _short_type(msgtype: str) -> str:
    package, _, name = msgtype.split('/')
    return f'{package}/{name}'


def _frame_cell(topic: OutputTopic) -> str:
    if not topic.frame:
        return ''
    return f'`{topic.frame}` (`{getattr(HacParams(), topic.frame)}`)'


def markdown_table() -> str:
    """docs/interface.md's table of the node's outputs (between its ``outputs`` markers)."""
    rows = ['| topic | type | frame | QoS | what it carries |', '| --- | --- | --- | --- | --- |']
    for t in NODE_TOPICS:
        switches = f' ({", ".join(f"`{s}`" for s in t.switches)})' if t.switches else ''
        rows.append(f'| `{t.name}`{switches} | `{_short_type(t.msgtype)}` | {_frame_cell(t)} '
                    f'| {t.qos_text()} | {t.detail} |')
    return '\n'.join([*rows, TF_ROW]) + '\n'


def qos_rows() -> str:
    """The outputs' rows of docs/node.md's QoS table (hac_ros.ros.qos.qos_table): the topics
    with the same QoS on one row."""
    groups: dict[str, list[str]] = {}
    for t in NODE_TOPICS:
        groups.setdefault(t.qos_text(), []).append(f'`{t.name}`')
    return ''.join(f'| out | {", ".join(names)} | {qos} |\n' for qos, names in groups.items())


def _in_words(code: str, with_sep: str) -> str:
    """The node's outputs, each with its summary and the switches off by default; names wrapped
    in ``code`` (a backtick in markdown), each switch after ``with_sep``."""
    defaults = HacParams()
    return ', '.join(
        f'{code}{t.name}{code} ({t.summary}' + ''.join(
            f'{with_sep}with {code}{s}{code}' for s in t.switches if not getattr(defaults, s))
        + ')' for t in NODE_TOPICS)


def names_line() -> str:
    """The node's outputs in words, for ``--help``."""
    return _in_words('', '; ')


def readme_outputs() -> str:
    """README's outputs sentence (between its ``outputs`` markers)."""
    return f"Outputs: {_in_words('`', ', ')}; services `~/reset`, `~/freeze`.\n"
