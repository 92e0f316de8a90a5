"""One scene through the core (our configurations) and through the literal authors' method.

A scene is a simulated scenario (``hac_ros.simulate``) or a real-data composite (bench/composite.py)
turned into the calibrator's inputs in SPEC's order plus the truth. Per run:

- offline (the replay's default): the deferred outputs resolved with the offline schedule
  (hac_ros.core.offline) exactly as ``hac replay`` does; the scale error is taken frame by frame
  against the truth of that moment (median over the frames), so drifting and reset recordings are
  judged like constant ones;
- online (causal, what hac_node publishes): the median error over the published scales, the error
  at the end, and the time from the first joints frame to the moment after which every published
  scale is within 5 % of the truth;
- W-MPJPE (mm) of the world joints, each person a track (SPEC, Metrics): unfiltered (what the
  targets compare with the literal method) and with the offline human filter (``smooth``). Each
  configuration's figures are taken on the joints frames both it and the literal method publish,
  and the literal method's W-MPJPE on those same frames is reported beside them
  (``w_mpjpe_literal``): W-MPJPE aligns each 100-frame chunk on its first two frames, so one frame
  more or less at the start shifts every chunk and moves the figure by tens of millimetres.

The literal authors' method (their code, as issue 19 states it; the library's
:mod:`hac_ros.core.estimate.literal`, which ``calibrate(..., literal=True)`` runs too): per frame every
joint's ray against every map point (cone cos > 0.999, the median distance of the points in the
cone), the largest ratio over the joints is the frame's scale, one median over the frames; world
joints ``R_wc J + s c`` in the SLAM frame. Here each frame uses the latest map of the recording.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hac_ros.core.basics.numeric import MAD_TO_SIGMA
from hac_ros.core.basics.outputs import (
    DiagnosticsOut,
    HumanJointsOut,
    OdometryOut,
    PoseOut,
    ResetOut,
    SampleOut,
    ScaleOut,
)
from hac_ros.core.bodies.human_filter import smooth_outputs
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.estimate.estimator import sequence_scale
from hac_ros.core.estimate.literal import max_ratio, world_joints
from hac_ros.core.estimate.segment import FEW_SAMPLES_MIN
from hac_ros.core.offline import resolve_offline
from hac_ros.core.rules.health import OK, HealthMonitor
from hac_ros.core.rules.params import HacParams
from hac_ros.evaluation import metrics
from hac_ros.simulate.feed import feed_events

CONVERGED_REL = 0.05


@dataclass
class Scene:
    """Inputs and truth of one recording (frames and units in the names).

    events: (stamp ns, 'map' | 'pose' | 'joints', payload) in processing order (maps: (points
    (N, 3) SLAM units, frame id); poses: (R_wc, c SLAM units, frame id); joints: (joints (P, 24, 3)
    metres camera frame, frame id)); K, width, height: the camera; true_scale_at(stamps) ->
    metres per SLAM unit; joints_world[k] (P, 24, 3) metres and person_ids[k] (P,) at the joints
    frames, in the order of the joints events; gt_R_wc (T, 3, 3) and gt_c (T, 3) metres the true
    camera at the pose stamps (camera to a z-up world whose floor is z = 0); hmr_bias: the HMR's
    mean relative depth bias.
    """

    name: str
    seed: int
    events: list[tuple[int, str, tuple]]
    K: np.ndarray
    width: int
    height: int
    pose_stamps_ns: np.ndarray
    true_scale: np.ndarray  # (T,) at the pose stamps
    joints_world: list[np.ndarray]
    person_ids: list[np.ndarray]
    gt_R_wc: np.ndarray
    gt_c: np.ndarray
    hmr_bias: float = 0.0

    def true_scale_at(self, stamps_ns: np.ndarray) -> np.ndarray:
        i = np.searchsorted(self.pose_stamps_ns, np.asarray(stamps_ns), side='right') - 1
        return self.true_scale[np.clip(i, 0, len(self.true_scale) - 1)]


def scene_from_scenario(sc: Any) -> Scene:
    from hac_ros.simulate.feed import scenario_events

    return Scene(sc.name, sc.seed, list(scenario_events(sc)), sc.K, sc.width, sc.height,
                 np.asarray(sc.pose_stamps_ns), np.broadcast_to(sc.true_scale,
                                                                (len(sc.pose_stamps_ns),)).copy(),
                 list(sc.gt_joints_world), list(sc.person_ids), sc.gt_R_wc, sc.gt_c, sc.hmr_bias)


def scene_from_composite(data: Any, seed: int, hmr_bias: float = 0.0) -> Scene:
    from composite import HEIGHT, WIDTH, events

    return Scene(f'composite:{data.name}', seed, events(data), data.K, WIDTH, HEIGHT,
                 np.asarray(data.stamps_ns), np.asarray(data.true_scale, dtype=float),
                 [j[None] for j in data.joints_world], [np.array([0])] * len(data.joints_world),
                 data.R_gt, data.c_gt, hmr_bias)


def feed(cal: Calibrator, scene: Scene) -> list[Any]:
    out = list(cal.add_camera_info(scene.K, scene.width, scene.height))
    return out + feed_events(cal, scene.events) + cal.flush()


def w_mpjpe(scene: Scene, stamps_ns: list[int], joints: list[np.ndarray]) -> float:
    """W-MPJPE (mm) of world joints at joints-frame stamps against the truth, per person track,
    weighted by each track's frames."""
    frame_of = {int(s): k for k, s in enumerate(_joint_stamps(scene))}
    tracks: dict[int, tuple[list, list]] = {}
    for stamp, people in zip(stamps_ns, joints):
        k = frame_of.get(int(stamp))
        if k is None:
            continue
        for p, pid in enumerate(scene.person_ids[k]):
            if p < len(people) and np.isfinite(people[p]).all():
                pred, gt = tracks.setdefault(int(pid), ([], []))
                pred.append(people[p])
                gt.append(scene.joints_world[k][p])
    values = [(metrics.w_mpjpe(np.array(p), np.array(g)), len(p)) for p, g in tracks.values()
              if len(p) >= 2]
    total = sum(n for _, n in values)
    return sum(v * n for v, n in values) / total if total else math.nan


