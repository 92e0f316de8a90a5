"""The QoS of hac_node's subscriptions and publishers (docs/node.md, "Topics"), and what to tell a
user whose publisher does not match."""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from hac_ros.bridge.messages import DIAGNOSTICS, LATCHED_TOPICS
from hac_ros.core.params import HacParams

INPUT_DEPTH = 100  # joints/camera_info kept per subscription: > 3 s at 30 Hz, absorbs bursts
POSE_DEPTH = 1000  # SLAM poses: 1 s at 1 kHz (a message costs the executor ~0.1 ms to take)
CLOUD_DEPTH = 2  # only the newest map matters; 2 lets one arrive while the previous is read
OUTPUT_DEPTH = 100  # odometry/pose/joints/scale/markers: 3 s at 30 Hz for slow subscribers
DIAGNOSTICS_DEPTH = 10


def input_qos(params: HacParams, kind: str = 'joints') -> QoSProfile:
    """Pose, joints and CameraInfo (``kind``): best effort (matches every publisher) or
    reliable; a pose stream may come at 1 kHz, so its queue is deeper."""
    reliability = (ReliabilityPolicy.RELIABLE if params.input_qos == 'reliable'
                   else ReliabilityPolicy.BEST_EFFORT)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST,
                      depth=POSE_DEPTH if kind == 'pose' else INPUT_DEPTH,
                      reliability=reliability, durability=DurabilityPolicy.VOLATILE)


def cloud_qos(params: HacParams) -> QoSProfile:
    """The map: reliable; transient_local receives a map latched before the node started."""
    durability = (DurabilityPolicy.TRANSIENT_LOCAL if params.cloud_qos == 'transient_local'
                  else DurabilityPolicy.VOLATILE)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=CLOUD_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE, durability=durability)


def output_qos(topic: str) -> QoSProfile:
    """Outputs: reliable; /hac/cloud and /hac/obstacles also transient local (a late subscriber
    gets the map)."""
    if topic in LATCHED_TOPICS:
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST,
                      depth=DIAGNOSTICS_DEPTH if topic == DIAGNOSTICS[0] else OUTPUT_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


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
