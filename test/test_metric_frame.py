"""The planner-grade outputs of the core (SPEC, Outputs and "The metric frame"): continuous
odometry, the globally consistent /hac/pose, the gravity-aligned metric frame, /hac/cloud and the
services' semantics. Pure core, no ROS."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from scenes import QUICK_CONVERGENCE

from hac_ros.core.basics.outputs import (
    CloudOut,
    HumanJointsOut,
    NoticeOut,
    OdometryOut,
    PoseOut,
    ScaleOut,
)
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.rules.params import HacParams
from hac_ros.simulate import make_scenario
from hac_ros.simulate.feed import scenario_events

NS = 1_000_000_000
STEP = 0.1  # SLAM units per pose, along the camera's optical axis
Q = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # the new map's rotation


def stamp(i: int) -> int:
    return 1_700_000_000 * NS + i * NS // 30


def straight_run(cal: Calibrator, first: int, last: int, R_wc: np.ndarray, frame: str,
                 start_units: float = 0.0) -> list:
    """Poses first..last-1 moving STEP units per pose along the camera's optical axis."""
    out: list = []
    for i in range(first, last):
        c = R_wc @ np.array([0.0, 0.0, start_units + STEP * (i - first)])
        out += cal.add_pose(stamp(i), R_wc, c, frame)
    return out


def by_stamp(outputs: list, kind: type) -> dict[int, object]:
    return {o.stamp_ns: o for o in outputs if isinstance(o, kind)}


def test_a_5pct_step_at_50_m_moves_the_pose_and_leaves_every_odometry_step_exact():
    """SPEC /hac/odometry: each step is the SLAM step times the scale of its moment; /hac/pose is
    the scale times the SLAM position, so it moves ~2.5 m when the estimate moves 5 % at 50 m.
    Across a reset the step counts as zero, the odometry pauses while the new segment converges,
    then sums the gap's steps with the new scale."""
    step_at, reset_at, converged_at, end = 500, 600, 650, 700

    def schedule(t: int) -> float | None:
        if t < stamp(step_at):
            return 1.0
        if t < stamp(reset_at):
            return 1.05
        return None if t < stamp(converged_at) else 1.2

    cal = Calibrator(HacParams(metric_frame_alignment='slam'), schedule=schedule)
    out = straight_run(cal, 0, reset_at, np.eye(3), 'map')
    out += straight_run(cal, reset_at, end, Q, 'map2', start_units=3.0)  # re-initialised
    odom, pose = by_stamp(out, OdometryOut), by_stamp(out, PoseOut)
    assert len(odom) == len(pose) == end - (converged_at - reset_at)
    stamps = sorted(odom)
    for a, b in itertools.pairwise(stamps):
        if b == stamp(converged_at):  # the gap: 599 -> 600 counts zero, 601..650 at the new scale
            expected = 1.2 * STEP * (converged_at - reset_at)
        else:
            expected = schedule(b) * STEP
        step = odom[b].position_metric - odom[a].position_metric
        # the step in the previous pose's camera frame is along its optical axis
        np.testing.assert_allclose(odom[a].rotation_metric.T @ step, [0.0, 0.0, expected],
                                   atol=1e-9)
    step_pose = pose[stamp(step_at)].position_metric - pose[stamp(step_at - 1)].position_metric
    assert np.linalg.norm(step_pose) == pytest.approx(1.05 * STEP * step_at - STEP * (step_at - 1),
                                                      abs=1e-9)  # 2.5 m of correction + the step
    # the new segment is placed on the last /hac/pose: 50 steps of 0.12 m further on
    gap = pose[stamp(converged_at)].position_metric - pose[stamp(reset_at - 1)].position_metric
    assert np.linalg.norm(gap) == pytest.approx(1.2 * STEP * (converged_at - reset_at), abs=1e-9)
    # first message after the gap: zero twist, and a covariance that covers the gap
    after = odom[stamp(converged_at)]
    assert not after.linear_velocity.any() and not after.angular_velocity.any()
    assert after.covariance[0, 0] > odom[stamp(reset_at - 1)].covariance[0, 0]
    # the twist is the metric speed, never a spike at the step
    speeds = [np.linalg.norm(odom[s].linear_velocity) for s in stamps if s != stamp(converged_at)]
    assert max(speeds) == pytest.approx(1.2 * STEP * 30, rel=1e-6)


