"""``hac plot OUT [--gt IN] -o DIR``: figures of a replayed recording (PNG, matplotlib Agg).

- ``trajectories.png``: top-down view of the camera (raw SLAM with its units taken as metres,
  calibrated, ground truth) and of each person's root (pelvis) path.
- ``scale.png``: the per-frame scale samples (``/hac/samples``, a replay-only topic: map hits,
  ground-plane fallbacks, gated samples), the published scale (``/hac/scale``) with the estimator's
  spread band (``/diagnostics``), the true scale (``/gt/scale``) and the resets.
- ``fallback.png``: ground-plane fallback use and rejected inputs per second of stamp time, resets.
- ``heights.png``: the metric frame as published: the camera's z (``/hac/pose``) and people's
  lowest joint over time; gravity-aligned, z is the height above the floor (z = 0).

"Top-down" needs an up direction that no frame here states: it is the mean body up axis (pelvis to
neck) of the reference joints (the ground truth's, else the replay's), the same cue the core uses
for its ground normal. With ground truth the replay is brought into its frame by one SE(3) fit
(Umeyama without scale) of its camera centres and joints to the truth's, so a wrong scale stays
visible; the raw SLAM track gets the same placement (the metric frame is the SLAM frame scaled).
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from hac_ros.core.basics.errors import HacError
from hac_ros.core.basics.numeric import NS
from hac_ros.core.layouts import SMPL24, JointLayout
from hac_ros.core.rules.params import POSE_MSGTYPES
from hac_ros.evaluation.evaluate import match, person_tracks
from hac_ros.recording.atomic import signals_held
from hac_ros.recording.reader import Recording
from hac_ros.recording.tracks import (
    CameraTrack,
    JointsTrack,
    Replayed,
    Truth,
    read_camera,
    read_output,
    read_truth,
)

DPI = 100
FIGSIZE = {'trajectories': (8.0, 8.0), 'scale': (11.0, 6.0), 'fallback': (11.0, 6.0),
           'heights': (11.0, 5.0)}  # inches
SLAM_POSE_TOPIC = '/slam/pose'
COLOURS = {'gt': 'black', 'hac': 'tab:blue', 'slam': 'tab:gray', 'map': 'tab:blue',
           'ground': 'tab:orange', 'gated': 'tab:red', 'scale': 'tab:green', 'reset': 'tab:purple'}


def figure_size_px(name: str) -> tuple[int, int]:
    """The (width, height) in pixels of figure ``name`` (what the tests check)."""
    w, h = FIGSIZE[name]
    return int(round(w * DPI)), int(round(h * DPI))


# ============================================================================ geometry helpers
def up_axis(joints: JointsTrack, layout: JointLayout = SMPL24) -> np.ndarray | None:
    """The mean body up direction (3,) (the layout's lower → upper joints, e.g. pelvis → neck),
    unit, in the joints' frame; None without joints."""
    if not len(joints):
        return None
    axes = np.concatenate([layout.up_axis(j) for j in joints.joints if len(j)])
    axes = axes[np.all(np.isfinite(axes), axis=1)]
    if not len(axes):
        return None
    mean = axes.mean(axis=0)
    norm = np.linalg.norm(mean)
    return mean / norm if norm > 0 else None


def plane_basis(up: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """(2, 3): two horizontal unit axes, the first along the path's main horizontal direction."""
    up = up / np.linalg.norm(up)
    flat = positions - np.outer(positions @ up, up)
    flat = flat - flat.mean(axis=0) if len(flat) else flat
    if len(flat) >= 2 and np.linalg.norm(flat) > 0:
        e1 = np.linalg.svd(flat, full_matrices=False)[2][0]
    else:
        e1 = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 = e1 - (e1 @ up) * up
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(up, e1)])


