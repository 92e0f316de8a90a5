"""``geometry_msgs/PoseArray`` ↔ joints (P, 24, 3): SMPL-24 blocks of 24 poses per person.

Positions only (metres, in the message's frame: the camera optical frame for HMR input, the metric
world for output); orientations are ignored on input and identity on output.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from msg_adapters.errors import MessageError
from msg_adapters.stamps import make_header
from msg_adapters.types import MessageTypes

JOINTS_PER_PERSON = 24


def pose_array_to_joints(msg: Any, joints_per_person: int = JOINTS_PER_PERSON) -> np.ndarray:
    """PoseArray → (P, 24, 3) float64. Non-finite values pass through (the core counts them)."""
    try:
        poses = msg.poses
        n = len(poses)
        if n % joints_per_person:
            raise MessageError(f'PoseArray: {n} poses is not a multiple of {joints_per_person} '
                               '(one block of joints per person)')
        flat = np.array([(p.position.x, p.position.y, p.position.z) for p in poses], dtype=float)
    except MessageError:
        raise
    except (AttributeError, TypeError, ValueError) as exc:
        raise MessageError(f'PoseArray: poses without positions ({exc})') from exc
    return flat.reshape(-1, joints_per_person, 3)


def joints_to_pose_array(joints: np.ndarray, stamp_ns: int, frame_id: str,
                         types: MessageTypes) -> Any:
    """(P, 24, 3) or (24, 3) joints, metres → PoseArray (identity orientations)."""
    joints = np.asarray(joints, dtype=float)
    if joints.ndim == 2:
        joints = joints[None]
    if joints.ndim != 3 or joints.shape[2] != 3:
        raise MessageError(f'joints_to_pose_array: expected (P, 24, 3), got {joints.shape}')
    Pose, Point, Quaternion = (types.get('geometry_msgs/msg/Pose'), types.get('geometry_msgs/msg/Point'),
                               types.get('geometry_msgs/msg/Quaternion'))
    poses = [Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))
             for x, y, z in joints.reshape(-1, 3).tolist()]
    return types.get('geometry_msgs/msg/PoseArray')(header=make_header(stamp_ns, frame_id, types),
                                                    poses=poses)