def test_covariances_grow_with_distance_and_are_inflated_after_a_reset():
    cal = Calibrator(HacParams(metric_frame_alignment='slam'), schedule=lambda t: 2.0)
    out = straight_run(cal, 0, 200, np.eye(3), 'map')
    out += straight_run(cal, 200, 260, Q, 'map2')
    odom = [by_stamp(out, OdometryOut)[k] for k in sorted(by_stamp(out, OdometryOut))]
    variances = [o.covariance[0, 0] for o in odom]
    assert all(b >= a for a, b in itertools.pairwise(variances)) and variances[-1] > variances[1]
    assert all(np.all(np.diag(o.twist_covariance) > 0) for o in odom)
    pose = by_stamp(out, PoseOut)
    first_after = pose[stamp(200)].covariance[0, 0]
    assert first_after >= pose[stamp(199)].covariance[0, 0]  # the anchor's variance carried over
    assert np.all(np.linalg.eigvalsh(pose[stamp(199)].covariance) > 0)


def simulated_run(name: str, seed: int, **params: object) -> tuple[object, list]:
    """A scenario through the calibrator; these tests are about the metric frame, so by default
    the estimate converges as quickly as scenes.py's QUICK_CONVERGENCE lets it."""
    sc = make_scenario(name, seed=seed, hmr_bias=0.0)
    cal = Calibrator(HacParams(**{'converged_max_rel_sigma': QUICK_CONVERGENCE, **params}))
    cal.add_camera_info(sc.K, sc.width, sc.height)
    out: list = []
    for t, kind, payload in scenario_events(sc):
        out += {'map': cal.add_map, 'pose': cal.add_pose, 'joints': cal.add_joints}[kind](t, *payload)
    return sc, out


@pytest.mark.parametrize('name, seed', [('walk', 0), ('crowd', 1), ('reset', 0)])
def test_gravity_frame_puts_the_floor_at_z0_and_the_camera_at_its_true_height(name, seed):
    """metric_frame_alignment gravity (the default): z up, floor at z = 0, feet at z ~ 0; the
    camera's height within 2 % of the truth without HMR bias (the world's floor is z = 0)."""
    sc, out = simulated_run(name, seed)
    index = {int(s): i for i, s in enumerate(sc.pose_stamps_ns)}
    poses = [o for o in out if isinstance(o, PoseOut)]
    assert len(poses) > 0.8 * len(sc.pose_stamps_ns)
    z = np.array([p.position_metric[2] for p in poses])
    true_z = np.array([sc.gt_c[index[p.stamp_ns], 2] for p in poses])
    assert abs(np.median(z / true_z - 1.0)) < 0.02
    # z is up: the camera's optical y axis (image down) points down
    down = np.array([p.rotation_metric[:, 1] for p in poses])
    assert np.median(down[:, 2]) < -0.9
    # people stand on the floor: each person's lowest joint just above z = 0
    lowest = np.concatenate([o.joints_metric[..., 2].min(axis=-1) for o in out
                             if isinstance(o, HumanJointsOut)])
    assert 0.0 < np.median(lowest) < 0.12
    assert not [o for o in out if isinstance(o, NoticeOut) and o.cause == 'alignment_slam']


def test_slam_alignment_keeps_the_slam_axes():
    _, out = simulated_run('walk', 0, metric_frame_alignment='slam')
    pose, scale = by_stamp(out, PoseOut), by_stamp(out, ScaleOut)
    stamp_ns = max(set(pose) & set(scale))
    # the first segment: the scale times the SLAM pose, no rotation
    sc = make_scenario('walk', seed=0, hmr_bias=0.0)
    i = int(np.searchsorted(sc.pose_stamps_ns, stamp_ns))
    np.testing.assert_allclose(pose[stamp_ns].rotation_metric, sc.slam_R_wc[i], atol=1e-12)
    position = pose[stamp_ns].position_metric
    np.testing.assert_allclose(np.cross(position, sc.slam_c[i]), 0.0, atol=1e-9)
    assert position @ sc.slam_c[i] / (sc.slam_c[i] @ sc.slam_c[i]) == pytest.approx(
        scale[stamp_ns].scale, rel=1e-3)


