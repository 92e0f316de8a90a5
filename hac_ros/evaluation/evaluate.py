"""``hac eval OUT --gt IN``: the metrics of a replayed recording against its ground truth.

Three rows, so that a number has something to be compared with:

- ``hac``: the outputs in OUT (the camera of ``/hac/pose``, ``/hac/odometry``,
  ``/hac/human_joints``, ``/hac/scale``);
- ``no calibration``: the same core on IN with the scale fixed at 1 (SLAM units taken as metres);
- ``true scale``: the same core on IN with the true scale of each moment (``/gt/scale``), the best
  any scale estimate could do with these SLAM poses and HMR joints.

The two reference rows run the core once on IN with its metric outputs deferred and resolve them
with each reference scale as the offline replay resolves OUT
(:func:`hac_ros.core.offline.resolve_offline`: the same final ground planes), so that resets are
anchored and the frame aligned as in OUT.
Metrics (docs/interface.md, "Metrics"; implemented in :mod:`hac_ros.evaluation.metrics`): ATE and
ATE-S (m, camera centres of ``/hac/pose``, Sim(3) / SE(3) alignment, mean), RPE (m and %, the
translation of ``/hac/odometry`` over 1 s steps: odometry is judged by its relative error), W-MPJPE
and WA-MPJPE (mm, 100-frame chunks), RTE (%), PA-MPJPE (mm), and the scale error (%) of the final
estimate and of every frame against the truth of that moment.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hac_ros.core.basics.outputs import HumanJointsOut, OdometryOut, Output, PoseOut, ScaleOut
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.layouts import BUILT_IN
from hac_ros.core.offline import resolve_offline
from hac_ros.core.rules.params import HacParams
from hac_ros.evaluation import metrics
from hac_ros.recording.reader import Recording
from hac_ros.recording.tracks import (
    CameraTrack,
    JointsTrack,
    Replayed,
    ScaleTrack,
    Truth,
    read_output,
    read_truth,
)

# the core fed a recording offline, its outputs deferred (hac_ros.replay.feeder.offline_run)
OfflineRun = Callable[[Recording, HacParams], Calibrator]

ROOT_JOINT = 0  # pelvis (SMPL-24)
# Outputs carry the input stamps exactly and the ground truth is at the same stamps; 1 ms absorbs
# a recording whose ground truth was stamped by another clock rounding.
MATCH_TOLERANCE_NS = 1_000_000
COLUMNS = (  # key, header, format
    ('ate_m', 'ATE (m)', '.3f'),
    ('ate_s_m', 'ATE-S (m)', '.3f'),
    ('rpe_m', 'RPE 1 s (m)', '.3f'),
    ('rpe_pct', 'RPE (%)', '.2f'),
    ('w_mpjpe_mm', 'W-MPJPE (mm)', '.1f'),
    ('wa_mpjpe_mm', 'WA-MPJPE (mm)', '.1f'),
    ('rte_pct', 'RTE (%)', '.2f'),
    ('pa_mpjpe_mm', 'PA-MPJPE (mm)', '.1f'),
    ('scale_error_pct', 'scale err. final (%)', '.2f'),
    ('scale_error_frames_pct', 'scale err. per frame (%)', '.2f'),
)


# ============================================================================ reference rows
@dataclass
class _Collector:
    poses: list[PoseOut] = field(default_factory=list)
    odometry: list[OdometryOut] = field(default_factory=list)
    joints: list[HumanJointsOut] = field(default_factory=list)
    scale: list[ScaleOut] = field(default_factory=list)

    def __call__(self, outputs: list[Output]) -> None:
        for o in outputs:
            if isinstance(o, PoseOut):
                self.poses.append(o)
            elif isinstance(o, OdometryOut):
                self.odometry.append(o)
            elif isinstance(o, HumanJointsOut):
                self.joints.append(o)
            elif isinstance(o, ScaleOut):
                self.scale.append(o)

    def as_replayed(self) -> Replayed:
        camera, odometry = _track(self.poses), _track(self.odometry)
        joints = JointsTrack(np.array([o.stamp_ns for o in self.joints], dtype=np.int64),
                             [o.joints_metric for o in self.joints])
        scale = ScaleTrack(np.array([o.stamp_ns for o in self.scale], dtype=np.int64),
                           np.array([o.scale for o in self.scale]))
        return Replayed(camera, joints, scale, [], None, odometry)


def _track(outputs: list[PoseOut] | list[OdometryOut]) -> CameraTrack:
    if not outputs:
        return CameraTrack()
    return CameraTrack(np.array([o.stamp_ns for o in outputs], dtype=np.int64),
                       np.array([o.position_metric for o in outputs]),
                       np.array([o.rotation_metric for o in outputs]))


def reference_runs(gt_path: str | Path, params: HacParams, truth: Truth,
                   offline_run: OfflineRun) -> dict[str, Replayed]:
    """'no calibration' (scale 1) and 'true scale' (/gt/scale) through the core on IN, from one
    ``offline_run`` of it."""
    scales: dict[str, Any] = {'no calibration': lambda stamp_ns: 1.0}
    if truth.scale is not None and len(truth.scale):
        true_scale = truth.scale
        scales['true scale'] = lambda stamp_ns: float(true_scale.at(np.array([stamp_ns]))[0])
    with Recording(gt_path) as rec:
        # one offline run, resolved once per reference scale (the same outputs as a run per scale)
        calibrator = offline_run(rec, params)
    runs: dict[str, Replayed] = {}
    for name, output_scale in scales.items():
        collect = _Collector()
        collect(resolve_offline(calibrator, output_scale).outputs)
        runs[name] = collect.as_replayed()
    return runs


# ============================================================================ metrics
def match(a_ns: np.ndarray, b_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices (ia, ib) of stamps that agree within :data:`MATCH_TOLERANCE_NS`."""
    ia, ib = metrics.associate_stamps(np.asarray(a_ns, dtype=np.int64),
                                      np.asarray(b_ns, dtype=np.int64),
                              MATCH_TOLERANCE_NS)
    return np.asarray(ia, dtype=int), np.asarray(ib, dtype=int)