def se3_fit(run: Replayed, truth: Truth) -> tuple[np.ndarray, np.ndarray] | None:
    """(R, t) with R @ p + t ≈ truth for the replay's points (Umeyama, no scale).

    Fitted on the matched camera centres and the matched people's joints together: a camera
    moving along a straight line alone leaves the rotation about that line undetermined.
    """
    from hac_ros.core.basics.similarity import umeyama

    src, dst = [], []
    if truth.camera is not None and len(run.camera):
        i, j = match(run.camera.stamps_ns, truth.camera.stamps_ns)
        src.append(run.camera.positions[i])
        dst.append(truth.camera.positions[j])
    if truth.joints is not None and len(run.joints):
        for pred, gt in person_tracks(run.joints, truth.joints):
            src.append(pred.reshape(-1, 3))
            dst.append(gt.reshape(-1, 3))
    if not src:
        return None
    src_points, dst_points = np.concatenate(src), np.concatenate(dst)
    finite = np.all(np.isfinite(src_points), axis=1) & np.all(np.isfinite(dst_points), axis=1)
    if finite.sum() < 3:
        return None
    _, R, t = umeyama(src_points[finite], dst_points[finite], with_scale=False)
    return np.asarray(R), np.asarray(t)


def _apply(fit: tuple[np.ndarray, np.ndarray] | None, points: np.ndarray) -> np.ndarray:
    if fit is None:
        return points
    R, t = fit
    return points @ R.T + t


# ============================================================================ figures
def plot_trajectories(path: Path, run: Replayed, truth: Truth | None,
                      slam: CameraTrack | None) -> None:
    import matplotlib.pyplot as plt

    reference_camera = truth.camera if truth is not None and truth.camera is not None else None
    reference_joints = truth.joints if truth is not None and truth.joints is not None else None
    up = up_axis(reference_joints, run.layout) if reference_joints is not None else None
    fit = se3_fit(run, truth) if truth is not None else None
    if up is None:
        up = up_axis(run.joints, run.layout)
        if up is not None and fit is not None:
            up = fit[0] @ up
    if up is None:
        up = np.array([0.0, 0.0, 1.0])
    base = reference_camera.positions if reference_camera is not None else run.camera.positions
    basis = plane_basis(up, base if len(base) else np.zeros((1, 3)))

    fig, ax = plt.subplots(figsize=FIGSIZE['trajectories'], dpi=DPI)
    if reference_camera is not None and len(reference_camera):
        xy = reference_camera.positions @ basis.T
        ax.plot(xy[:, 0], xy[:, 1], color=COLOURS['gt'], lw=2.0, label='camera, ground truth')
    if len(run.camera):
        xy = _apply(fit, run.camera.positions) @ basis.T
        ax.plot(xy[:, 0], xy[:, 1], color=COLOURS['hac'], lw=1.5, label='camera, calibrated')
    if slam is not None and len(slam):
        # the metric frame is the SLAM map frame scaled (until a reset): the same placement
        xy = _apply(fit, slam.positions) @ basis.T
        ax.plot(xy[:, 0], xy[:, 1], color=COLOURS['slam'], lw=1.2, ls='--', zorder=5,
                label='camera, raw SLAM (units as metres)')
    for k, (_, roots) in enumerate(_roots(run.joints, run.layout)):
        xy = _apply(fit, roots) @ basis.T
        ax.plot(xy[:, 0], xy[:, 1], color='tab:green', lw=1.2, alpha=0.8,
                label='people, calibrated' if k == 0 else None)
    if reference_joints is not None:
        for k, (_, roots) in enumerate(_roots(reference_joints, run.layout)):
            xy = roots @ basis.T
            ax.plot(xy[:, 0], xy[:, 1], color=COLOURS['gt'], lw=1.0, ls=':',
                    label='people, ground truth' if k == 0 else None)
    ax.set_aspect('equal', adjustable='datalim')
    frame = 'ground-truth world' if reference_camera is not None else 'metric frame'
    _finish(fig, ax, path, f'Top-down view ({frame}; replay SE(3)-aligned to it)'
            if fit is not None else f'Top-down view ({frame})', 'm', 'm')


