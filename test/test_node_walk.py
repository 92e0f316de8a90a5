"""hac_node in-process on simulated walks, with the harness of test_node.py: it converges within
2 % with the outputs the core alone gives for the same stamps; bad input is counted, logged once
and survived; a SLAM reset re-converges without an odometry jump; runtime parameter changes
(valid, invalid, atomic) and every parameter's declaration; body-frame poses warned about; a
custom joint layout."""
from __future__ import annotations

from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.serialization import serialize_message
from test_node import (  # noqa: F401 (harness: a fixture)
    PATIENCE_S,
    SCALE_TOL,
    TEST_PARAMS,
    TYPES,
    Event,
    Recording,
    frames_after,
    harness,
    scenario_recording,
    wait_for,
)

from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import HumanJointsOut, OdometryOut, ScaleOut
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.rules.params import HacParams, describe, names
from msg_adapters import (
    cloud_to_xyz,
    joints_to_pose_array,
    pose_array_to_joints,
    pose_msg_to_rt,
    rt_to_pose_stamped,
    stamp_to_ns,
    xyz_to_cloud,
)


# ================================================================================ recordings
def core_outputs(events: list[Event], params: HacParams) -> list[Any]:
    """What the core alone makes of the same messages in the same order (the replay's view)."""
    calibrator = Calibrator(params)
    out: list[Any] = []
    for e in events:
        if e.kind == 'cloud':
            out += calibrator.add_map(e.stamp_ns, cloud_to_xyz(e.msg), e.msg.header.frame_id)
        elif e.kind == 'pose':
            R, c = pose_msg_to_rt(e.msg)
            out += calibrator.add_pose(e.stamp_ns, R, c, e.msg.header.frame_id)
        elif e.kind == 'joints':
            out += calibrator.add_joints(e.stamp_ns, pose_array_to_joints(e.msg),
                                         e.msg.header.frame_id)
    return out


@pytest.fixture(scope='module')
def walk() -> Recording:
    return scenario_recording('walk', duration=12.0)


# ================================================================================ tests
def test_walk_converges_and_outputs_arrive_for_the_expected_stamps(harness, walk):
    h = harness()
    h.play(walk.events)
    h.settle()
    scales = h.scales()
    assert scales, 'no /hac/scale published'
    true = walk.scale_at(int(walk.pose_stamps[-1]))
    assert abs(scales[-1] / true - 1.0) < SCALE_TOL

    # the core alone on the same messages: which stamps get odometry / joints, and their values
    expected = core_outputs(walk.events, h.node.params)
    core_odom = [o.stamp_ns for o in expected if isinstance(o, OdometryOut)]
    core_joints = [o.stamp_ns for o in expected if isinstance(o, HumanJointsOut)]
    core_scale = {o.stamp_ns: o.scale for o in expected if isinstance(o, ScaleOut)}
    node_odom, node_joints = h.stamps('/hac/odometry'), h.stamps('/hac/human_joints')
    assert node_odom == sorted(set(node_odom)), 'odometry stamps repeated or out of order'
    pose_stamps = [int(s) for s in walk.pose_stamps]
    first = pose_stamps.index(node_odom[0])
    # once converged, every SLAM pose has its odometry (the first may differ by one pose from
    # the core alone: the node may see a pose before the joints of the previous stamp)
    assert node_odom == pose_stamps[first:]
    assert abs(first - pose_stamps.index(core_odom[0])) <= 1
    joints_stamps = [int(s) for s in walk.joints_stamps]
    assert node_joints == joints_stamps[joints_stamps.index(node_joints[0]):]
    assert node_joints == core_joints
    node_scale = dict(zip(h.stamps('/hac/human_joints'), scales))
    worst = max(abs(node_scale[s] / core_scale[s] - 1.0) for s in core_joints)
    assert worst < 1e-3, f'node and core scales differ by {worst:.2e}'
    # the joints themselves are the core's, in the metric frame, same blocks
    last_msg = h.received['/hac/human_joints'][-1][1]
    assert last_msg.header.frame_id == 'map_metric'
    last_core = next(o for o in reversed(expected) if isinstance(o, HumanJointsOut))
    np.testing.assert_allclose(pose_array_to_joints(last_msg), last_core.joints_metric,
                               rtol=2e-3, atol=2e-3)
    odom = h.received['/hac/odometry'][-1][1]
    assert odom.header.frame_id == 'hac_odom' and odom.child_frame_id == walk.camera_frame
    diag = h.diagnostics()
    assert diag['converged'] == 'true' and 'rejected.internal_error' not in diag
    assert h.received['/hac/markers'], 'publish_markers is true by default'


