"""The floor from the map (hac_ros.core.geometry.ground.map_floor) and what it decides before any scale.

Scenes built for it: people who lean (their body axis is not gravity), and tables standing between
the camera and the feet from the very first frame, so that the first map hits of the contact rays
are table tops.
"""
from __future__ import annotations

import math

import numpy as np
from scenes import QUICK_CONVERGENCE, Scene, walking_scene
from scipy.spatial.transform import Rotation

from hac_ros.core.basics.outputs import HumanJointsOut, NoticeOut, SampleOut, ScaleOut
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.geometry.ground import GroundModel, map_floor
from hac_ros.core.geometry.reference import MapIndex
from hac_ros.core.layouts import SMPL24
from hac_ros.core.rules.health import WARN, HealthMonitor
from hac_ros.core.rules.params import HacParams

TABLE_TOP_M = 0.75


def uniform(rng: np.random.Generator, density: float, lo: list[float], hi: list[float]
            ) -> np.ndarray:
    """Textured points spread uniformly over the box [lo, hi] (one side flat: a face), metres."""
    lo_a, hi_a = np.array(lo), np.array(hi)
    area = float(np.prod(np.sort(hi_a - lo_a)[1:]))
    return rng.uniform(lo_a, hi_a, (int(density * area), 3))


def room_points(seed: int, floor: bool = True) -> np.ndarray:
    """A room seen from y = -4 over a row of tables (:func:`table_row`), world metres: the floor
    (z = 0) where the camera sees it (not under or behind the tables: the walker's feet at y = 0
    are hidden), a back wall (y = 3) and two side walls, with 1 cm noise."""
    rng = np.random.default_rng(seed)
    parts = [uniform(rng, 150, [-6, 3, 0], [6, 3, 2.5]), uniform(rng, 150, [-6, -4, 0], [-6, 3, 2.5]),
             uniform(rng, 150, [6, -4, 0], [6, 3, 2.5])]
    if floor:
        parts += [uniform(rng, 150, [-6, -4, 0], [6, -2.3, 0]),
                  uniform(rng, 150, [-6, 1.6, 0], [6, 3, 0])]
    points = np.vstack(parts)
    return points + rng.normal(0.0, 0.01, points.shape)


def table_row(seed: int = 7) -> np.ndarray:
    """A row of tables between the camera (y = -4) and the walker (y = 0), all along the walk:
    textured tops at TABLE_TOP_M over y in [-2.3, -1.2] and textured fronts (y = -2.3), metres."""
    rng = np.random.default_rng(seed)
    return np.vstack([uniform(rng, 300, [-6, -2.3, TABLE_TOP_M], [6, -1.2, TABLE_TOP_M]),
                      uniform(rng, 300, [-6, -2.3, 0], [6, -2.3, TABLE_TOP_M])])


def leaning(scene: Scene, degrees: float) -> np.ndarray:
    """The scene's joints in the camera frame, each person turned forward by ``degrees`` about
    their feet (towards the camera): an HMR body whose axis is not gravity. (T, 24, 3) metres."""
    turn = Rotation.from_euler('x', -degrees, degrees=True).as_matrix()  # world x: the walk
    feet = scene.joints_world[:, [10, 11]].mean(axis=1, keepdims=True)
    world = (scene.joints_world - feet) @ turn.T + feet
    return np.einsum('tji,tkj->tki', scene.R_wc_world, world - scene.c_world[:, None, :])


def run(scene: Scene, points_slam: np.ndarray, joints_cam: np.ndarray | None = None,
        params: HacParams | None = None) -> tuple[Calibrator, list]:
    """The map once at the first stamp, then pose and joints per frame, in SPEC order (these
    tests are about the floor: by default the estimate converges as quickly as scenes.py's
    QUICK_CONVERGENCE lets it)."""
    cal = Calibrator(params or HacParams(converged_max_rel_sigma=QUICK_CONVERGENCE))
    joints_cam = scene.joints_cam if joints_cam is None else joints_cam
    outs = cal.add_map(int(scene.stamps_ns[0]), points_slam, 'map')
    for t, stamp in enumerate(scene.stamps_ns.tolist()):
        outs += cal.add_pose(stamp, scene.R_wc_slam[t], scene.c_slam[t], 'map')
        outs += cal.add_joints(stamp, joints_cam[t][None], 'camera')
    return cal, outs + cal.flush()