def _joint_stamps(scene: Scene) -> list[int]:
    return [s for s, kind, _ in scene.events if kind == 'joints']


World = dict[int, np.ndarray]  # joints stamp ns -> world joints (P, 24, 3) metres


def run_ours(scene: Scene, params: HacParams, literal: World, online: bool = False
             ) -> dict[str, float]:
    """Our offline figures (and the online ones when asked) for one configuration; ``literal``:
    the literal method's world joints, for W-MPJPE on the frames both publish."""
    cal = Calibrator(params, offline=True)
    feed(cal, scene)
    return figures(scene, params, cal, literal, online)


def figures(scene: Scene, params: HacParams, cal: Calibrator, literal: World,
            online: bool = False) -> dict[str, float]:
    """:func:`run_ours`' figures of an offline calibrator ``cal`` fed ``scene``'s inputs,
    however they were fed."""
    samples = [o for o in cal.journal or [] if isinstance(o, SampleOut) and o.accepted]
    out: dict[str, float] = {'samples': len(samples)}
    if len(samples) < FEW_SAMPLES_MIN:  # fewer: offline has no estimate either
        return {**out, 'scale_err': math.nan, 'scale_bias': math.nan, 'w_mpjpe': math.nan}
    # as the replay, the humans smoothed below (W-MPJPE is measured on both)
    resolved = resolve_offline(cal, smooth_humans=False).outputs
    frames = [o for o in resolved if isinstance(o, ScaleOut)]
    signed = _signed_errors(scene, frames)
    humans = [o for o in resolved if isinstance(o, HumanJointsOut)]
    raw = w_mpjpe(scene, *_common(humans, literal))
    offline_humans = {o.stamp_ns: o.joints_metric.copy() for o in humans}
    smooth_outputs(humans, cal.layout)  # the replay's offline human_filter: smooth
    common = _common(humans, literal)
    poses = [o for o in resolved if isinstance(o, PoseOut)]
    accepted = np.log([o.scale for o in samples])
    out['sample_sigma'] = 100.0 * MAD_TO_SIGMA * float(np.median(np.abs(accepted - np.median(
        accepted))))  # a sample's own spread, %
    out.update(scale_bias=float(np.median(signed)), scale_err=float(np.median(np.abs(signed))),
               scale_err_max=float(np.max(np.abs(signed))),
               w_mpjpe=raw, w_mpjpe_filtered=w_mpjpe(scene, *common),
               w_mpjpe_literal=w_mpjpe(scene, common[0], [literal[t] for t in common[0]]),
               fallback_pct=100.0 * cal.status().fallback_rate,
               hmr_excess=float(np.median(np.abs(signed))) - 100.0 * abs(scene.hmr_bias))
    out['w_mpjpe_vs_literal'] = out['w_mpjpe'] - out['w_mpjpe_literal']
    if params.metric_frame_alignment == 'gravity':
        out.update(gravity_frame(scene, poses, frames))
    if online:
        out.update(_online(scene, params, offline_humans,
                           {o.stamp_ns: o.position_metric for o in poses}, out['scale_bias']))
    return out


