#!/usr/bin/env python3
"""Accuracy benchmark: the paper's tables reproduced on simulated scenarios, and a real-data composite.

    python bench/accuracy.py [--seeds 3] [--duration 40] [--quick]

Runs the core (hac_ros.core.Calibrator) directly on the simulator's in-memory scenarios (the same
inputs `hac simulate` writes to a recording), prints the tables, writes
bench/results/accuracy.json and the `accuracy` section of docs/benchmarks.md.

1. Reference joint ablation (paper Tab. 1) on walk, occluded, crowd, stairs.
2. Ground-plane strategies on ego (paper Tab. 2).
3. Online vs offline per scenario.
4. Drift and reset: rolling window vs one global median.
5. Real-data composite: the real ORB-SLAM monocular keyframes of TUM fr2_desk as SLAM input.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import machine, machine_line, table, write_json, write_section  # noqa: E402

from hac_ros.core import metrics  # noqa: E402
from hac_ros.core.calibrator import Calibrator  # noqa: E402
from hac_ros.core.estimator import sequence_scale  # noqa: E402
from hac_ros.core.outputs import ResetOut, SampleOut, ScaleOut  # noqa: E402
from hac_ros.core.params import HacParams  # noqa: E402
from hac_ros.simulate import make_scenario  # noqa: E402
from hac_ros.simulate.feed import feed_scenario  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / 'shared' / 'data'
ABLATION_SCENARIOS = ('walk', 'crowd', 'stairs')
OCCLUDED = ('occluded',)  # reported apart: a known failure that would swamp the means
ALL_SCENARIOS = ('walk', 'ego', 'stairs', 'handstand', 'skate', 'occluded', 'crowd', 'drift',
                 'reset', 'static')
CONTACT_ROWS = ('head', 'pelvis', 'feet', 'lowest', 'max_ratio', 'lowest_gravity')
GROUND_ROWS = ('none', 'largest_plane', 'slam_y', 'hmr')
ROOT = 0  # pelvis: the root joint for RTE


@dataclass
class Run:
    """What one calibrator run over one scenario produced."""

    samples_ns: np.ndarray
    samples: np.ndarray
    online_ns: np.ndarray
    online: np.ndarray
    resets_ns: list[int] = field(default_factory=list)
    fallback_rate: float = 0.0


def calibrate(scenario, params: HacParams, known_plane: bool = False) -> Run:
    cal = Calibrator(params)
    if known_plane:
        n, b = scenario.true_ground_plane_slam(0)
        cal.set_ground_plane(n, b)
    outs = feed_scenario(cal, scenario)
    acc = [o for o in outs if isinstance(o, SampleOut) and o.accepted]
    online = [o for o in outs if isinstance(o, ScaleOut)]
    status = cal.status()
    return Run(np.array([o.stamp_ns for o in acc], dtype=np.int64), np.array([o.scale for o in acc]),
               np.array([o.stamp_ns for o in online], dtype=np.int64),
               np.array([o.scale for o in online]),
               [o.stamp_ns for o in outs if isinstance(o, ResetOut)], status.fallback_rate)


def human_and_camera_metrics(scenario, scale: float) -> dict[str, float]:
    """Metrics of the metric outputs made with one sequence scale (the paper is offline)."""
    frames = {int(s): i for i, s in enumerate(scenario.pose_stamps_ns)}
    idx = np.array([frames[int(s)] for s in scenario.joints_stamps_ns])
    pred, gt = [], []
    for k, i in enumerate(idx):
        J = scenario.joints_cam[k][0]  # first person: a track
        pred.append(J @ scenario.slam_R_wc[i].T + scale * scenario.slam_c[i])
        gt.append(scenario.gt_joints_world[k][0])
    pred, gt = np.array(pred), np.array(gt)
    cams = scale * scenario.slam_c
    return {
        'W-MPJPE': metrics.w_mpjpe(pred, gt), 'WA-MPJPE': metrics.wa_mpjpe(pred, gt),
        'RTE': metrics.rte(pred[:, ROOT], gt[:, ROOT]), 'PA-MPJPE': metrics.pa_mpjpe(pred, gt),
        'ATE': metrics.ate(cams, scenario.gt_c), 'ATE-S': metrics.ate_s(cams, scenario.gt_c),
    }


def mean_rows(rows: list[dict[str, float]]) -> dict[str, float]:
    keys = rows[0].keys()
    return {k: float(np.mean([r[k] for r in rows])) for k in keys}


# ---------------------------------------------------------------------- tables
def table_reference_joint(seeds, duration, scenarios=ABLATION_SCENARIOS) -> dict:
    results: dict[str, list] = {}
    for name in scenarios:
        for seed in seeds:
            sc = make_scenario(name, seed=seed, duration=duration)
            true = float(np.median(sc.true_scale))
            rows = {'no calibration': 1.0, 'true scale': true}
            for mode in CONTACT_ROWS:
                rows[mode] = sequence_scale(calibrate(sc, HacParams(contact_mode=mode)).samples)
            for row, s in rows.items():
                if not math.isfinite(s):
                    continue
                m = human_and_camera_metrics(sc, s)
                m['scale error %'] = abs(s / true - 1) * 100
                results.setdefault(row, []).append(m)
    return {row: mean_rows(v) for row, v in results.items()}


def table_ground(seeds, duration) -> dict:
    results: dict[str, list] = {}
    for seed in seeds:
        sc = make_scenario('ego', seed=seed, duration=duration)
        true = float(np.median(sc.true_scale))
        variants = {g: dict(params=HacParams(ground_mode=g)) for g in GROUND_ROWS}
        variants['true plane'] = dict(params=HacParams(ground_mode='hmr'), known_plane=True)
        for row, kw in variants.items():
            run = calibrate(sc, kw['params'], kw.get('known_plane', False))
            s = sequence_scale(run.samples)
            if not math.isfinite(s):
                results.setdefault(row, []).append(None)
                continue
            m = human_and_camera_metrics(sc, s)
            m['scale error %'] = abs(s / true - 1) * 100
            m['fallback %'] = 100 * run.fallback_rate
            results.setdefault(row, []).append(m)
    return {row: mean_rows([r for r in v if r]) if any(v) else None for row, v in results.items()}


def true_at(sc, stamps_ns: np.ndarray) -> np.ndarray:
    pos = np.searchsorted(sc.pose_stamps_ns, stamps_ns)
    return sc.true_scale[np.clip(pos, 0, len(sc.true_scale) - 1)]


def table_online_offline(seeds, duration) -> dict:
    out = {}
    for name in ALL_SCENARIOS:
        online_err, offline_err, conv_s = [], [], []
        for seed in seeds:
            sc = make_scenario(name, seed=seed, duration=duration)
            run = calibrate(sc, HacParams())
            if run.online.size == 0:
                continue
            truth = true_at(sc, run.online_ns)
            online_err.append(np.mean(np.abs(run.online / truth - 1)) * 100)
            if name in ('drift', 'reset'):  # one median cannot serve; table 4 covers them
                from hac_ros.core.offline import offline_scale
                p = HacParams()
                est = offline_scale(run.samples_ns, run.samples, run.resets_ns, p.window_s,
                                    p.min_samples).at(run.online_ns)
            else:
                est = np.full(run.online.size, sequence_scale(run.samples))
            offline_err.append(np.nanmean(np.abs(est / truth - 1)) * 100)
            conv_s.append((run.online_ns[0] - sc.pose_stamps_ns[0]) / 1e9)
        if online_err:
            out[name] = {'online scale error %': float(np.mean(online_err)),
                         'offline scale error %': float(np.mean(offline_err)),
                         'converged after s': float(np.mean(conv_s))}
    return out


NONE_ROW_NOTE = ("`none` uses map hits only: in the simulated `ego` the head pitches down often enough to see the partner's feet in some frames, and those few hits are accurate, so `none` scores well here, unlike the paper's EgoBody (where the feet are rarely seen); `fallback %` shows how much each row relied on the plane.")
DRIFT_WINDOWS = (30.0, 5.0)  # SPEC's default window and a short one that can follow a drift


def table_drift_reset(seeds, duration) -> dict:
    out = {}
    for name, window in [('drift', w) for w in DRIFT_WINDOWS] + [('reset', DRIFT_WINDOWS[0])]:
        rows = []
        for seed in seeds:
            sc = make_scenario(name, seed=seed, duration=max(duration, 60.0) if name == 'drift' else duration)
            run = calibrate(sc, HacParams(window_s=window))
            truth = true_at(sc, run.online_ns)
            rolling = np.abs(run.online / truth - 1) * 100
            glob = np.abs(sequence_scale(run.samples) / truth - 1) * 100
            row = {'rolling mean %': float(rolling.mean()), 'rolling final %': float(rolling[-1]),
                   'global median mean %': float(glob.mean()),
                   'global median final %': float(glob[-1])}
            if name == 'reset':
                changes = np.flatnonzero(np.diff(sc.true_scale) != 0)
                if changes.size and run.resets_ns:
                    t_true = sc.pose_stamps_ns[changes[0] + 1]
                    after = run.online_ns[run.online_ns > run.resets_ns[0]]
                    row['reset detected after s'] = (run.resets_ns[0] - t_true) / 1e9
                    row['reconverged after s'] = ((after[0] - t_true) / 1e9 if after.size else math.nan)
                row['resets detected'] = len(run.resets_ns)
            rows.append(row)
        out[f'{name}, window_s {window:g}'] = mean_rows(rows)
    return out


def table_real_composite() -> dict | None:
    """TUM fr2_desk: real monocular ORB-SLAM keyframes (input) and real ground truth; a CMU walker."""
    if not SHARED.is_dir():
        return None
    from composite import real_composite
    return real_composite(SHARED)


# ---------------------------------------------------------------------- report
def render(results: dict) -> str:
    parts = [f"Command: `python bench/accuracy.py --seeds {results['seeds']} --duration "
             f"{results['duration']}`. {machine_line(results['machine'])} "
             f"Wall time {results['wall_s']:.0f} s.", '']
    cols = ['W-MPJPE', 'WA-MPJPE', 'RTE', 'PA-MPJPE', 'ATE', 'ATE-S', 'scale error %']
    parts += ['### 1. Reference joint ablation (paper Tab. 1)', '',
              f"Scenarios {', '.join(ABLATION_SCENARIOS)} × {results['seeds']} seeds; one sequence "
              'median per recording (the paper is offline). mm, mm, %, mm, m, m, %.', '',
              table(['row', *cols], [[row, *[m[c] for c in cols]]
                                     for row, m in results['reference_joint'].items()]), '']
    parts += ['#### 1b. The same on `occluded` (tables between the camera and the feet)', '',
              'A known failure (docs/method.md): the table tops are hit before any scale exists and '
              'the estimate locks on them.', '',
              table(['row', *cols], [[row, *[m[c] for c in cols]]
                                     for row, m in results['reference_joint_occluded'].items()]), '']
    gcols = cols + ['fallback %']
    parts += ['### 2. Ground-plane strategies on `ego` (paper Tab. 2)', '',
              NONE_ROW_NOTE, '',
              table(['row', *gcols], [[row, *([m[c] for c in gcols] if m else ['no estimate'] * len(gcols))]
                                      for row, m in results['ground'].items()]), '']
    ocols = ['online scale error %', 'offline scale error %', 'converged after s']
    parts += ['### 3. Online (causal rolling median at every frame) vs offline (whole recording)', '',
              table(['scenario', *ocols], [[k, *[v[c] for c in ocols]]
                                           for k, v in results['online_offline'].items()]), '']
    parts += ['### 4. Drift and reset: rolling window vs one global median', '']
    for name, row in results['drift_reset'].items():
        parts.append(f'- `{name}`: ' + ', '.join(f'{k} {v:.3g}' for k, v in row.items()))
    parts.append('')
    real = results.get('real_composite')
    parts += ['### 5. Real-data composite (TUM fr2_desk ORB-SLAM monocular keyframes)', '']
    if real is None:
        parts.append('Skipped: ../shared/data is absent.')
    else:
        parts.append(real['description'])
        parts.append('')
        parts.append(table(['quantity', 'value'], [[k, v] for k, v in real['figures'].items()]))
    return '\n'.join(parts) + '\n'


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seeds', type=int, default=3)
    parser.add_argument('--duration', type=float, default=40.0)
    parser.add_argument('--quick', action='store_true', help='1 seed, 15 s (a smoke run)')
    args = parser.parse_args()
    if args.quick:
        args.seeds, args.duration = 1, 15.0
    seeds = list(range(args.seeds))
    t0 = time.perf_counter()
    results = {'seeds': args.seeds, 'duration': args.duration, 'machine': machine()}
    for key, fn in [('reference_joint', table_reference_joint),
                    ('reference_joint_occluded',
                     lambda seeds, d: table_reference_joint(seeds, d, OCCLUDED)),
                    ('ground', table_ground),
                    ('online_offline', table_online_offline), ('drift_reset', table_drift_reset)]:
        t = time.perf_counter()
        results[key] = fn(seeds, args.duration)
        print(f'[{key}: {time.perf_counter() - t:.0f} s]', file=sys.stderr)
    results['real_composite'] = table_real_composite()
    results['wall_s'] = time.perf_counter() - t0
    text = render(results)
    print(text)
    write_json('accuracy', results)
    write_section('accuracy', '## Accuracy (`bench/accuracy.py`)\n\n' + text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