def person_tracks(pred: JointsTrack, truth: JointsTrack) -> list[tuple[np.ndarray, np.ndarray]]:
    """For each person index k: (pred (F_k, K, 3), truth (F_k, K, 3)) over the matched frames
    where both have a k-th person (people keep their block order in both topics; K the joint
    layout's joints per person)."""
    ip, it = match(pred.stamps_ns, truth.stamps_ns)
    people = max((len(pred.joints[i]) for i in ip), default=0)
    tracks = []
    for k in range(people):
        pairs = [(pred.joints[i][k], truth.joints[j][k]) for i, j in zip(ip, it)
                 if len(pred.joints[i]) > k and len(truth.joints[j]) > k]
        if pairs:
            tracks.append((np.array([p for p, _ in pairs]), np.array([t for _, t in pairs])))
    return tracks


def _weighted(values: list[tuple[float, int]]) -> float:
    values = [(v, n) for v, n in values if math.isfinite(v) and n > 0]
    total = sum(n for _, n in values)
    return sum(v * n for v, n in values) / total if total else math.nan


def row_metrics(run: Replayed, truth: Truth) -> dict[str, float]:
    """The metrics of one row against the truth (NaN where an input is missing)."""
    out: dict[str, float] = {k: math.nan for k, _, _ in COLUMNS}
    out['camera_frames'] = 0
    out['joints_frames'] = 0
    if truth.camera is not None and len(run.camera) >= 3:
        ie, ig = match(run.camera.stamps_ns, truth.camera.stamps_ns)
        if len(ie) >= 3:
            est, gt = run.camera.positions[ie], truth.camera.positions[ig]
            out['ate_m'] = float(metrics.ate(est, gt))
            out['ate_s_m'] = float(metrics.ate_s(est, gt))
            out['camera_frames'] = len(ie)
    if truth.camera is not None and len(run.odometry) >= 2:
        ie, ig = match(run.odometry.stamps_ns, truth.camera.stamps_ns)
        if len(ie) >= 2:
            out['rpe_m'], out['rpe_pct'] = metrics.rpe(
                run.odometry.positions[ie], run.odometry.rotations[ie], truth.camera.positions[ig],
                truth.camera.rotations[ig], run.odometry.stamps_ns[ie])
    if truth.joints is not None and len(run.joints):
        tracks = person_tracks(run.joints, truth.joints)
        if tracks:
            out['w_mpjpe_mm'] = _weighted([(metrics.w_mpjpe(p, t), len(p)) for p, t in tracks])
            out['wa_mpjpe_mm'] = _weighted([(metrics.wa_mpjpe(p, t), len(p)) for p, t in tracks])
            out['rte_pct'] = _weighted([(metrics.rte(p[:, ROOT_JOINT], t[:, ROOT_JOINT]), len(p))
                                        for p, t in tracks if len(p) >= 3])
            out['pa_mpjpe_mm'] = _weighted([(metrics.pa_mpjpe(p, t), len(p)) for p, t in tracks])
            out['joints_frames'] = int(sum(len(p) for p, _ in tracks))
    if truth.scale is not None and len(truth.scale) and len(run.scale):
        true_at = truth.scale.at(run.scale.stamps_ns)
        per_frame = np.asarray(metrics.scale_error(run.scale.values, true_at), dtype=float)
        out['scale_error_pct'] = float(per_frame.reshape(-1)[-1])
        out['scale_error_frames_pct'] = float(np.mean(per_frame))
        out['scale_error_frames_max_pct'] = float(np.max(per_frame))
        out['scale_final'] = float(run.scale.values[-1])
    return out