def gravity_frame(scene: Scene, poses: list[PoseOut], scales: list[ScaleOut]) -> dict[str, float]:
    """How well the gravity-aligned metric frame sits (its floor is z = 0): ``camera_height_err``
    the median relative error of the camera's height (/hac/pose z against the true height above
    the floor), %; ``floor_err`` the median |z| (metres) of the true floor below each person's
    lowest joint, placed in the metric frame through the camera of its frame (the true camera-frame
    vector, at the published scale over the true one)."""
    index = {int(s): i for i, s in enumerate(scene.pose_stamps_ns)}
    rel = [o.position_metric[2] / scene.gt_c[index[o.stamp_ns], 2] - 1.0 for o in poses
           if o.stamp_ns in index]
    pose_at = {o.stamp_ns: o for o in poses}
    scale_at = {o.stamp_ns: o.scale for o in scales}
    floor = []
    for k, stamp in enumerate(_joint_stamps(scene)):
        pose, i = pose_at.get(stamp), index.get(stamp)
        if pose is None or i is None or stamp not in scale_at:
            continue
        ratio = scale_at[stamp] / float(scene.true_scale_at(np.array([stamp]))[0])
        for person in scene.joints_world[k]:
            below = person[np.argmin(person[:, 2])] * [1.0, 1.0, 0.0]  # the floor under the feet
            v_cam = scene.gt_R_wc[i].T @ (below - scene.gt_c[i])
            floor.append(abs(float((pose.position_metric + ratio * pose.rotation_metric @ v_cam)[2])))
    return {'camera_height_err': 100.0 * float(np.median(np.abs(rel))) if rel else math.nan,
            'floor_err': float(np.median(floor)) if floor else math.nan}


def _common(humans: list[HumanJointsOut], literal: World) -> tuple[list[int], list[np.ndarray]]:
    """Stamps and joints of ``humans`` at the frames the literal method also published."""
    kept = [o for o in humans if o.stamp_ns in literal]
    return [o.stamp_ns for o in kept], [o.joints_metric for o in kept]


def _signed_errors(scene: Scene, scales: list[ScaleOut]) -> np.ndarray:
    """Per published scale, its signed relative error against the truth of that moment, %."""
    stamps = np.array([o.stamp_ns for o in scales], dtype=np.int64)
    values = np.array([o.scale for o in scales])
    return 100.0 * (values / scene.true_scale_at(stamps) - 1.0) if len(values) else np.full(1, np.nan)


