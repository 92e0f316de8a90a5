"""The scenarios: a world, people, a camera rig, a SLAM and an HMR model, with ground truth.

``make_scenario(name, seed, ...)`` is pure computation (no I/O) and deterministic for a seed; the
recording writer and the benchmarks use the same :class:`Scenario`.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hac_ros.core.basics.errors import HacError
from hac_ros.core.basics.numeric import NS
from hac_ros.core.layouts import BUILT_IN
from hac_ros.simulate import camera as rigs
from hac_ros.simulate import motions
from hac_ros.simulate.hmr import DepthBias, draw_bias, in_view, predict
from hac_ros.simulate.skeletons import simulated_layouts, to_layout
from hac_ros.simulate.slam import MapMessage, run_slam
from hac_ros.simulate.world import Box, World, room

SCALE_RANGE = (0.2, 5.0)  # the true scale is drawn log-uniformly from this range
LANDMARK_DENSITY = 60.0  # textured landmarks per m² of surface (times each surface's texture)
START_NS = 1_700_000_000_000_000_000  # recordings start at a fixed, plausible wall-clock stamp
DRIFT_TOTAL = 0.40  # the drift scenario's scale drifts by 40 % over the run
# The contact joint's height above the sole, drawn per person (shoes and feet differ), metres: the
# foot joints of the procedural gait and the skater, the hand joints of the handstand. Drawn
# independently of any model the core uses for it; the real motion (--motion) keeps its own.
SOLE_HEIGHT_M = (0.015, 0.045)
HAND_HEIGHT_M = (0.01, 0.03)


@dataclass
class Scenario:
    """Everything a recording holds, as arrays. Frames and units in every name.

    Poses at every stamp: ``slam_R_wc`` (T, 3, 3) camera-to-map and ``slam_c`` (T, 3) SLAM units
    (what /slam/pose carries, map frame ``slam_frame_ids[i]``); ``gt_R_wc``, ``gt_c`` (metres) the
    true camera in the fixed world frame; ``true_scale`` (T,) metres per SLAM unit.
    Humans at ``joints_stamps_ns`` (F,) (the stamps with someone in view): ``joints_cam[k]``
    (P, K, 3) the HMR prediction, metres, camera optical frame; ``gt_joints_world[k]`` the truth,
    world frame; ``person_ids[k]`` which people. ``contact_heights`` (people,): each person's
    contact joint's height above the surface it stands on, metres (NaN: real motion, its own);
    ``hmr_bias``: the mean of the HMR depth bias, ``hmr_bias_frames`` (T,) its value at each frame.
    """

    name: str
    seed: int
    rate: float
    camera_frame: str
    K: np.ndarray
    width: int
    height: int
    pose_stamps_ns: np.ndarray
    slam_R_wc: np.ndarray
    slam_c: np.ndarray
    slam_frame_ids: list[str]
    gt_R_wc: np.ndarray
    gt_c: np.ndarray
    true_scale: np.ndarray
    maps: list[MapMessage]
    joints_stamps_ns: np.ndarray
    joints_cam: list[np.ndarray]
    gt_joints_world: list[np.ndarray]
    person_ids: list[np.ndarray]
    hmr_bias: float
    hmr_bias_frames: np.ndarray
    contact_heights: np.ndarray
    outlier_frames: np.ndarray
    segment_starts: list[int]
    world: World = field(repr=False)
    world_frame: str = 'world'
    joint_layout: str = 'smpl24'  # of joints_cam and gt_joints_world (K joints per person)

    def segment_start(self, i: int) -> int:
        return max(s for s in self.segment_starts if s <= i)

    @property
    def duration_s(self) -> float:
        return float(self.pose_stamps_ns[-1] - self.pose_stamps_ns[0]) / NS


# name -> (default duration s, description)
SCENARIOS: dict[str, tuple[float, str]] = {
    'walk': (30.0, 'handheld camera following a walker, feet mostly in view (EMDB-like)'),
    'ego': (30.0, 'head-mounted camera, a partner in view, feet mostly out of view, sparse floor'),
    'stairs': (30.0, 'a walker crossing a flight of stairs up and down'),
    'handstand': (20.0, 'walking on the hands: the hands are the contact'),
    'skate': (20.0, 'a standing pose gliding across the world'),
    'occluded': (30.0, 'tables between the camera and the feet'),
    'crowd': (30.0, 'three people'),
    'drift': (90.0, 'the SLAM scale drifts by 40 % over the run'),
    'reset': (40.0, 'the SLAM re-initialises mid-run: new map frame, new scale'),
    'static': (20.0, 'a camera that does not move'),
    'seated': (20.0, 'one person seated on a high stool (not in the map), feet hanging: no sample'),
    'lying': (20.0, 'one person lying on a bed (not in the map): no sample'),
    'office': (30.0, 'two people seated at desks, two walking: the walkers calibrate'),
}
# scenes where nobody measures (only standing people do): nothing is calibrated from them
NOBODY_STANDS = ('seated', 'lying')
# each scenario's draws come from generators keyed by its index here: the scenarios added later
# keep every earlier scenario's recordings as they were
SEED_KEYS = {name: k for k, name in enumerate(
    ['crowd', 'drift', 'ego', 'handstand', 'occluded', 'reset', 'skate', 'stairs', 'static',
     'walk', 'seated', 'lying', 'office'])}


def _furniture(world: World) -> None:
    """A few textured boxes along the walls (shelves, a cabinet, a sofa)."""
    world.boxes += [Box(np.array([-6.9, -2.0, 0.0]), np.array([-6.3, 2.0, 1.8]), 1.5),
                    Box(np.array([4.0, 6.2, 0.0]), np.array([6.5, 6.9, 0.9]), 1.5),
                    Box(np.array([-3.0, -6.9, 0.0]), np.array([0.5, -6.2, 0.8]), 1.5)]


def _stairs(world: World) -> None:
    """Three steps up, a landing, three steps down, across x in [-1.75, 1.75], y in [-1.2, 1.2]."""
    rise, run = 0.17, 0.35
    for k in range(3):
        h = rise * (k + 1)
        world.boxes.append(Box(np.array([-1.75 + run * k, -1.2, 0.0]),
                               np.array([-1.75 + run * (k + 1), 1.2, h]), 1.2))
        world.boxes.append(Box(np.array([1.75 - run * (k + 1), -1.2, 0.0]),
                               np.array([1.75 - run * k, 1.2, h]), 1.2))
    world.boxes.append(Box(np.array([-0.7, -1.2, 0.0]), np.array([0.7, 1.2, 3 * rise]), 1.2))


def make_scenario(name: str, seed: int = 0, duration: float | None = None, rate: float = 30.0,
                  hmr_bias: float | None = None, motion: str | None = None,
                  joint_layout: str = 'smpl24', foot_roll: bool = True) -> Scenario:
    """Build one scenario (deterministic for ``seed``; the same people, camera and SLAM for every
    ``joint_layout``: the HMR model's joints, one of
    :func:`~hac_ros.simulate.skeletons.simulated_layouts`). ``foot_roll`` False: the walkers'
    stance feet stay planted (motions.FootRoll(), the simulator before the roll)."""
    if name not in SCENARIOS:
        raise HacError(f'unknown scenario {name!r}; one of: {", ".join(SCENARIOS)}')
    if rate <= 0 or (duration is not None and duration <= 0):
        raise HacError('rate and duration must be positive')
    if joint_layout not in simulated_layouts():
        raise HacError(f'joint layout must be one of {", ".join(simulated_layouts())}, not '
                       f'{joint_layout!r}')
    rng = np.random.default_rng([seed, SEED_KEYS[name]])
    # the contact heights and the HMR depth process have a generator of their own (adding them
    # left every other draw of a seed as it was)
    body_rng = np.random.default_rng([seed, SEED_KEYS[name], 1])
    # so have the walkers' foot rolls (motions.FootRoll: a contact lifted as in real gait)
    roll_rng = np.random.default_rng([seed, SEED_KEYS[name], 2])

    def walker(path: motions.Path2D, phase_s: float = 0.0) -> np.ndarray:
        roll = motions.FootRoll(roll_rng.uniform(*motions.ROLL_HEEL_STRIKE_M),
                                roll_rng.uniform(*motions.ROLL_TOE_OFF_M))
        return motions.gait(t, path, world, phase_s, roll if foot_roll else motions.FootRoll())

    duration = SCENARIOS[name][0] if duration is None else float(duration)
    T = max(2, int(round(duration * rate)) + 1)
    t = np.arange(T) / rate
    stamps = START_NS + np.round(t * NS).astype(np.int64)
    world = room()
    _furniture(world)
    scale0 = float(np.exp(rng.uniform(math.log(SCALE_RANGE[0]), math.log(SCALE_RANGE[1]))))
    bias = draw_bias(rng) if hmr_bias is None else float(hmr_bias)
    # the draws below keep this order: every seed's scenario stays what it was
    people = _people(name, t, world, walker, rng, body_rng)
    heights = _contact_heights(name, people, body_rng)
    if motion is not None:
        people[0] = motions.load_motion(motion, t)
        heights[0] = math.nan
    R_world, c_world = _camera(name, people[0][:, 0], t, rng)
    scale_fn, segments = _slam_scale(name, T, scale0, rng)
    K = rigs.K_DEFAULT.copy()
    landmarks = world.sample_landmarks(LANDMARK_DENSITY, rng)
    people_per_frame = [np.stack([p[i] for p in people]) for i in range(T)]
    slam = run_slam(world, landmarks, stamps, R_world, c_world, people_per_frame, K,
                    (rigs.WIDTH, rigs.HEIGHT), scale_fn, segments, rng)
    depth_bias = DepthBias(bias, t, body_rng, wander=hmr_bias is None or hmr_bias != 0.0)
    hmr = _hmr(people, joint_layout, stamps, R_world, c_world, K, depth_bias.values, body_rng)
    return Scenario(
        name=name, seed=seed, rate=rate, camera_frame='camera_optical', K=K, width=rigs.WIDTH,
        height=rigs.HEIGHT, pose_stamps_ns=stamps, slam_R_wc=slam.R_wc, slam_c=slam.c,
        slam_frame_ids=slam.frame_ids, gt_R_wc=R_world, gt_c=c_world, true_scale=slam.scale,
        maps=slam.maps, joints_stamps_ns=hmr.stamps_ns, joints_cam=hmr.joints_cam,
        gt_joints_world=hmr.joints_world, person_ids=hmr.person_ids, hmr_bias=bias,
        hmr_bias_frames=depth_bias.values, contact_heights=heights,
        outlier_frames=hmr.outlier_frames, segment_starts=segments,
        world=world, joint_layout=joint_layout)


def _people(name: str, t: np.ndarray, world: World,
            walker: Callable[..., np.ndarray], rng: np.random.Generator,
            body_rng: np.random.Generator) -> list[np.ndarray]:
    """Each person's world joints (T, 24, 3) metres, SMPL order, over the times ``t`` (s); the
    scenario's furniture added to ``world``; ``walker(path, phase_s)`` walks a path."""
    if name == 'stairs':
        _stairs(world)
        return [walker(motions.shuttle_path((-4.0, 0.0), (4.0, 0.0), 1.0))]
    if name == 'handstand':
        return [motions.handstand(t, motions.circle_path((0.0, 0.0), 2.5, 0.5), world)]
    if name == 'skate':
        return [motions.skate(t, motions.circle_path((0.0, 0.0), 3.0, 1.5))]
    if name == 'occluded':
        for k in range(4):  # a row of tables between the camera and the walker
            x0 = -5.0 + 2.6 * k
            world.boxes.append(Box(np.array([x0, -0.3, 0.0]), np.array([x0 + 2.0, 0.9, 0.75]), 1.5))
        return [walker(motions.shuttle_path((-4.5, 1.6), (4.5, 1.6), 1.0))]
    if name == 'crowd':
        return [walker(motions.circle_path((0.0, 0.0), 3.0, 1.1)),
                walker(motions.circle_path((0.0, 0.0), 1.8, 0.9, phase=2.0), 0.2),
                walker(motions.shuttle_path((-4.0, -4.0), (4.0, -1.0), 1.2), 0.35)]
    if name == 'ego':
        world.floor_texture = 0.08  # a plain floor: sparsely mapped
        return [walker(motions.circle_path((0.0, 0.0), 3.2, 1.0))]
    if name == 'seated':
        return [motions.seated(t, (0.0, 0.0), rng.uniform(0, 2 * np.pi), 0.9, body_rng)]
    if name == 'lying':
        return [motions.lying(t, (0.0, 0.0), rng.uniform(0, 2 * np.pi), 0.45, body_rng)]
    if name == 'office':
        for x0 in (-2.5, 1.5):  # two desks (mapped), their chairs not
            world.boxes.append(Box(np.array([x0, 1.8, 0.0]), np.array([x0 + 1.2, 2.5, 0.75]), 1.5))
        return [walker(motions.shuttle_path((-4.0, -0.5), (4.0, -0.5), 1.0)),
                walker(motions.shuttle_path((3.5, -2.5), (-3.5, -2.0), 0.8), 0.3),
                motions.seated(t, (-1.9, 1.3), np.pi / 2, 0.45, body_rng),
                motions.seated(t, (2.1, 1.3), np.pi / 2, 0.45, body_rng)]
    return [walker(motions.circle_path((0.0, 0.0), 3.0, 1.1))]  # walk, drift, reset, static