@dataclass
class Evaluation:
    """The rows of ``hac eval`` and what they were computed on."""

    output_path: str
    gt_path: str
    rows: dict[str, dict[str, float]]
    true_scale: dict[str, float]
    frames: dict[str, int]

    def as_dict(self) -> dict[str, Any]:
        return {'output': self.output_path, 'ground_truth': self.gt_path,
                'rows': {k: {m: _json_number(v) for m, v in row.items()}
                         for k, row in self.rows.items()},
                'true_scale': self.true_scale, 'frames': self.frames}

    def markdown(self) -> str:
        header = '| | ' + ' | '.join(h for _, h, _ in COLUMNS) + ' |'
        rule = '| --- |' + ' ---: |' * len(COLUMNS)
        lines = [header, rule]
        for name, row in self.rows.items():
            cells = [_cell(row.get(key, math.nan), fmt) for key, _, fmt in COLUMNS]
            lines.append(f'| {name} | ' + ' | '.join(cells) + ' |')
        return '\n'.join(lines)

    def text(self) -> str:
        info = [f'hac eval: {self.output_path} against {self.gt_path}']
        if self.frames:
            info.append('  matched: ' + ', '.join(f'{k} {v}' for k, v in self.frames.items()))
        if self.true_scale:
            info.append('  true scale: ' + ', '.join(f'{k} {v:.6g}'
                                                     for k, v in self.true_scale.items()))
        return '\n'.join(info) + '\n\n' + self.markdown()


def _cell(value: float, fmt: str) -> str:
    return '–' if value is None or not math.isfinite(value) else format(value, fmt)


def _json_number(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def evaluate(output_path: str | Path, gt_path: str | Path, params: HacParams | None = None,
             offline_run: OfflineRun | None = None) -> Evaluation:
    """The metrics of OUT against IN's ground truth, beside the two reference rows when
    ``offline_run`` is given: the core fed IN offline, as the replay feeds it
    (:func:`hac_ros.replay.feeder.offline_run`), whose outputs they resolve."""
    if params is None:  # the defaults, in the input recording's joint layout
        with Recording(gt_path) as rec:
            layout = rec.layout.name
        params = HacParams().replace(joint_layout=layout) if layout in BUILT_IN else HacParams()
    replayed = read_output(output_path)
    truth = read_truth(gt_path)
    rows = {'hac': row_metrics(replayed, truth)}
    if offline_run is not None:
        for name, run in reference_runs(gt_path, params, truth, offline_run).items():
            rows[name] = row_metrics(run, truth)
    true_scale: dict[str, float] = {}
    if truth.scale is not None and len(truth.scale):
        true_scale = {'first': float(truth.scale.values[0]), 'last': float(truth.scale.values[-1]),
                      'min': float(np.min(truth.scale.values)),
                      'max': float(np.max(truth.scale.values))}
    frames = {'camera poses': int(rows['hac'].get('camera_frames', 0)),
              'joints frames': int(rows['hac'].get('joints_frames', 0))}
    if truth.camera is not None:
        frames['ground-truth poses'] = len(truth.camera)
    return Evaluation(str(output_path), str(gt_path), rows, true_scale, frames)