def _online(scene: Scene, params: HacParams, offline_humans: World,
            offline_positions: dict[int, np.ndarray], offline_bias: float) -> dict[str, float]:
    """The online run's figures (what hac_node publishes; the world humans unfiltered, like the
    offline ones they are compared with): its scale error, its W-MPJPE and ATE-S on the frames
    after convergence beside the offline run's on the same frames, and the /diagnostics statuses
    that said OK and converged while the scale was more than CONVERGED_REL off the truth; the
    ``±``'s coverage of the truth, and of the truth times the run's own offline bias
    (``offline_bias``, %: what the ``±`` leaves out by design, the contact height and the HMR's
    bias, removed)."""
    outputs = feed(Calibrator(params.replace(human_filter='none')), scene)
    scales = [o for o in outputs if isinstance(o, ScaleOut)]
    signed = _signed_errors(scene, scales)
    joint_stamps = _joint_stamps(scene)
    converged = math.nan
    if len(scales) and joint_stamps:
        bad = np.flatnonzero(np.abs(signed) > 100.0 * CONVERGED_REL)
        first_good = 0 if not bad.size else int(bad[-1]) + 1
        if first_good < len(scales):
            converged = (scales[first_good].stamp_ns - joint_stamps[0]) / 1e9
    out = {'online_err': float(np.median(np.abs(signed))),
           'online_final_err': float(abs(signed[-1])), 'converged_s': converged}
    humans = [o for o in outputs if isinstance(o, HumanJointsOut) and o.stamp_ns in offline_humans]
    if humans:
        stamps = [o.stamp_ns for o in humans]
        out['w_mpjpe_online'] = w_mpjpe(scene, stamps, [o.joints_metric for o in humans])
        out['w_mpjpe_offline'] = w_mpjpe(scene, stamps, [offline_humans[t] for t in stamps])
    index = {int(s): i for i, s in enumerate(scene.pose_stamps_ns)}
    poses = [o for o in outputs if isinstance(o, PoseOut) and o.stamp_ns in offline_positions
             and o.stamp_ns in index]
    if len(poses) > 2:
        true = scene.gt_c[[index[o.stamp_ns] for o in poses]]
        out['ate_s_online'] = metrics.ate_s(np.array([o.position_metric for o in poses]), true)
        out['ate_s_offline'] = metrics.ate_s(np.array([offline_positions[o.stamp_ns]
                                                       for o in poses]), true)
    statuses = [o.status for o in outputs if isinstance(o, DiagnosticsOut)]
    true = scene.true_scale_at(np.array([st.stamp_ns for st in statuses], dtype=np.int64))
    log_err_signed = np.array([math.log(st.scale / t) if st.scale > 0 else math.inf
                               for st, t in zip(statuses, true)])
    log_err = np.abs(log_err_signed)
    off = [bool(abs(st.scale / t - 1.0) > CONVERGED_REL) and st.converged
           for st, t in zip(statuses, true)]
    # the level /diagnostics gives each status, in order (hac_ros.core.rules.health, as the node)
    monitor = HealthMonitor(params.metric_frame_alignment == 'gravity')
    ok = [monitor.assess(st).level == OK for st in statuses]
    # the ± a user reads (published) against the truth of the moment, and the estimate's own
    # (σ_stat) against the truth times the run's own offline bias, on the published statuses
    published = np.array([st.publishing and st.scale > 0 for st in statuses], dtype=bool)
    rel_pub = np.array([st.spread / st.scale if st.scale > 0 else math.nan for st in statuses])
    rel_stat = np.array([st.spread_stat / st.scale if st.scale > 0 else math.nan
                         for st in statuses])
    own_err = np.abs(log_err_signed - math.log1p(offline_bias / 100.0))
    out.update(statuses=len(statuses), converged_wrong=int(sum(off)),
               ok_wrong=int(sum(w and k for w, k in zip(off, ok))), ok_statuses=int(sum(ok)),
               sigma_statuses=int(published.sum()),
               cover1=int(np.sum(log_err[published] <= rel_pub[published])),
               cover2=int(np.sum(log_err[published] <= 2.0 * rel_pub[published])),
               cover1_own=int(np.sum(own_err[published] <= rel_stat[published])),
               cover2_own=int(np.sum(own_err[published] <= 2.0 * rel_stat[published])),
               relocking=int(sum('relocking' in st.conditions for st in statuses)),
               window_samples=float(np.median([st.samples for st in statuses]))
               if statuses else math.nan)
    out.update(availability(scene, outputs, statuses, ok, params.min_samples))
    return out