def true_down(scene: Scene) -> np.ndarray:
    """Gravity (down) in the SLAM map frame."""
    return scene.R0.T @ np.array([0.0, 0.0, -1.0])


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(min(1.0, abs(float(a @ b)))))


def test_the_map_floor_gives_the_normal_and_offset_a_leaning_body_cannot():
    """People leaning 4 degrees: their axis is 4 degrees off gravity; the floor found in the map
    (a room with walls and a row of tables) is within a tenth of a degree, its offset within a
    centimetre."""
    scene = walking_scene(frames=30, true_scale=2.0)
    index = MapIndex(scene.to_slam(np.vstack([room_points(0), table_row()])))
    ground = GroundModel('hmr', inlier_m=0.02, ransac_iters=200)
    for t, joints in enumerate(leaning(scene, 4.0)):
        up = scene.R_wc_slam[t] @ (joints[12] - joints[0])
        ground.down.add(SMPL24, joints, scene.R_wc_slam[t], scene.c_slam[t], index,
                        up / np.linalg.norm(up))  # which way is down: the scene says
        ground.add_body(scene.R_wc_slam[t], joints[12] - joints[0])
    body = ground._body_normal()
    assert body is not None and angle_deg(body, true_down(scene)) > 3.0
    plane = ground.plane(index)
    assert plane is not None and ground.trusted
    assert angle_deg(plane.normal, true_down(scene)) < 0.1
    floor_offset = float(true_down(scene) @ scene.to_slam(np.zeros(3)))  # the floor's n·p
    assert abs(plane.offset - floor_offset) * scene.true_scale < 0.01


def test_a_map_without_a_floor_is_not_trusted():
    """Table tops over a floor the map missed (an untextured floor; the walls go down to it): the
    lowest dense surface has much of the map below it, so it is not taken for the floor."""
    scene = walking_scene(frames=30, true_scale=2.0)
    index = MapIndex(scene.to_slam(np.vstack([room_points(0, floor=False), table_row()])))
    assert map_floor(index, true_down(scene)) is None
    ground = GroundModel('hmr', inlier_m=0.02, ransac_iters=200)
    for t, joints in enumerate(scene.joints_cam):
        up = scene.R_wc_slam[t] @ (joints[12] - joints[0])
        ground.down.add(SMPL24, joints, scene.R_wc_slam[t], scene.c_slam[t], index,
                        up / np.linalg.norm(up))  # which way is down: the scene says
        ground.add_body(scene.R_wc_slam[t], joints[12] - joints[0])
    ground.plane(index)
    assert not ground.trusted


def test_tables_in_front_of_the_feet_from_the_first_frame_are_not_the_contact():
    """The walker's feet are hidden behind tables from the first frame: every contact ray meets a
    table top at about half the floor's distance. Before any scale exists those hits are refused
    for the map's floor, and the estimate converges on the floor, not on the tables (it read the
    tables, 100 % too high, before the floor came from the map)."""
    scene = walking_scene(frames=60, true_scale=2.0)
    points = scene.to_slam(np.vstack([room_points(1), table_row()]))
    rng = np.random.default_rng(3)
    noisy = leaning(scene, 2.0) + rng.normal(0.0, 0.01, scene.joints_cam.shape)
    cal, outs = run(scene, points, noisy)
    used = [o for o in outs if isinstance(o, SampleOut) and o.accepted]
    tables = [o for o in used if o.scale > 1.3 * scene.true_scale]
    # the first frames, before five bodies give a normal, have no floor to judge hits by
    assert len(used) >= 50 and len(tables) <= 4 and cal.ground.trusted
    published = np.array([o.scale for o in outs if isinstance(o, ScaleOut)])
    assert len(published) and np.all(np.abs(published / scene.true_scale - 1) < 0.03)
    assert abs(published[-1] / scene.true_scale - 1) < 0.02


