"""A fixed camera (``static_camera``): no SLAM pose, no map; people walking on the floor tell its
height above the floor in metres, its pitch and roll (docs/method.md, "A fixed camera")."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scenes import STANDING, look_at
from test_node import Event, harness, wait_for  # noqa: F401 (harness: a fixture)

from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import DiagnosticsOut, HumanJointsOut, ScaleOut
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.rules.params import HacParams
from hac_ros.core.rules.reasons import REASONS

HEIGHT_M, PITCH_DEG, ROLL_DEG = 3.0, math.degrees(math.atan2(3.0, 8.0)), 10.0
K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])


def static_scene(seconds: float = 20.0, rate: float = 10.0, sizes=(1.0, 1.0, 1.0), seed: int = 0
                 ) -> list[tuple[int, np.ndarray]]:
    """Three SMPL-24 people walking to and fro across a floor (z = 0), each along a heading of
    their own, in view of a camera HEIGHT_M up,
    looking 8 m ahead (PITCH_DEG down) and rolled ROLL_DEG: (stamp ns, joints (3, 24, 3) metres,
    camera optical frame) per frame. ``sizes``: each person's size against the model's (their
    depth error), with 1 % jitter per frame."""
    rng = np.random.default_rng(seed)
    camera = np.array([0.0, -6.0, HEIGHT_M])
    roll = math.radians(ROLL_DEG)
    R = look_at(camera, np.array([0.0, 2.0, 0.0])) @ np.array(
        [[math.cos(roll), -math.sin(roll), 0.0], [math.sin(roll), math.cos(roll), 0.0],
         [0.0, 0.0, 1.0]])  # camera to world, rolled about the optical axis
    frames = []
    for i in range(int(seconds * rate)):
        t = i / rate
        people = []
        for k, (heading, speed, phase) in enumerate(((0.0, 0.8, 0.0), (2.1, 0.6, 3.0),
                                                      (4.2, 0.5, 6.0))):
            # each walks to and fro across the square (x in [-3, 3], y in [0, 6]) along a
            # heading of its own, turning at the ends
            along = (speed * t + phase) % 12.0
            along = along if along < 6.0 else 12.0 - along
            x, y = (along - 3.0) * math.cos(heading), 3.0 + (along - 3.0) * math.sin(heading)
            body = STANDING + [x, y, 0.0]
            if i % 2:
                body[10 + k % 2] += [0.0, 0.0, 0.08]  # a swinging foot
            people.append(((body - camera) @ R) * sizes[k] * (1 + rng.normal(0.0, 0.01)))
        frames.append((NS + int(t * NS), np.stack(people)))
    return frames


def run(frames, **params) -> tuple[Calibrator, list]:
    cal = Calibrator(HacParams(**params))
    cal.add_camera_info(K, 640, 480)
    outs = []
    for stamp, joints in frames:
        outs += cal.add_joints(stamp, joints, 'camera')
    return cal, outs + cal.flush()


def last_status(outs):
    return [o for o in outs if isinstance(o, DiagnosticsOut)][-1].status


def true_down_cam() -> np.ndarray:
    """Down (3,) in the camera optical frame of static_scene's camera."""
    R = look_at(np.array([0.0, -6.0, HEIGHT_M]), np.array([0.0, 2.0, 0.0]))
    roll = math.radians(ROLL_DEG)
    R = R @ np.array([[math.cos(roll), -math.sin(roll), 0.0],
                      [math.sin(roll), math.cos(roll), 0.0], [0.0, 0.0, 1.0]])
    return R.T @ np.array([0.0, 0.0, -1.0])


def test_a_fixed_camera_without_slam_or_map_gives_its_height_pitch_and_roll():
    frames = static_scene()
    cal, outs = run(frames, static_camera=True)
    status = last_status(outs)
    assert status.converged and cal.rejected['slam_frozen'] == 0
    assert 'slam_frozen' not in status.conditions
    # the floor one SLAM unit below the camera: the scale is its height in metres
    assert status.scale == pytest.approx(HEIGHT_M, rel=0.02)
    assert status.camera_height_m == status.scale
    assert status.camera_pitch_deg == pytest.approx(PITCH_DEG, abs=1.0)
    assert status.camera_roll_deg == pytest.approx(ROLL_DEG, abs=1.0)
    # the people in the gravity-aligned metric frame, standing on its floor
    humans = [o for o in outs if isinstance(o, HumanJointsOut)]
    assert humans and [o for o in outs if isinstance(o, ScaleOut)]
    n, point = status.ground_normal_metric, status.ground_point_metric
    placed = [min(float(n @ (j - point)) for j in person[[10, 11]]) for o in humans
              for person in o.joints_metric]  # each person's lower foot along down (< 0: above)
    down = true_down_cam()
    truth = [min(float(down @ j) for j in person[[10, 11]]) - HEIGHT_M for _, people in frames
             for person in people]  # the same on the true floor
    assert np.median(placed) == pytest.approx(np.median(truth), abs=0.03)


def test_people_of_other_sizes_read_the_height_as_much_off_and_the_spread_says_so():
    _, outs = run(static_scene(sizes=(1.04, 0.97, 1.01), seed=1), static_camera=True)
    status = last_status(outs)
    assert status.camera_height_m == pytest.approx(HEIGHT_M * 1.01, rel=0.02)
    assert status.spread / status.scale >= 0.03  # the layout's prior for the people's sizes