def _contact_heights(name: str, people: list[np.ndarray], body_rng: np.random.Generator
                     ) -> np.ndarray:
    """Each person's contact height above its surface (metres, NaN for who sits or lies), added
    to their joints' z in place."""
    heights = body_rng.uniform(*(HAND_HEIGHT_M if name == 'handstand' else SOLE_HEIGHT_M),
                               len(people))
    if name in ('seated', 'lying', 'office'):  # nobody seated or lying stands on anything
        heights[len(people) - (2 if name == 'office' else 1):] = math.nan
    for person, height in zip(people, heights):
        person[:, :, 2] += 0.0 if math.isnan(height) else height  # its contact above its surface
    return heights


def _camera(name: str, root: np.ndarray, t: np.ndarray, rng: np.random.Generator
            ) -> tuple[np.ndarray, np.ndarray]:
    """The camera's true path: R_wc (T, 3, 3) and centres (T, 3) metres, world frame, following
    or watching the first person's ``root`` (T, 3)."""
    if name == 'ego':
        return rigs.head_mounted(root, t, rng)
    if name == 'static':
        return rigs.static(np.array([0.0, 0.0, 0.8]), t, np.array([0.0, -6.2, 1.6]))
    if name in ('seated', 'lying'):
        return rigs.static(root[0] * [1, 1, 0] + [0, 0, 0.6], t,
                           root[0] * [1, 1, 0] + [0.0, -3.5, 1.6])
    if name in ('occluded', 'office'):
        return rigs.side(root, t, offset_y=-4.8)
    if name == 'stairs':
        return rigs.side(root, t, offset_y=-4.5)
    return rigs.follow(root, t, rng, distance=4.5 if name == 'crowd' else 3.5)


