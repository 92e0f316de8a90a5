"""Write a :class:`Scenario` as a rosbag2 recording (sqlite3 or mcap) with hac_ros' topics.

Inputs: /slam/pose (PoseStamped or Odometry), /slam/cloud, /hmr/joints, /camera/camera_info;
ground truth: /gt/camera_pose, /gt/human_joints, /gt/scale. Every message is logged at its
header stamp (/gt/scale, which has none, at the stamp of the pose it belongs to); at one stamp the
map comes first, then the pose, the camera info, the joints, the ground truth.

The SLAM pose as different wrappers report it, for the tests of ``pose_to_optical`` and
``pose_source``: ``pose_frame='base'`` reports the pose of a robot base (x forward, z up) whose
camera stands 1.2 above and 0.3 ahead of it (:data:`BASE_TO_OPTICAL`), composed as a wrapper
composes its extrinsic with a monocular trajectory: pose_base = pose_camera · T⁻¹, the translation
taken in SLAM units; ``pose_source='tf'`` writes no /slam/pose but ``tf2_msgs/msg/TFMessage`` on
/tf (the map frame → the camera or the base, at every pose stamp) and, for the base, the static
base → camera optical transform on /tf_static (latched, at the first stamp).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from hac_ros.core.basics.errors import HacError
from hac_ros.core.bodies.conventions import optical_transform
from hac_ros.core.layouts import BUILT_IN
from hac_ros.core.rules.params import POSE_MSGTYPES, PoseSource, PoseType
from hac_ros.recording.atomic import staged_output
from hac_ros.recording.reader import layout_data
from hac_ros.recording.writer import OutputWriter
from msg_adapters import (
    intrinsics_to_camera_info,
    joints_to_pose_array,
    rosbags_types,
    rt_to_odometry,
    rt_to_pose_stamped,
    rt_to_transform_stamped,
    xyz_to_cloud,
)

TOPICS = {
    '/slam/cloud': 'sensor_msgs/msg/PointCloud2',
    '/tf_static': 'tf2_msgs/msg/TFMessage',  # pose_source tf
    '/slam/pose': None,  # by pose_type
    '/tf': 'tf2_msgs/msg/TFMessage',  # pose_source tf
    '/camera/camera_info': 'sensor_msgs/msg/CameraInfo',
    '/hmr/joints': 'geometry_msgs/msg/PoseArray',
    '/gt/camera_pose': 'geometry_msgs/msg/PoseStamped',
    '/gt/human_joints': 'geometry_msgs/msg/PoseArray',
    '/gt/scale': 'std_msgs/msg/Float64',
}
ORDER = {topic: k for k, topic in enumerate(TOPICS)}
POSE_FRAMES = ('optical', 'base')
POSE_SOURCES = ('topic', 'tf')
# the camera optical frame in the base frame (x forward, z up): 0.3 ahead, 1.2 above, looking
# forward; x y z qx qy qz qw, as pose_to_optical takes it
BASE_TO_OPTICAL = [0.3, 0.0, 1.2, -0.5, 0.5, -0.5, 0.5]
BASE_FRAME = 'base_link'


def write_recording(sc: Any, out_path: str | Path, storage: str = 'mcap',
                    pose_type: str = 'PoseStamped', pose_frame: str = 'optical',
                    pose_source: str = 'topic') -> Path:
    """Write ``sc`` to a new recording at ``out_path`` (refused if the path exists; it appears
    whole or not at all). storage: ``mcap`` or ``sqlite3``; pose_type: ``PoseStamped`` or
    ``Odometry``; pose_frame: ``optical`` or ``base``, pose_source: ``topic`` or ``tf`` (module
    docstring)."""
    out = Path(out_path)
    if out.exists():
        raise HacError(f'{out} exists: refusing to overwrite it')
    if pose_type not in POSE_MSGTYPES:
        raise HacError(f'pose type must be one of {", ".join(POSE_MSGTYPES)}, got {pose_type!r}')
    if pose_frame not in POSE_FRAMES:
        raise HacError(f'pose frame must be one of {", ".join(POSE_FRAMES)}, got {pose_frame!r}')
    if pose_source not in POSE_SOURCES:
        raise HacError(f'pose source must be one of {", ".join(POSE_SOURCES)}, got '
                       f'{pose_source!r}')
    types = rosbags_types()
    pose_msgtype = POSE_MSGTYPES[pose_type]
    base = optical_transform(BASE_TO_OPTICAL) if pose_frame == 'base' else None
    child = BASE_FRAME if base is not None else sc.camera_frame
    tf_message = types.get(TOPICS['/tf'] or '')
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
        if base is not None:  # pose_base = pose_camera · T⁻¹, T's translation in SLAM units
            R_bo, t_bo = base
            R = R @ R_bo.T
            c = c - R @ t_bo
        if pose_source == PoseSource.TF:
            add(stamp, '/tf', tf_message(transforms=[
                rt_to_transform_stamped(R, c, stamp, frame, child, types)]))
            if base is not None and i == 0:
                add(stamp, '/tf_static', tf_message(transforms=[
                    rt_to_transform_stamped(*base, stamp, BASE_FRAME, sc.camera_frame, types)]))
        elif pose_type == PoseType.ODOMETRY:
            add(stamp, '/slam/pose', rt_to_odometry(R, c, stamp, frame, child, types))
        else:
            add(stamp, '/slam/pose', rt_to_pose_stamped(R, c, stamp, frame, types))
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
            used = {m[2] for m in messages}
            for topic, msgtype in TOPICS.items():
                if topic in used or topic not in ('/tf', '/tf_static', '/slam/pose'):
                    writer.connection(topic, msgtype or pose_msgtype,
                                      latched=topic == '/tf_static')
            for stamp, _, topic, msgtype, msg in messages:
                writer.write(topic, msgtype, stamp, writer.typestore.serialize_cdr(msg, msgtype))
        finally:
            writer.close()
    return out