def test_constant_poses_of_a_fixed_camera_are_taken_not_frozen():
    frames = static_scene(seconds=10.0)
    cal = Calibrator(HacParams(static_camera=True))
    outs = []
    for stamp, joints in frames:
        outs += cal.add_pose(stamp, np.eye(3), np.zeros(3), 'map')
        outs += cal.add_joints(stamp, joints, 'camera')
    outs += cal.flush()
    assert cal.rejected['slam_frozen'] == 0
    assert last_status(outs).camera_height_m == pytest.approx(HEIGHT_M, rel=0.02)
    # without the parameter the same input is a frozen SLAM, and the advice names it
    cal = Calibrator(HacParams())
    for stamp, joints in frames:
        cal.add_pose(stamp, np.eye(3), np.zeros(3), 'map')
        cal.add_joints(stamp, joints, 'camera')
    cal.flush()
    assert cal.rejected['slam_frozen'] > 0
    assert 'static_camera' in REASONS['slam_frozen'].remedy


def test_with_a_map_in_slam_units_it_gives_the_maps_scale_too():
    """A floor map of the fixed camera in units of 0.5 m (an SfM of the empty scene): the scale
    is 2 m per unit, and the camera's height still 3 m."""
    frames = static_scene()
    R = look_at(np.array([0.0, -6.0, HEIGHT_M]), np.array([0.0, 2.0, 0.0]))
    roll = math.radians(ROLL_DEG)
    R = R @ np.array([[math.cos(roll), -math.sin(roll), 0.0],
                      [math.sin(roll), math.cos(roll), 0.0], [0.0, 0.0, 1.0]])
    assert np.allclose(R.T @ [0.0, 0.0, -1.0], true_down_cam())
    x, y = np.meshgrid(np.arange(-5.0, 5.0, 0.05), np.arange(-2.0, 9.0, 0.05))
    floor_world = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    floor_cam = (floor_world - [0.0, -6.0, HEIGHT_M]) @ R  # metres, camera frame = map frame
    cal = Calibrator(HacParams(static_camera=True))
    cal.add_camera_info(K, 640, 480)
    outs = cal.add_map(frames[0][0] - 1, floor_cam / 2.0, 'map')
    for stamp, joints in frames:
        outs += cal.add_joints(stamp, joints, 'camera')
    outs += cal.flush()
    status = last_status(outs)
    assert cal.rejected['slam_frozen'] == 0 and cal.map_hits > 0
    assert status.scale == pytest.approx(2.0, rel=0.01)
    assert status.camera_height_m == pytest.approx(HEIGHT_M, rel=0.01)


def test_hac_replay_of_a_fixed_camera_recording_without_poses(tmp_path):
    """A recording of joints and CameraInfo only (a camera on a tripod, no SLAM): replayed with
    static_camera, it converges on the camera's height; its /diagnostics say it."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from hac_ros.recording.reader import Recording
    from hac_ros.replay.replayer import replay
    from msg_adapters import intrinsics_to_camera_info, joints_to_pose_array, rosbags_types

    typestore, types = get_typestore(Stores.ROS2_JAZZY), rosbags_types()
    source = tmp_path / 'tripod'
    writer = Writer(source, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    joints = writer.add_connection('/hmr/joints', 'geometry_msgs/msg/PoseArray',
                                   typestore=typestore)
    info = writer.add_connection('/camera/camera_info', 'sensor_msgs/msg/CameraInfo',
                                 typestore=typestore)
    frames = static_scene()
    writer.write(info, frames[0][0] - 1, typestore.serialize_cdr(intrinsics_to_camera_info(
        K, 640, 480, frames[0][0] - 1, 'camera', types), 'sensor_msgs/msg/CameraInfo'))
    for stamp, people in frames:
        writer.write(joints, stamp, typestore.serialize_cdr(joints_to_pose_array(
            people, stamp, 'camera', types), 'geometry_msgs/msg/PoseArray'))
    writer.close()
    summary = replay(source, tmp_path / 'out', HacParams(static_camera=True))
    assert summary.calibrated and summary.status.rejected.get('slam_frozen', 0) == 0
    assert summary.final_scale == pytest.approx(HEIGHT_M, rel=0.02)
    with Recording(tmp_path / 'out') as out:
        values = {kv.key: kv.value for kv in out.read('/diagnostics')[-1][1].status[0].values}
    assert float(values["camera_height_m"]) == pytest.approx(HEIGHT_M, rel=0.02)
    assert float(values["camera_roll_deg"]) == pytest.approx(ROLL_DEG, abs=1.0)


def test_hac_node_over_dds_with_joints_alone(harness):
    """hac_node with static_camera, fed joints and CameraInfo only over DDS (no SLAM, no map):
    it converges on the camera's height, its /diagnostics name it and never ask for a pose."""
    from msg_adapters import intrinsics_to_camera_info, joints_to_pose_array, rclpy_types

    types = rclpy_types()
    h = harness(static_camera=True, input_qos='reliable', stale_after_s=60.0)
    frames = static_scene(seconds=10.0)
    events = [Event(frames[0][0] - 1, 'camera_info', intrinsics_to_camera_info(
        K, 640, 480, frames[0][0] - 1, 'camera', types))]
    events += [Event(stamp, 'joints', joints_to_pose_array(people, stamp, 'camera', types))
               for stamp, people in frames]
    h.play(events, frame_period_s=0.02)
    # /diagnostics go out once per second of stamp time: the last second's frames are not in it
    assert wait_for(lambda: h.received['/diagnostics'] and float(
        h.diagnostics().get('frames', 0)) >= len(frames) - 10, 60.0), 'hac_node did not catch up'
    values = h.diagnostics()
    assert values['converged'] == 'true' and 'rejected.slam_frozen' not in values
    assert 'no_poses' not in values['reasons']
    assert float(values["camera_height_m"]) == pytest.approx(HEIGHT_M, rel=0.02)
    assert h.scales()[-1] == pytest.approx(HEIGHT_M, rel=0.02)
