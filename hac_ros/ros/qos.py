"""The QoS of hac_node's subscriptions and publishers (docs/node.md, "Topics"), and what to tell a
user whose publisher does not match."""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from hac_ros.bridge.topics import BY_NAME, qos_rows
from hac_ros.core.rules.params import CloudQos, HacParams, InputQos

INPUT_DEPTH = 100  # joints/camera_info kept per subscription: > 3 s at 30 Hz, absorbs bursts
POSE_DEPTH = 1000  # SLAM poses: 1 s at 1 kHz (a message costs the executor ~0.1 ms to take)
CLOUD_DEPTH = 2  # only the newest map matters; 2 lets one arrive while the previous is read


def input_qos(params: HacParams, kind: str = 'joints') -> QoSProfile:
    """Pose, joints and CameraInfo (``kind``): best effort (matches every publisher) or
    reliable; a pose stream may come at 1 kHz, so its queue is deeper."""
    reliability = (ReliabilityPolicy.RELIABLE if params.input_qos == InputQos.RELIABLE
                   else ReliabilityPolicy.BEST_EFFORT)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST,
                      depth=POSE_DEPTH if kind == 'pose' else INPUT_DEPTH,
                      reliability=reliability, durability=DurabilityPolicy.VOLATILE)


def cloud_qos(params: HacParams) -> QoSProfile:
    """The map: reliable; transient_local receives a map latched before the node started."""
    durability = (DurabilityPolicy.TRANSIENT_LOCAL if params.cloud_qos == CloudQos.TRANSIENT_LOCAL
                  else DurabilityPolicy.VOLATILE)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=CLOUD_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE, durability=durability)


def output_qos(topic: str) -> QoSProfile:
    """Output ``topic`` (its name in :mod:`hac_ros.bridge.topics`): reliable, its depth, and
    transient local when it is latched (/hac/cloud, /hac/obstacles: a late subscriber gets the
    map)."""
    entry = BY_NAME[topic]
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=entry.depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=(DurabilityPolicy.TRANSIENT_LOCAL if entry.latched
                                  else DurabilityPolicy.VOLATILE))


def qos_table() -> str:
    """docs/node.md's table of the node's QoS (between its ``qos`` markers): the subscriptions'
    from the depths above, the outputs' from :mod:`hac_ros.bridge.topics`."""
    return (
        '| direction | topic (default) | QoS |\n|---|---|---|\n'
        f'| in | `pose_topic` `slam/pose` | `input_qos`, keep last {POSE_DEPTH} |\n'
        '| in | `joints_topic` `hmr/joints`, `camera_info_topic` `camera/camera_info` | '
        f'`input_qos`, keep last {INPUT_DEPTH} |\n'
        '| in | `cloud_topic` `slam/cloud` (read raw, see below) | reliable, `cloud_qos`, keep '
        f'last {CLOUD_DEPTH} |\n'
        '| in | `/tf`, `/tf_static` (with `pose_source: tf`, instead of `pose_topic`) | tf2_ros\' '
        "listener's |\n"
        + qos_rows()
        + "| out | `/tf` (optional) | tf2_ros's |\n"
        '| service | `~/reset` (`std_srvs/Trigger`), `~/freeze` (`std_srvs/SetBool`) | |\n')


def qos_hint(kind: str, policy: str) -> str:
    """What the user can change when a publisher's QoS does not match subscription ``kind``."""
    if kind == 'cloud' and policy == 'DURABILITY':
        return ("the map publisher is volatile: set parameter cloud_qos to 'volatile' "
                '(or latch the map with transient_local on the publisher)')
    if kind == 'cloud' and policy == 'RELIABILITY':
        return 'the map publisher is best effort: hac_node needs a reliable map publisher'
    if policy == 'RELIABILITY':
        return "the publisher is best effort: set parameter input_qos to 'best_effort'"
    return f'change the publisher\'s {policy} policy (input_qos/cloud_qos cannot match it)'
