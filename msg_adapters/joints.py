"""``geometry_msgs/PoseArray`` ↔ joints (P, K, 3): consecutive blocks of K joints, one per person
(K = the joint layout's joints per person; SMPL-24 by default).

Positions only, metres, in the message's frame (the camera optical frame for HMR input, the metric
world for output); orientations are ignored on input and identity on output.
"""
from __future__ import annotations

import operator
from typing import Any

import numpy as np

from msg_adapters.errors import MessageError
from msg_adapters.stamps import make_header
from msg_adapters.types import MessageTypes

JOINTS_PER_PERSON = 24  # SMPL-24, the default joint layout
_POSITION = operator.attrgetter('position.x', 'position.y', 'position.z')  # one C call per pose


def pose_array_to_joints(msg: Any, joints_per_person: int = JOINTS_PER_PERSON) -> np.ndarray:
    """PoseArray → (P, joints_per_person, 3) float64, metres, ``msg.header.frame_id``.

    Zero poses → shape (0, joints_per_person, 3). Non-finite values pass through (the core counts
    them); MessageError when the number of poses is not a multiple of ``joints_per_person``.
    """
    if not isinstance(joints_per_person, int) or joints_per_person <= 0:
        raise MessageError(f'PoseArray: joints_per_person must be a positive int, got '
                           f'{joints_per_person!r}')
    try:
        poses = msg.poses
        n = len(poses)
    except (AttributeError, TypeError) as exc:
        raise MessageError(f'PoseArray: expected a poses sequence ({exc})') from exc
    if n % joints_per_person:
        raise MessageError(f'PoseArray: {n} poses is not a multiple of {joints_per_person} '
                           '(one block of joints per person)')
    try:
        flat = np.array(list(map(_POSITION, poses)), dtype=float).reshape(n, 3)
    except (AttributeError, TypeError, ValueError) as exc:
        raise MessageError(f'PoseArray: every pose needs a numeric position x, y, z '
                           f'({exc})') from exc
    return flat.reshape(n // joints_per_person, joints_per_person, 3)


def joints_to_pose_array(joints: np.ndarray, stamp_ns: int, frame_id: str,
                         types: MessageTypes) -> Any:
    """Joints (P, K, 3) or one person (K, 3), metres, ``frame_id`` → PoseArray (identity
    orientations).

    Non-finite values are written as they are.
    """
    try:
        joints = np.asarray(joints, dtype=float)
    except (TypeError, ValueError) as exc:
        raise MessageError(f'joints_to_pose_array: joints must be numbers ({exc})') from exc
    if joints.ndim == 2:
        joints = joints[None]
    if joints.ndim != 3 or joints.shape[2] != 3 or (len(joints) and not joints.shape[1]):
        raise MessageError(f'joints_to_pose_array: expected (P, K, 3) or (K, 3), got shape '
                           f'{joints.shape}')
    Pose = types.get('geometry_msgs/msg/Pose')
    positions = joints.reshape(-1, 3).tolist()  # Python floats (rclpy refuses numpy scalars)
    if types.is_rosbags:  # dataclasses: every field given
        Point, Quaternion = (types.get('geometry_msgs/msg/Point'),
                             types.get('geometry_msgs/msg/Quaternion'))
        poses = [Pose(position=Point(x=x, y=y, z=z),
                      orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))
                 for x, y, z in positions]
    else:  # rclpy: Pose() is already identity (Quaternion.msg: w default 1); twice as fast
        poses = [_rclpy_pose(Pose(), x, y, z) for x, y, z in positions]
    return types.get('geometry_msgs/msg/PoseArray')(header=make_header(stamp_ns, frame_id, types),
                                                    poses=poses)


def _rclpy_pose(pose: Any, x: float, y: float, z: float) -> Any:
    """Set the position of a default-constructed rclpy Pose (orientation identity) and return it."""
    position = pose.position
    position.x, position.y, position.z = x, y, z
    return pose