def bad_cloud(kind: str, stamp_ns: int, frame_id: str) -> Any:
    """A PointCloud2 the adapters must refuse: wrong point_step, missing fields, short data."""
    msg = xyz_to_cloud(np.random.default_rng(0).random((50, 3)) + 1.0, stamp_ns, frame_id, TYPES)
    if kind == 'point_step':
        msg.point_step = 8  # z (offset 8) no longer fits in a point
        msg.row_step = 8 * msg.width
        del msg.data[8 * msg.width:]
    elif kind == 'fields':
        msg.fields = msg.fields[:2]  # no z
    elif kind == 'short':
        del msg.data[-5:]
    return msg


def test_bad_input_is_counted_logged_once_and_the_node_recovers(harness, walk):
    h = harness(publish_markers=False)
    cut = frames_after(walk, 0.3)
    h.play(walk.events[:cut])
    frame = next(e for e in walk.events[cut:] if e.kind == 'joints')
    pose = next(e for e in walk.events[:cut][::-1] if e.kind == 'pose')
    cloud = next(e for e in walk.events if e.kind == 'cloud')
    stamp = pose.stamp_ns
    J = pose_array_to_joints(frame.msg)
    R, c = pose_msg_to_rt(pose.msg)

    def joints(values: np.ndarray, stamp_ns: int, frame_id: str = walk.camera_frame) -> Event:
        return Event(stamp_ns, 'joints', joints_to_pose_array(values, stamp_ns, frame_id, TYPES))

    nan = J.copy()
    nan[0, 5] = np.nan  # a knee not seen: smpl24's contact may be any joint, so none is taken
    inf = J.copy()
    inf[0, 7, 2] = np.inf
    short = joints_to_pose_array(J, stamp + 1, walk.camera_frame, TYPES)
    short.poses = short.poses[:23]
    bad_quat = rt_to_pose_stamped(R, c, stamp + 2, pose.msg.header.frame_id, TYPES)
    bad_quat.pose.orientation.w = 3.0
    bad_stamp = joints_to_pose_array(J, stamp + 3, walk.camera_frame, TYPES)
    bad_stamp.header.stamp.nanosec = 1_500_000_000  # not a valid builtin_interfaces/Time
    bad = [
        Event(stamp, 'cloud', xyz_to_cloud(np.zeros((0, 3)), stamp, cloud.msg.header.frame_id,
                                           TYPES)),
        *[Event(stamp, 'cloud', bad_cloud(k, stamp, cloud.msg.header.frame_id))
          for k in ('point_step', 'fields', 'short')],
        Event(stamp - NS, 'pose', rt_to_pose_stamped(R, c, stamp - NS, pose.msg.header.frame_id,
                                                     TYPES)),  # out of order
        Event(stamp, 'pose', pose.msg),  # repeated
        Event(stamp + 1, 'joints', short),  # 23 poses
        Event(stamp + 2, 'pose', bad_quat),
        Event(stamp + 3, 'joints', bad_stamp),
        # bytes cut inside the header: published raw, they do not deserialize in the node
        Event(stamp + 4, 'pose', serialize_message(pose.msg)[:10]),
        Event(stamp + 5, 'joints', serialize_message(short)[:10]),
    ]
    h.play(bad)
    rest = walk.events[cut:]
    # within the rest: NaN and inf joints at real frames, joints in another frame, a repeated
    # joints stamp, and an isolated outlier pose (a jump and back)
    js = [i for i, e in enumerate(rest) if e.kind == 'joints']
    ps = [i for i, e in enumerate(rest) if e.kind == 'pose']
    extent = np.ptp(np.array([pose_msg_to_rt(e.msg)[1] for e in walk.events if e.kind == 'pose']),
                    axis=0).max()
    R5, c5 = pose_msg_to_rt(rest[ps[5]].msg)
    outlier_stamp = (rest[ps[5]].stamp_ns + rest[ps[6]].stamp_ns) // 2
    replaced = {
        js[2]: joints(nan, rest[js[2]].stamp_ns),
        js[4]: joints(inf, rest[js[4]].stamp_ns),
        js[8]: joints(J, rest[js[8]].stamp_ns, 'some_other_camera'),
    }
    inserted = {
        js[10]: joints(J, rest[js[10]].stamp_ns),  # the same stamp twice
        ps[5]: Event(outlier_stamp, 'pose', rt_to_pose_stamped(
            R5, c5 + 40.0 * extent, outlier_stamp, rest[ps[5]].msg.header.frame_id, TYPES)),
    }
    played = []
    for i, e in enumerate(rest):
        played.append(replaced.get(i, e))
        if i in inserted:
            played.append(inserted[i])
    h.play(played)
    h.settle()

    expected = {'cloud_empty': 1, 'cloud_malformed': 3, 'pose_out_of_order': 2,
                'joints_malformed': 2, 'joints_wrong_layout': 1, 'pose_nonfinite': 2,
                'nonfinite_joints': 1, 'contact_unseen': 1, 'joints_wrong_frame': 1,
                'late_frame': 1, 'pose_outlier': 1}
    diag = h.diagnostics()
    for reason, count in expected.items():
        assert int(diag.get(f'rejected.{reason}', 0)) == count, (reason, diag)
        assert h.node.notices[reason] == 1, f'{reason} logged {h.node.notices[reason]} times'
    assert 'rejected.internal_error' not in diag
    assert int(diag['resets']) == 0, 'an isolated outlier pose is not a reset'
    true = walk.scale_at(int(walk.pose_stamps[-1]))
    assert abs(h.scales()[-1] / true - 1.0) < SCALE_TOL
    # the outlier pose got no odometry, and the metric path has no jump
    assert outlier_stamp not in h.stamps('/hac/odometry')
    positions = np.array([[m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z]
                          for _, m in h.received['/hac/odometry']])
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    assert steps.max() < 10 * np.median(steps) + 1e-6


