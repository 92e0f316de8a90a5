"""Write a :class:`Scenario` as a rosbag2 recording (sqlite3 or mcap) with hac_ros' topics.

Inputs: /slam/pose (PoseStamped or Odometry), /slam/cloud, /hmr/joints, /camera/camera_info;
ground truth: /gt/camera_pose, /gt/human_joints, /gt/scale. Every message is logged at its
header stamp (/gt/scale, which has none, at the stamp of the pose it belongs to); at one stamp the
map comes first, then the pose, the camera info, the joints, the ground truth.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from hac_ros.core.errors import HacError
from hac_ros.core.layouts import BUILT_IN
from hac_ros.core.params import POSE_MSGTYPES
from hac_ros.recording.atomic import staged_output
from hac_ros.recording.reader import layout_data
from hac_ros.recording.writer import OutputWriter
from msg_adapters import (
    intrinsics_to_camera_info,
    joints_to_pose_array,
    rosbags_types,
    rt_to_odometry,
    rt_to_pose_stamped,
    xyz_to_cloud,
)

TOPICS = {
    '/slam/cloud': 'sensor_msgs/msg/PointCloud2',
    '/slam/pose': None,  # by pose_type
    '/camera/camera_info': 'sensor_msgs/msg/CameraInfo',
    '/hmr/joints': 'geometry_msgs/msg/PoseArray',
    '/gt/camera_pose': 'geometry_msgs/msg/PoseStamped',
    '/gt/human_joints': 'geometry_msgs/msg/PoseArray',
    '/gt/scale': 'std_msgs/msg/Float64',
}
ORDER = {topic: k for k, topic in enumerate(TOPICS)}


def write_recording(sc: Any, out_path: str | Path, storage: str = 'mcap',
                    pose_type: str = 'PoseStamped') -> Path:
    """Write ``sc`` to a new recording at ``out_path`` (refused if the path exists; it appears
    whole or not at all). storage: ``mcap`` or ``sqlite3``; pose_type: ``PoseStamped`` or
    ``Odometry``."""
    out = Path(out_path)
    if out.exists():
        raise HacError(f'{out} exists: refusing to overwrite it')
    if pose_type not in POSE_MSGTYPES:
        raise HacError(f'pose type must be one of {", ".join(POSE_MSGTYPES)}, got {pose_type!r}')
    types = rosbags_types()
    pose_msgtype = POSE_MSGTYPES[pose_type]
    messages: list[tuple[int, int, str, str, Any]] = []

    def add(stamp: int, topic: str, msg: Any) -> None:
        messages.append((int(stamp), ORDER[topic], topic, TOPICS[topic] or pose_msgtype, msg))

    for m in sc.maps:
        add(m.stamp_ns, '/slam/cloud',
            xyz_to_cloud(m.points_slam, m.stamp_ns, m.frame_id, types))
    last_scale = None
    for i, stamp in enumerate(sc.pose_stamps_ns):
        stamp = int(stamp)
        R, c, frame = sc.slam_R_wc[i], sc.slam_c[i], sc.slam_frame_ids[i]
        if pose_type == 'Odometry':
            msg = rt_to_odometry(R, c, stamp, frame, sc.camera_frame, types)
        else:
            msg = rt_to_pose_stamped(R, c, stamp, frame, types)
        add(stamp, '/slam/pose', msg)
        add(stamp, '/camera/camera_info',
            intrinsics_to_camera_info(sc.K, sc.width, sc.height, stamp, sc.camera_frame, types))
        add(stamp, '/gt/camera_pose',
            rt_to_pose_stamped(sc.gt_R_wc[i], sc.gt_c[i], stamp, sc.world_frame, types))
        scale = float(sc.true_scale[i])
        if last_scale is None or scale != last_scale:
            add(stamp, '/gt/scale',
                types.get('std_msgs/msg/Float64')(data=scale))
            last_scale = scale
    for k, stamp in enumerate(sc.joints_stamps_ns):
        stamp = int(stamp)
        add(stamp, '/hmr/joints',
            joints_to_pose_array(sc.joints_cam[k], stamp, sc.camera_frame, types))
        add(stamp, '/gt/human_joints',
            joints_to_pose_array(sc.gt_joints_world[k], stamp, sc.world_frame, types))
    messages.sort(key=lambda m: (m[0], m[1]))

    with staged_output(out) as staged:
        writer = OutputWriter(staged, storage, layout_data(BUILT_IN[sc.joint_layout]))
        try:
            for topic, msgtype in TOPICS.items():
                writer.connection(topic, msgtype or pose_msgtype)
            for stamp, _, topic, msgtype, msg in messages:
                writer.write(topic, msgtype, stamp, writer.typestore.serialize_cdr(msg, msgtype))
        finally:
            writer.close()
    return out