def availability(scene: Scene, outputs: list[Any], statuses: list[Any], ok: list[bool],
                 min_samples: int) -> dict[str, float]:
    """How soon and how much an online run speaks (issue 43): the stamp time (s) and the accepted
    samples from the first accepted sample to the first OK status (``first_ok_s``,
    ``first_ok_samples``); the statuses after it and those of them OK (``after_ok``,
    ``after_ok_ok``); whether a scale was published; and, from each segment's first published
    pose to the segment's end, its SLAM poses and those with odometry (``flow_poses``,
    ``flow_odometry``), its joints frames with someone in them and those published
    (``flow_frames``, ``flow_joints``)."""
    accepted = np.array(sorted(o.stamp_ns for o in outputs
                               if isinstance(o, SampleOut) and o.accepted), dtype=np.int64)
    published = any(isinstance(o, ScaleOut) for o in outputs)
    enough = accepted.size >= min_samples
    out: dict[str, float] = {'published': float(published), 'runs_enough': float(enough),
                             'published_enough': float(enough and published)}
    first = next((k for k, good in enumerate(ok) if good), None)
    if first is not None and accepted.size:
        stamp = statuses[first].stamp_ns
        out['first_ok_s'] = (stamp - int(accepted[0])) / 1e9
        out['first_ok_samples'] = float(np.searchsorted(accepted, stamp, side='right'))
        out['after_ok'] = float(len(ok) - first)
        out['after_ok_ok'] = float(sum(ok[first:]))
    resets = sorted(o.stamp_ns for o in outputs if isinstance(o, ResetOut))
    bounds = [*resets, 2 ** 62]
    segment_of = lambda stamp: int(np.searchsorted(bounds, stamp, side='right'))  # noqa: E731
    first_pose: dict[int, int] = {}
    for o in outputs:
        if isinstance(o, PoseOut):
            first_pose.setdefault(segment_of(o.stamp_ns), o.stamp_ns)
    odometry = {o.stamp_ns for o in outputs if isinstance(o, OdometryOut)}
    joints = {o.stamp_ns for o in outputs if isinstance(o, HumanJointsOut)}
    poses = [s for s, kind, _ in scene.events if kind == 'pose']
    frames = [s for s, kind, p in scene.events if kind == 'joints' and len(p[0])]

    def flowing(stamps: list[int]) -> list[int]:
        return [t for t in stamps if segment_of(t) in first_pose
                and t >= first_pose[segment_of(t)]]
    flow_poses, flow_frames = flowing(poses), flowing(frames)
    out.update(flow_poses=float(len(flow_poses)),
               flow_odometry=float(sum(t in odometry for t in flow_poses)),
               flow_frames=float(len(flow_frames)),
               flow_joints=float(sum(t in joints for t in flow_frames)))
    return out


def run_literal(scene: Scene) -> tuple[dict[str, float], World]:
    """The literal authors' method on ``scene`` (module docstring): its figures and its world
    joints per frame."""
    maps: list[tuple[int, np.ndarray]] = []
    poses: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    frames: list[tuple[int, np.ndarray, float]] = []  # stamp, joints, sample
    for stamp, kind, payload in scene.events:
        if kind == 'map':
            maps.append((stamp, np.asarray(payload[0], dtype=float)))
        elif kind == 'pose':
            poses[stamp] = (payload[0], payload[1])
        elif maps and stamp in poses:
            R, c = poses[stamp]
            for person in payload[0]:
                frames.append((stamp, person, max_ratio(maps[-1][1], R, c, person)))
    samples = np.array([s for _, _, s in frames])
    samples = samples[np.isfinite(samples)]
    if not samples.size:
        return {'scale_err': math.nan, 'scale_bias': math.nan, 'w_mpjpe': math.nan}, {}
    s = sequence_scale(samples)
    signed = 100.0 * (s / scene.true_scale_at(np.array(sorted(poses))) - 1.0)
    world: dict[int, list[np.ndarray]] = {}
    for stamp, person, _ in frames:
        R, c = poses[stamp]
        world.setdefault(stamp, []).append(world_joints(person, R, c, s))
    stamps = sorted(world)
    joints = {t: np.array(world[t]) for t in stamps}
    return {'scale_bias': float(np.median(signed)), 'scale_err': float(np.median(np.abs(signed))),
            'w_mpjpe': w_mpjpe(scene, stamps, [joints[t] for t in stamps]),
            'samples': int(samples.size)}, joints