def test_slam_reset_reconverges_without_a_jump(harness):
    # 15 s after the re-initialisation: the core alone is within 1 % of the new scale by then
    rec = scenario_recording('reset', duration=30.0)
    h = harness(publish_markers=False)
    h.play(rec.events)
    h.settle()
    assert h.node.notices['reset'] >= 1
    assert int(h.diagnostics()['resets']) >= 1
    true = rec.scale_at(int(rec.pose_stamps[-1]))
    assert abs(h.scales()[-1] / true - 1.0) < SCALE_TOL
    odom = h.received['/hac/odometry']
    stamps = np.array([stamp_to_ns(m.header.stamp) for _, m in odom])
    positions = np.array([[m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z]
                          for _, m in odom])
    speeds = np.linalg.norm(np.diff(positions, axis=0), axis=1) / (np.diff(stamps) / NS)
    # the camera's metric speed stays a walking speed across the reset (no jump)
    poses = [e for e in rec.events if e.kind == 'pose']
    reset_stamp = next(e.stamp_ns for e in poses
                       if e.msg.header.frame_id != poses[0].msg.header.frame_id)
    assert stamps[0] < reset_stamp < stamps[-1], 'odometry published on both sides of the reset'
    assert speeds.max() < 5.0 * np.median(speeds) + 0.5, (speeds.max(), np.median(speeds))


def test_runtime_parameters(harness, walk):
    h = harness()
    cut = frames_after(walk, 0.35)
    h.play(walk.events[:cut])
    h.settle()
    assert h.scales(), 'converged before the parameter changes'
    client = AsyncParameterClient(h.io, 'hac_node')
    assert client.wait_for_services(timeout_sec=10.0)

    def set_atomically(**values: Any) -> Any:
        future = client.set_parameters_atomically([Parameter(k, value=v) for k, v in values.items()])
        assert wait_for(future.done, PATIENCE_S)
        return future.result().result

    # descriptors: description and range from params.py
    future = client.describe_parameters(['cone_angle_deg', 'contact_mode', 'min_samples'])
    assert wait_for(future.done, PATIENCE_S)
    cone, contact, min_samples = future.result().descriptors
    assert cone.floating_point_range[0].from_value == describe('cone_angle_deg')['low']
    assert cone.floating_point_range[0].to_value == describe('cone_angle_deg')['high']
    assert 'max_ratio' in contact.additional_constraints and contact.description
    assert min_samples.integer_range[0].from_value == describe('min_samples')['low']

    # invalid values are rejected with a reason, and nothing changes (all or nothing)
    calibrator = h.node.calibrator
    result = set_atomically(contact_mode='bogus')
    assert not result.successful and 'contact_mode' in result.reason
    result = set_atomically(cone_angle_deg=45.0)  # outside the declared range
    assert not result.successful and result.reason
    result = set_atomically(min_samples=25, gate_k=-1.0)
    assert not result.successful and result.reason
    result = set_atomically(min_samples=25, base_to_camera=[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0])
    assert not result.successful and 'quaternion' in result.reason
    assert h.node.params.min_samples == 10 and h.node.calibrator is calibrator

    # a shell-only change takes effect at once, the estimate is kept
    markers_before = len(h.received['/hac/markers'])
    assert set_atomically(publish_markers=False, odom_frame='odom2').successful
    assert h.node.calibrator is calibrator and h.node.calibrator.converged
    # a topic change re-subscribes: the joints now come on another topic
    assert set_atomically(joints_topic='/hmr/joints_renamed').successful
    second = frames_after(walk, 0.55)
    h.play(walk.events[cut:second], topics={'joints': '/hmr/joints_renamed'})
    h.settle()
    assert len(h.received['/hac/markers']) == markers_before
    assert h.received['/hac/odometry'][-1][1].header.frame_id == 'odom2'
    assert h.stamps('/hac/human_joints')[-1] == max(
        e.stamp_ns for e in walk.events[:second] if e.kind == 'joints')

    # an estimator parameter rebuilds the calibrator: nothing metric until min_samples again
    published = len(h.scales())
    assert set_atomically(min_samples=40).successful
    assert h.node.calibrator is not calibrator and h.node.calibrator.params.min_samples == 40
    next_map = next(i for i, e in enumerate(walk.events) if i >= second and e.kind == 'cloud')
    h.play(walk.events[second:next_map], topics={'joints': '/hmr/joints_renamed'})
    h.settle()
    assert h.node.calibrator.status().map_points > 0, 'the current map was handed over'
    h.play(walk.events[next_map:], topics={'joints': '/hmr/joints_renamed'})
    h.settle()
    new_scale_stamps = h.stamps('/hac/human_joints')[published:]
    frames_since = [e.stamp_ns for e in walk.events[second:] if e.kind == 'joints']
    assert new_scale_stamps, 'the rebuilt estimator converged again'
    assert frames_since.index(new_scale_stamps[0]) >= 40 - 1
    true = walk.scale_at(int(walk.pose_stamps[-1]))
    assert abs(h.scales()[-1] / true - 1.0) < SCALE_TOL