def _finish(fig: Any, ax: Any, path: Path, title: str, xlabel: str, ylabel: str) -> None:
    """Title, axis labels, grid and legend of a one-axes figure; saved to ``path`` and closed."""
    import matplotlib.pyplot as plt

    ax.set_title(title)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    ax.legend(loc='best', fontsize=8)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def _roots(joints: JointsTrack, layout: JointLayout) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per person index: (stamps, root (pelvis) positions (F, 3), the joints' frame)."""
    people = max((len(j) for j in joints.joints), default=0)
    out = []
    for k in range(people):
        rows = [(s, layout.root_of(j[k]))
                for s, j in zip(joints.stamps_ns, joints.joints) if len(j) > k]
        if rows:
            out.append((np.array([s for s, _ in rows]), np.array([p for _, p in rows])))
    return out


def _resets(run: Replayed) -> list[int]:
    """Stamps (ns) where /diagnostics' reset counter grew (1 s resolution)."""
    stamps, last = [], 0
    for stamp, values in run.diagnostics:
        count = int(values.get('resets', '0'))
        if count > last:
            stamps.append(stamp)
        last = count
    return stamps


def _t0(run: Replayed, truth: Truth | None) -> int:
    tracks: tuple[np.ndarray, ...] = (run.camera.stamps_ns, run.scale.stamps_ns,
                                      run.samples.stamps_ns if run.samples is not None
                                      else np.zeros(0, dtype=np.int64))
    candidates = [a[0] for a in tracks if len(a)]
    candidates += [s for s, _ in run.diagnostics[:1]]
    if truth is not None and truth.camera is not None and len(truth.camera):
        candidates.append(truth.camera.stamps_ns[0])
    return int(min(candidates)) if candidates else 0


def plot_scale(path: Path, run: Replayed, truth: Truth | None) -> None:
    import matplotlib.pyplot as plt

    t0 = _t0(run, truth)
    fig, ax = plt.subplots(figsize=FIGSIZE['scale'], dpi=DPI)
    samples = run.samples
    if samples is not None and len(samples.stamps_ns):
        t = (samples.stamps_ns - t0) / NS
        for code, name in ((0, 'map'), (1, 'ground')):
            mask = (samples.source == code) & samples.accepted
            ax.plot(t[mask], samples.scale[mask], '.', ms=3, alpha=0.5, color=COLOURS[name],
                    label=f'samples: {"map hit" if name == "map" else "ground plane"}')
        gated = ~samples.accepted & np.isfinite(samples.scale)
        if gated.any():
            ax.plot(t[gated], samples.scale[gated], 'x', ms=4, color=COLOURS['gated'],
                    label='samples: gated')
    if run.diagnostics:
        d_t = np.array([(s - t0) / NS for s, _ in run.diagnostics])
        d_scale = np.array([float(v.get('scale', 'nan')) for _, v in run.diagnostics])
        d_spread = np.array([float(v.get('spread', 'nan')) for _, v in run.diagnostics])
        converged = np.array([v.get('converged') == 'true' for _, v in run.diagnostics])
        if converged.any():
            ax.fill_between(d_t, np.where(converged, d_scale - d_spread, np.nan),
                            np.where(converged, d_scale + d_spread, np.nan), color=COLOURS['scale'],
                            alpha=0.2, step='post', label='online estimate ± its uncertainty')
    if len(run.scale):
        ax.plot((run.scale.stamps_ns - t0) / NS, run.scale.values, color=COLOURS['scale'], lw=1.8,
                label='published scale (/hac/scale)')
    if truth is not None and truth.scale is not None and len(truth.scale):
        ends = [truth.scale.stamps_ns[-1]] + ([run.scale.stamps_ns[-1]] if len(run.scale) else [])
        end = max(ends)
        ts = np.append(truth.scale.stamps_ns, end)
        vs = np.append(truth.scale.values, truth.scale.values[-1])
        ax.step((ts - t0) / NS, vs, where='post', color=COLOURS['gt'], lw=1.5, ls='--',
                label='true scale')
    for k, stamp in enumerate(_resets(run)):
        ax.axvline((stamp - t0) / NS, color=COLOURS['reset'], ls=':', lw=1.5,
                   label='reset (SLAM re-initialised)' if k == 0 else None)
    _focus_scale_axis(ax, run, truth)
    _finish(fig, ax, path, 'Scale: per-frame samples, estimate and truth', 'stamp time (s)',
            'scale (m per SLAM unit)')


def _focus_scale_axis(ax: Any, run: Replayed, truth: Truth | None) -> None:
    """Keep the y range on the estimate and the truth (samples' outliers would flatten them)."""
    values = list(run.scale.values)
    if truth is not None and truth.scale is not None:
        values += list(truth.scale.values)
    if run.samples is not None:
        finite = run.samples.scale[np.isfinite(run.samples.scale)]
        if len(finite):
            values += list(np.percentile(finite, [2, 98]))
    values = [v for v in values if np.isfinite(v)]
    if values:
        lo, hi = min(values), max(values)
        pad = 0.1 * (hi - lo) if hi > lo else 0.05 * abs(hi) + 1e-9
        ax.set_ylim(lo - pad, hi + pad)


def plot_fallback(path: Path, run: Replayed, truth: Truth | None) -> None:
    import matplotlib.pyplot as plt

    t0 = _t0(run, truth)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=FIGSIZE['fallback'], dpi=DPI, sharex=True)
    diag = run.diagnostics
    if len(diag) >= 2:
        t = np.array([(s - t0) / NS for s, _ in diag])
        hits = np.array([int(v.get('map_hits', 0)) for _, v in diag])
        ground = np.array([int(v.get('ground_fallbacks', 0)) for _, v in diag])
        d_hits, d_ground = np.diff(hits), np.diff(ground)
        used = d_hits + d_ground
        rate = np.where(used > 0, d_ground / np.maximum(used, 1), np.nan)
        width = np.diff(t)
        top.bar(t[:-1], 100 * np.nan_to_num(rate), width=width, align='edge',
                color=COLOURS['ground'], alpha=0.8, label='ground-plane fallback (% of samples)')
        reasons = sorted({k for _, v in diag for k in v if k.startswith('rejected.')})
        bottom_acc = np.zeros(len(diag) - 1)
        for reason in reasons:
            counts = np.array([int(v.get(reason, 0)) for _, v in diag])
            delta = np.diff(counts)
            if delta.any():
                bottom.bar(t[:-1], delta, width=width, bottom=bottom_acc, align='edge',
                           label=reason.split('.', 1)[1])
                bottom_acc += delta
        if not bottom_acc.any():
            bottom.text(0.5, 0.5, 'no rejected inputs', ha='center', va='center',
                        transform=bottom.transAxes)
    else:
        top.text(0.5, 0.5, 'fewer than two /diagnostics messages', ha='center',
                 transform=top.transAxes)
    for ax in (top, bottom):
        for k, stamp in enumerate(_resets(run)):
            ax.axvline((stamp - t0) / NS, color=COLOURS['reset'], ls=':', lw=1.5,
                       label='reset' if k == 0 else None)
        ax.grid(True, alpha=0.3)
    top.set_ylim(0, 100)
    top.set_ylabel('fallback (%)')
    top.set_title('Ground-plane fallback and rejected inputs per second')
    bottom.set_ylabel('rejected / s')
    bottom.set_xlabel('stamp time (s)')
    for ax in (top, bottom):
        handles, _labels = ax.get_legend_handles_labels()
        if handles:
            ax.legend(loc='upper right', fontsize=8)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def plot_heights(path: Path, run: Replayed, truth: Truth | None) -> None:
    """Heights in the metric frame over time: with ``metric_frame_alignment: gravity`` z is up and
    the floor is z = 0, so the camera's z is its height above the floor and people's lowest joints
    stay just above 0. No alignment to the truth: the frame is shown as published."""
    import matplotlib.pyplot as plt

    t0 = _t0(run, truth)
    fig, ax = plt.subplots(figsize=FIGSIZE['heights'], dpi=DPI)
    ax.axhline(0.0, color='black', lw=0.8, label='floor (z = 0)')
    if len(run.camera):
        ax.plot((run.camera.stamps_ns - t0) / NS, run.camera.positions[:, 2], color=COLOURS['hac'],
                lw=1.5, label='camera height, /hac/pose z')
    if truth is not None and truth.camera is not None and len(truth.camera):
        ax.plot((truth.camera.stamps_ns - t0) / NS, truth.camera.positions[:, 2],
                color=COLOURS['gt'], lw=1.0, ls='--', label='camera height, ground truth z')
    lowest = [(s, float(np.nanmin(j[..., 2]))) for s, j in zip(run.joints.stamps_ns,
                                                               run.joints.joints)
              if len(j) and np.isfinite(j[..., 2]).any()]
    if lowest:
        stamps, z = np.array(lowest).T
        ax.plot((stamps - t0) / NS, z, '.', ms=2, color='tab:green',
                label='people: lowest joint z (/hac/human_joints)')
    alignment = next((v.get('alignment') for _, v in reversed(run.diagnostics)
                      if v.get('alignment')), None)
    title = ('Metric frame heights' + (f' (alignment {alignment})' if alignment else '')
             + ': z up, floor at 0 when gravity-aligned')
    _finish(fig, ax, path, title,
            'stamp time (s)', 'z (m)')