def _slam_scale(name: str, T: int, scale0: float, rng: np.random.Generator
                ) -> tuple[Callable[[int], float], list[int]]:
    """The SLAM's scale (SLAM units per metre) at each frame index, and the frames where its
    segments start: drifting (``drift``), re-initialised half-way (``reset``) or constant."""
    if name == 'drift':
        return (lambda i: scale0 * (1.0 + DRIFT_TOTAL * i / (T - 1))), [0]
    if name == 'reset':
        reset_at = T // 2
        scale1 = scale0 * float(np.exp(rng.uniform(math.log(0.4), math.log(2.5))))
        return (lambda i: scale0 if i < reset_at else scale1), [0, reset_at]
    return (lambda i: scale0), [0]


@dataclass
class _Hmr:
    """The HMR model's joints: per joints frame, its stamp (int ns), the people's joints (P, K, 3)
    metres camera frame, their true world joints, their ids; the frames with an outlier."""

    stamps_ns: np.ndarray
    joints_cam: list[np.ndarray]
    joints_world: list[np.ndarray]
    person_ids: list[np.ndarray]
    outlier_frames: np.ndarray


def _hmr(people: list[np.ndarray], joint_layout: str, stamps: np.ndarray, R_world: np.ndarray,
         c_world: np.ndarray, K: np.ndarray, depth_bias: np.ndarray,
         body_rng: np.random.Generator) -> _Hmr:
    """The same bodies as the HMR model sees them, in ``joint_layout``: each frame's people in
    view, predicted with the frame's ``depth_bias`` (T,) and noise."""
    layout = BUILT_IN[joint_layout]
    people = [to_layout(person, joint_layout) for person in people]
    j_stamps, j_cam, j_world, ids, outliers = [], [], [], [], []
    for i in range(len(stamps)):
        preds, truths, who = [], [], []
        for pid, person in enumerate(people):
            cam = (person[i] - c_world[i]) @ R_world[i]
            if not in_view(cam, K, rigs.WIDTH, rigs.HEIGHT, layout):
                continue
            pred, outlier = predict(person[i], R_world[i], c_world[i], depth_bias[i], body_rng,
                                    layout)
            preds.append(pred)
            truths.append(person[i])
            who.append(pid)
            if outlier:
                outliers.append(i)
        if preds:
            j_stamps.append(stamps[i])
            j_cam.append(np.stack(preds))
            j_world.append(np.stack(truths))
            ids.append(np.array(who))
    return _Hmr(np.array(j_stamps, dtype=np.int64), j_cam, j_world, ids,
                np.array(sorted(set(outliers)), dtype=int))