def test_every_parameter_is_declared_with_its_default_and_description(harness):
    h = harness()
    for name in names():
        value = h.node.get_parameter(name).value
        expected = HacParams().as_dict()[name] if name not in TEST_PARAMS else TEST_PARAMS[name]
        assert (list(value) if isinstance(expected, list) else value) == expected, name
        descriptor = h.node.describe_parameter(name)
        assert descriptor.description.startswith(describe(name)['description'])


@pytest.mark.parametrize('pose_to_optical, warned', [([0.0, 0.0, 0.0, 1.0], True),
                                                     ([-0.5, 0.5, -0.5, 0.5], False)])
def test_body_frame_poses_are_warned_about_over_dds(harness, pose_to_optical, warned):
    """SLAM poses of an x-forward, z-up camera frame: one warning in the log naming
    pose_to_optical, kept in /diagnostics; with pose_to_optical set, none."""
    from scipy.spatial.transform import Rotation

    rec = scenario_recording('walk', 12.0, seed=3)
    R_q = Rotation.from_quat([-0.5, 0.5, -0.5, 0.5]).as_matrix()
    body = []
    for e in rec.events:  # R_map_body = R_map_optical · R(q)^T
        if e.kind == 'pose':
            R, c = pose_msg_to_rt(e.msg)
            e = Event(e.stamp_ns, 'pose', rt_to_pose_stamped(R @ R_q.T, c, e.stamp_ns,
                                                             e.msg.header.frame_id, TYPES))
        body.append(e)
    h = harness(pose_to_optical=pose_to_optical)
    h.play(body)
    h.settle()
    diag = h.diagnostics()
    assert h.node.notices['convention_pose_convention'] == (1 if warned else 0)
    assert ('suspect.pose_convention' in diag) == warned
    if warned:
        assert 'pose_to_optical' in diag['suspect.pose_convention']
        status = h.received['/diagnostics'][-1][1].status[0]
        assert status.level == TYPES.get('diagnostic_msgs/msg/DiagnosticStatus').WARN
        assert 'inputs suspect: pose_convention' in status.message


def test_a_custom_joint_layout_is_given_as_integer_arrays(harness):
    custom = dict(joint_layout='custom', joints_per_person=17, root_joints=[11, 12],
                  body_axis_lower_joints=[11, 12], body_axis_upper_joints=[5, 6],
                  contact_joints=[15, 16], skeleton_edges=[11, 13, 13, 15])
    h = harness(**custom)
    assert h.node.calibrator is not None and h.node.calibrator.layout.root == (11, 12)
    assert list(h.node.get_parameter('contact_joints').value) == [15, 16]
    bad = h.node.set_parameters([Parameter('root_joints', value=[40])])[0]
    assert not bad.successful and 'outside 0..16' in bad.reason