def test_the_cloud_is_the_map_in_metres_sent_on_a_new_map_and_on_a_scale_change_rate_limited():
    sc = make_scenario('walk', seed=0, hmr_bias=0.0, duration=20.0)
    state = {'scale': 2.0}
    cal = Calibrator(HacParams(metric_frame_alignment='slam', cloud_min_period_s=2.0), schedule=lambda t: state['scale'])
    cal.add_camera_info(sc.K, sc.width, sc.height)
    clouds: list[CloudOut] = []
    switch = int(sc.pose_stamps_ns[len(sc.pose_stamps_ns) // 2])
    for t, kind, payload in scenario_events(sc):
        if t >= switch:
            state['scale'] = 2.0 * (1 + 0.5 * cal.params.cloud_republish_rel)  # below the threshold
        if t >= switch + 3 * NS:
            state['scale'] = 2.0 * (1 + 2 * cal.params.cloud_republish_rel)
        out = {'map': cal.add_map, 'pose': cal.add_pose, 'joints': cal.add_joints}[kind](t, *payload)
        clouds += [o for o in out if isinstance(o, CloudOut)]
    maps_used = {m.stamp_ns for m in sc.maps}
    assert clouds and all(c.points_metric.dtype == np.float32 for c in clouds)
    assert all(b.stamp_ns - a.stamp_ns >= 2 * NS for a, b in itertools.pairwise(clouds))
    assert len(clouds) <= len(maps_used) + 1
    scale_change = [c for c in clouds if c.stamp_ns >= switch + 3 * NS]
    assert scale_change, 'a 2 % scale change republishes the cloud'
    assert len(clouds[-1].points_metric) <= cal.params.cloud_out_max_points
    # in metres: the SLAM map times the scale in use (alignment slam, first segment)
    last_map = max((m for m in sc.maps if m.stamp_ns <= clouds[-1].stamp_ns), key=lambda m: m.stamp_ns)
    span_slam = np.ptp(last_map.points_slam, axis=0)
    np.testing.assert_allclose(np.ptp(clouds[-1].points_metric, axis=0), state['scale'] * span_slam,
                               rtol=0.05)


def test_freeze_holds_the_scale_and_reset_starts_a_segment_without_an_odometry_jump():
    sc = make_scenario('walk', seed=2, hmr_bias=0.0)
    cal = Calibrator(HacParams(converged_max_rel_sigma=QUICK_CONVERGENCE))
    cal.add_camera_info(sc.K, sc.width, sc.height)
    events = list(scenario_events(sc))
    third = len(events) // 3
    out: list = []

    def feed(items: list) -> None:
        for t, kind, payload in items:
            out.extend({'map': cal.add_map, 'pose': cal.add_pose,
                        'joints': cal.add_joints}[kind](t, *payload))

    feed(events[:third])
    assert cal.converged
    cal.request_freeze(True)
    feed(events[third:2 * third])
    frozen = [o.scale for o in out if isinstance(o, ScaleOut)][-(third // 4):]
    assert len(set(frozen)) == 1 and cal.services.samples > 0
    cal.request_freeze(False)
    cal.request_reset()
    before = len(out)
    feed(events[2 * third:])
    notices = {o.cause for o in out[before:] if isinstance(o, NoticeOut)}
    assert {'service_freeze', 'service_reset'} <= notices
    assert cal.services.counts['reset'] == 1 and cal.services.counts['freeze_false'] == 1
    odom = [o for o in out if isinstance(o, OdometryOut)]
    index = {int(s): i for i, s in enumerate(sc.pose_stamps_ns)}
    true_steps = np.linalg.norm(np.diff(sc.gt_c, axis=0), axis=1)
    gaps = 0
    for a, b in itertools.pairwise(odom):
        step = np.linalg.norm(b.position_metric - a.position_metric)
        if b.linear_velocity.any():  # no jump at the freeze, the release or the reset
            assert step < 3 * true_steps.max()
        else:  # the reset's gap: its steps summed with the new scale
            gaps += 1
            i, j = index[a.stamp_ns], index[b.stamp_ns]
            assert step == pytest.approx(true_steps[i + 1:j].sum(), rel=0.1)
    assert gaps == 1


def test_the_obstacle_cloud_is_the_metric_maps_band_above_the_floor():
    """publish_obstacles: /hac/obstacles with each /hac/cloud, its points between the two heights
    (gravity alignment: z is the height above the floor)."""
    from rosbags.typesys import Stores, get_typestore

    from hac_ros.bridge.messages import CLOUD, OBSTACLES, OutputMessages
    from msg_adapters import cloud_to_xyz

    params = HacParams(publish_obstacles=True, obstacle_min_height=0.3, obstacle_max_height=1.5)
    _, out = simulated_run('walk', 0, publish_obstacles=True, obstacle_min_height=0.3,
                           obstacle_max_height=1.5)
    messages = OutputMessages(params)
    store = get_typestore(Stores.ROS2_JAZZY)
    clouds = [o for o in out if isinstance(o, CloudOut)]
    assert clouds and all(c.levelled for c in clouds)
    for cloud in clouds:
        msgs = {m.topic: store.deserialize_cdr(m.msg, m.msgtype) for m in messages.convert(cloud)}
        assert set(msgs) == {CLOUD[0], OBSTACLES[0]}
        obstacles = cloud_to_xyz(msgs[OBSTACLES[0]])
        z = cloud.points_metric[:, 2]
        assert len(obstacles) == np.count_nonzero((z >= 0.3) & (z <= 1.5)) > 0
        assert obstacles[:, 2].min() >= 0.3 and obstacles[:, 2].max() <= 1.5
        assert len(obstacles) < len(cloud.points_metric)  # the floor and the ceiling are out
    with pytest.raises(Exception, match='obstacle_min_height'):
        HacParams(obstacle_min_height=2.0, obstacle_max_height=1.0)


# ============================================================================ input conventions
BODY_TO_OPTICAL = [-0.5, 0.5, -0.5, 0.5]  # x-forward, z-up camera body frame (SPEC)


def _run(sc, params: HacParams, pose_rotation=None, joints_fn=None, camera_info: bool = True):
    cal = Calibrator(params)
    out: list = cal.add_camera_info(sc.K, sc.width, sc.height) if camera_info else []
    for t, kind, payload in scenario_events(sc):
        if kind == 'pose' and pose_rotation is not None:
            payload = (payload[0] @ pose_rotation, *payload[1:])
        if kind == 'joints' and joints_fn is not None:
            payload = (joints_fn(np.asarray(payload[0])), *payload[1:])
        out += {'map': cal.add_map, 'pose': cal.add_pose, 'joints': cal.add_joints}[kind](t, *payload)
    return out


def test_body_frame_poses_with_pose_to_optical_calibrate_like_optical_ones():
    from scipy.spatial.transform import Rotation

    sc = make_scenario('walk', seed=4, hmr_bias=0.0, duration=15.0)
    R_child_optical = Rotation.from_quat(BODY_TO_OPTICAL).as_matrix()
    quick = HacParams(converged_max_rel_sigma=QUICK_CONVERGENCE)
    optical = _run(sc, quick)
    body = _run(sc, quick.replace(pose_to_optical=BODY_TO_OPTICAL),
                pose_rotation=R_child_optical.T)
    a = [o.scale for o in optical if isinstance(o, ScaleOut)]
    b = [o.scale for o in body if isinstance(o, ScaleOut)]
    assert len(a) == len(b) > 100
    np.testing.assert_allclose(b, a, rtol=1e-9)
    # the same body-frame poses read as optical: the rays miss, the scale is far off or absent
    wrong = [o.scale for o in _run(sc, quick, pose_rotation=R_child_optical.T)
             if isinstance(o, ScaleOut)]
    assert not wrong or abs(np.median(wrong) / sc.true_scale[0] - 1) > 0.1


def test_hmr_focal_px_undoes_a_focal_length_mismatch():
    """An HMR model that assumed f_a = 800 px on a camera of fx puts each person at f_a/fx times
    the true depth (x, y right); hmr_focal_px: 800 moves them back."""
    sc = make_scenario('walk', seed=5, hmr_bias=0.0, duration=15.0)
    fx, f_a = float(sc.K[0, 0]), 800.0

    def assumed(joints: np.ndarray) -> np.ndarray:
        out = joints.copy()
        out[:, :, 2] += joints[:, :1, 2] * (f_a / fx - 1.0)
        return out

    def final(outputs: list) -> float:
        return [o.scale for o in outputs if isinstance(o, ScaleOut)][-1] / float(sc.true_scale[-1])

    baseline = final(_run(sc, HacParams()))
    wrong = final(_run(sc, HacParams(), joints_fn=assumed))
    fixed_out = _run(sc, HacParams(hmr_focal_px=f_a), joints_fn=assumed)
    assert abs(wrong - 1.0) > 0.5 * abs(f_a / fx - 1.0)  # the mismatch shows in the scale
    assert abs(final(fixed_out) - baseline) < 0.005
    notes = [o.text for o in fixed_out if isinstance(o, NoticeOut) and o.cause == 'hmr_focal']
    assert len(notes) == 1 and '800.0 px' in notes[0]
    # hmr_focal_px 0: nothing to say on a correct run (issue 36: correct runs look alarming)
    assert not [o for o in _run(sc, HacParams()) if isinstance(o, NoticeOut)
                and o.cause.startswith('hmr_focal')]
    # without CameraInfo: one clear warning, depths uncorrected
    blind = _run(sc, HacParams(hmr_focal_px=f_a), joints_fn=assumed, camera_info=False)
    assert [o.cause for o in blind if isinstance(o, NoticeOut)].count('hmr_focal_no_camera_info') == 1
    with pytest.raises(Exception, match='pose_to_optical'):
        HacParams(pose_to_optical=[0.0, 0.0, 0.0, 2.0])