def test_the_world_frame_stays_put_once_converged_at_keyframe_rate():
    """A person standing still, leaning 4 degrees, seen at keyframe rate (1.3 Hz) by a camera
    that moves: once the node publishes, the person stays where they are in the metric frame
    (the gravity alignment comes from the map's floor from the start; with the leaning bodies'
    axis the frame tilted as it was refined, and the person moved with it)."""
    scene = walking_scene(frames=40, true_scale=2.0, rate=1.3, stride=0.0)
    points = scene.to_slam(room_points(2))
    rng = np.random.default_rng(4)
    noisy = leaning(scene, 4.0) + rng.normal(0.0, 0.005, scene.joints_cam.shape)
    _, outs = run(scene, points, noisy, HacParams(human_filter='none'))
    pelvis = np.array([o.joints_metric[0, 0] for o in outs if isinstance(o, HumanJointsOut)])
    assert len(pelvis) >= 25
    assert np.max(np.linalg.norm(pelvis - np.median(pelvis, axis=0), axis=1)) < 0.02
    assert abs(np.median(pelvis[:, 2]) - scene.joints_world[0, 0, 2]) < 0.05  # levelled: z up


def test_no_floor_in_the_map_is_said_in_diagnostics():
    """Tables over an untextured floor: the map shows no floor, so nothing says the table tops
    the contact rays meet are not the floor; /diagnostics says so (WARN, ``floor_unknown``) instead
    of OK. With the floor in the map, the reason is absent."""
    scene = walking_scene(frames=40, true_scale=2.0)
    for floor, expected in ((False, True), (True, False)):
        points = scene.to_slam(np.vstack([room_points(5, floor=floor), table_row()]))
        cal, _ = run(scene, points)
        status = cal.status()
        assert status.converged and ('floor_unknown' in status.conditions) == expected, floor
        health = HealthMonitor().assess(status)
        assert (health.level == WARN and 'floor_unknown' in health.reasons) == expected, floor


def test_a_window_locked_on_tables_is_dropped_when_the_floor_appears():
    """The first maps show the tables but not yet the floor (too little of it seen): nothing
    refuses the table tops and the estimate converges on them. When a later map shows the floor,
    the floor's readings of the next samples disagree with the estimate by far more than
    plausibility_rel_tol: the window is dropped (a notice says so) and the scale comes from the
    floor."""
    scene = walking_scene(frames=80, true_scale=2.0)
    tables = scene.to_slam(np.vstack([room_points(6, floor=False), table_row()]))
    room = scene.to_slam(np.vstack([room_points(6), table_row()]))
    cal = Calibrator(HacParams())
    outs: list = []
    for t, stamp in enumerate(scene.stamps_ns.tolist()):
        if t in (0, 40):
            outs += cal.add_map(stamp, tables if t == 0 else room, 'map')
        outs += cal.add_pose(stamp, scene.R_wc_slam[t], scene.c_slam[t], 'map')
        outs += cal.add_joints(stamp, scene.joints_cam[t][None], 'camera')
    outs += cal.flush()
    published = [o for o in outs if isinstance(o, ScaleOut)]
    early = [o.scale for o in published if o.stamp_ns < scene.stamps_ns[40]]
    assert early and np.median(early) > 1.5 * scene.true_scale  # locked on the tables at first
    assert any(isinstance(o, NoticeOut) and o.cause == 'floor_relock' for o in outs)
    assert abs(published[-1].scale / scene.true_scale - 1) < 0.02
