"""What hac_node pays once, at start-up, so that no input frame pays it.

rosbags generates the CDR serializer of a message type the first time one is serialized (it
compiles Python source for every nested type: 1-12 ms per type, 35 ms for hac_node's eight output
types on a 2-core machine), and msg_adapters builds its numpy dtypes on first use. Left to the
first output of each type, all of it fell on the frame at which the estimate first converged
(the first /hac/human_joints, /hac/scale, /hac/markers, then /hac/odometry, /hac/pose and
/hac/cloud): 45-60 ms of CPU in one frame, over 100 ms of wall time on a loaded machine, while
``joints_backlog_max`` (2) lets 66 ms of joints wait at 30 Hz, so the frames behind it were
dropped at 1x (issue 36). :func:`warm_outputs` converts one message of every output type with a
throwaway converter when the node is configured, before any input can arrive.
"""
from __future__ import annotations

import numpy as np

from hac_ros.bridge.messages import OutputMessages
from hac_ros.core.basics.outputs import (
    CloudOut,
    DiagnosticsOut,
    HumanJointsOut,
    OdometryOut,
    Output,
    PoseOut,
    ScaleOut,
    Status,
)
from hac_ros.core.rules.params import HacParams


def warm_outputs(params: HacParams) -> int:
    """Serialize one message of every output type with ``params`` (a throwaway converter: the
    node's own keeps no trace of it). Returns the number of messages made."""
    converter = OutputMessages(params.replace(publish_obstacles=True, publish_markers=True))
    layout = params.layout()
    eye, zero3, zero6 = np.eye(3), np.zeros(3), np.zeros((6, 6))
    people = np.zeros((1, layout.joints_per_person, 3))
    status = Status(stamp_ns=0, converged=True, scale=1.0, spread=0.0, samples=0, frames=0,
                    people=0, map_hits=0, ground_fallbacks=0, resets=0,
                    ground_normal_metric=np.array([0.0, 0.0, -1.0]), ground_point_metric=zero3)
    outputs: list[Output] = [
        OdometryOut(0, '', eye, zero3, zero6, zero3, zero3, zero6),
        PoseOut(0, '', eye, zero3, zero6),
        HumanJointsOut(0, people),
        ScaleOut(0, 1.0, 0.0),
        CloudOut(0, np.zeros((2, 3), np.float32), levelled=True),
        DiagnosticsOut(status),
    ]
    return sum(len(converter.convert(output)) for output in outputs)