# ============================================================================ entry points
def read_slam(path: str | Path) -> CameraTrack | None:
    """The raw SLAM camera track of a recording (/slam/pose, PoseStamped or Odometry), if any."""
    with Recording(path) as rec:
        if rec.topics.get(SLAM_POSE_TOPIC) in POSE_MSGTYPES.values() and rec.has(SLAM_POSE_TOPIC):
            return read_camera(rec, SLAM_POSE_TOPIC)
    return None


def make_plots(output_path: str | Path, directory: str | Path,
               gt_path: str | Path | None = None) -> dict[str, Path]:
    """Write the figures (FIGSIZE) into ``directory`` (created); returns name -> path."""
    import matplotlib

    matplotlib.use('Agg')
    directory = Path(directory)
    run = read_output(output_path)
    truth = read_truth(gt_path) if gt_path is not None else None
    slam = read_slam(gt_path) if gt_path is not None else read_slam(output_path)
    if not len(run.camera) and not len(run.scale) and not run.diagnostics:
        raise HacError(f'{output_path} has nothing to plot (no odometry, scale or diagnostics)')
    created = not directory.exists()
    directory.mkdir(parents=True, exist_ok=True)
    paths = {name: directory / f'{name}.png' for name in FIGSIZE}
    # drawn beside, moved in once all are done: an interrupted plot leaves no half set
    staging: Path | None = None
    try:
        with signals_held():  # made and known, or neither
            staging = Path(tempfile.mkdtemp(prefix='.hac_plot.', suffix='.partial',
                                            dir=directory))
        staged = {name: staging / path.name for name, path in paths.items()}
        plot_trajectories(staged['trajectories'], run, truth, slam)
        plot_scale(staged['scale'], run, truth)
        plot_fallback(staged['fallback'], run, truth)
        plot_heights(staged['heights'], run, truth)
        for name, path in staged.items():
            os.replace(path, paths[name])
    finally:
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)
        if created and not any(directory.iterdir()):
            directory.rmdir()
    return paths
