#!/usr/bin/env python3
"""Accuracy over many seeds: our configurations beside the literal authors' method, per scenario,
at 30 Hz and at keyframe rate.

    python bench/accuracy.py [--seeds 20] [--scenarios walk crowd ...] [--configs ...]
                             [--rates 30hz kf] [--workers 2] [--quick] [--resume runs.jsonl]
    python bench/accuracy.py --report runs.jsonl   # the docs from the scenes of earlier runs

Every scene (a simulated scenario of ``hac_ros.simulate`` at its own duration, or a real-data
composite of bench/composite.py) is generated once per seed and run through every configuration
and through the literal authors' method (bench/_accuracy_runs.py says exactly what each figure
is), at two rates: ``30hz`` (a pose and a joints frame per video frame) and ``kf`` (keyframe rate:
the poses and joints frames of the keyframes a SLAM chooses by camera motion, bench/_keyframes.py;
the composites' real ORB-SLAM keyframes, their 30 Hz version the same scene seen at every
frame). Per scenario, rate and method, over the seeds: the median and p90 of the absolute scale
error (%), the median signed error (the bias, %) and the median W-MPJPE (mm); online (the default
only): the median error over the run, the error at the end, the time to converge within 5 %, the
statuses OK while > 5 % off, the ``±``'s coverage of the truth. ``drift_planted`` is ``drift``
with its walkers' feet planted (the drift target's scene).

Two HMR conditions: ``clean`` (no HMR depth bias; per-frame depth noise remains) and ``biased``
(the simulator's default: a mean bias drawn up to +-4 % per recording, wandering; the composite
5 %). Prints the tables and the targets (bench/_accuracy_targets.py), writes
bench/results/accuracy.json, accuracy_runs.jsonl and the ``accuracy`` section of
docs/accuracy.md.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _accuracy_targets import pairs, targets_30, targets_37, targets_43
from _report import (
    ACCURACY_DOC,
    RESULTS,
    command_line,
    machine,
    machine_line,
    table,
    write_json,
    write_section,
)
from paired import native

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / 'shared' / 'data'
SIMULATED = ('walk', 'crowd', 'stairs', 'ego', 'handstand', 'skate', 'static', 'drift', 'reset',
             'occluded', 'office')
# simulated scenes edited as a hostile user would (bench/_scene_edits.py): scene -> (scenario, its
# duration s, the edits in order); the fast change shrinks the SLAM unit 1.3x at 40-48 s
EDITED = {
    'rescale': ('walk', 90.0, (('rescaled', 'fast'),)),  # 30 % in 8 s, the walker in view
    'rescale_unseen': ('walk', 90.0, (('rescaled', 'fast'), ('blank_joints', 34.0, 54.0))),
    'rescale_gap': ('walk', 90.0, (('rescaled', 'fast'), ('drop_joints', 20.0, 80.0))),
    'breathing': ('walk', 120.0, (('rescaled', 'breathing'),)),  # +-10 %, 20 s and 60 s
    'bursts': ('walk', 60.0, (('bursts',),)),  # a frame resent 100 times within 0.1 s, every 15 s
}
# the real-data composites, one per CMU motion (bench/composite.py): on fr2_desk, and on
# freiburg1_xyz as a steep view (camera 1.6 m high pitched ~48 deg down, the person 1-2 m away)
COMPOSITES = {f'{view}_{motion + 1:02d}': (sequence, motion) for motion in range(3)
              for view, sequence in (('composite', 'fr2_desk'), ('steep', 'freiburg1_xyz'))}
# a drifting composite: fr2_desk's real keyframes, the SLAM's scale growing 40 % over 90 s, the
# motion drawn from the seed (bench/composite.py)
DRIFTING = {'composite_drift': ('fr2_desk', 0.40)}
PLANTED = ('drift_planted',)  # drift with the walkers' feet planted: clean only
SCENARIOS = SIMULATED + PLANTED + tuple(EDITED) + tuple(COMPOSITES) + tuple(DRIFTING)
RATES = ('30hz', 'kf')
COMPOSITE_BIAS = 0.05
# the results the paired targets compare with: the bench at 3867b2c (issue 43)
BASELINE = RESULTS / 'accuracy_runs_3867b2c.jsonl'
# name -> parameter overrides; 'default' is HacParams' own defaults
CONFIGS: dict[str, dict[str, Any]] = {
    'default': {},
    'lowest_gravity cone_median (previous default)': dict(contact_mode='lowest_gravity',
                                                          reference_mode='cone_median',
                                                          sole_correction=False),
    'lowest_gravity cone_median sole': dict(contact_mode='lowest_gravity',
                                            reference_mode='cone_median', sole_correction=True),
    'lowest_gravity cone_plane sole': dict(contact_mode='lowest_gravity',
                                           reference_mode='cone_plane', sole_correction=True),
    'lowest_gravity nearest_to_ray sole': dict(contact_mode='lowest_gravity',
                                               reference_mode='nearest_to_ray', sole_correction=True),
    'lowest cone_plane sole': dict(contact_mode='lowest', reference_mode='cone_plane',
                                   sole_correction=True),
    'max_ratio cone_median': dict(contact_mode='max_ratio', reference_mode='cone_median',
                                  sole_correction=False),
    'feet cone_plane sole': dict(contact_mode='feet', reference_mode='cone_plane',
                                 sole_correction=True),
    'pelvis cone_plane': dict(contact_mode='pelvis', reference_mode='cone_plane'),
    'head cone_plane': dict(contact_mode='head', reference_mode='cone_plane'),
}
ONLINE_CONFIGS = ('default', 'lowest_gravity cone_median (previous default)')


Task = tuple[str, int, str, list[str], tuple[str, ...], bool]


def make_scenes(name: str, seed: int, condition: str, rates: tuple[str, ...],
                planted: bool = False) -> dict[str, Any]:
    """One scene (scenario, seed, condition) at each rate: rate -> bench/_accuracy_runs.Scene."""
    from _accuracy_runs import scene_from_composite, scene_from_scenario
    from _keyframes import at_keyframes

    from hac_ros.simulate import make_scenario

    scenes = {}
    if name in COMPOSITES or name in DRIFTING:
        from composite import build

        bias = 0.0 if condition == 'clean' else COMPOSITE_BIAS
        sequence, motion = COMPOSITES[name] if name in COMPOSITES else (DRIFTING[name][0], None)
        drift = DRIFTING[name][1] if name in DRIFTING else 0.0
        for rate in rates:
            data = build(SHARED, seed, bias, sequence, motion, rate=30.0 if rate == '30hz' else None,
                         drift=drift)
            scenes[rate] = scene_from_composite(data, seed, bias)
        return scenes
    import _scene_edits

    base, duration, edits = EDITED.get(name, (name.removesuffix('_planted'), None, ()))
    sc = make_scenario(base, seed=seed, duration=duration,
                       hmr_bias=0.0 if condition == 'clean' else None,
                       foot_roll=not (planted or name in PLANTED))
    scene = scene_from_scenario(sc)
    for edit in edits[:1] if edits and edits[0][0] == 'rescaled' else ():
        scene = getattr(_scene_edits, edit[0])(scene, *edit[1:])  # the SLAM's, before keyframes
    scenes = {rate: scene if rate == '30hz' else at_keyframes(scene) for rate in rates}
    for edit in edits[1:] if edits and edits[0][0] == 'rescaled' else edits:
        scenes = {rate: getattr(_scene_edits, edit[0])(s, *edit[1:]) for rate, s in scenes.items()}
    return scenes


def run_task(task: Task) -> list[dict[str, Any]]:
    """One scene (scenario, seed, condition) at each rate through every configuration and the
    literal method: one result per rate."""
    from _accuracy_runs import run_literal, run_ours

    from hac_ros.core.rules.params import HacParams

    name, seed, condition, configs, rates, planted = task
    scenes = make_scenes(name, seed, condition, rates, planted)
    out = []
    for rate, scene in scenes.items():
        literal, literal_world = run_literal(scene)
        rows = {'literal': literal}
        for config in configs:
            params = HacParams().replace(**CONFIGS[config])
            rows[config] = run_ours(scene, params, literal_world, online=config in ONLINE_CONFIGS)
        out.append({'scenario': name, 'seed': seed, 'condition': condition, 'rate': rate,
                    'rows': rows})
    return out


def scene_of(result: dict[str, Any]) -> str:
    """A result's scene: its scenario at its rate (earlier results without one: the native)."""
    return f"{result['scenario']}@{result.get('rate', native(result['scenario']))}"


def summarise(results: list[dict[str, Any]]) -> dict[str, Any]:
    """scene (scenario@rate) -> condition -> method -> statistics over the seeds."""
    out: dict[str, Any] = {}
    for r in results:
        for method, row in r['rows'].items():
            cell = out.setdefault(scene_of(r), {}).setdefault(r['condition'], {}).setdefault(
                method, {})
            for key, value in row.items():
                cell.setdefault(key, []).append(value)
    for scenario in out.values():
        for condition in scenario.values():
            for method, lists in condition.items():
                condition[method] = _stats(lists)
    return out


def _stats(lists: dict[str, list[float]]) -> dict[str, float]:
    def finite(key: str) -> np.ndarray:
        values = np.asarray(lists.get(key, []), dtype=float)
        return values[np.isfinite(values)]

    err, bias, w, wf = (finite('scale_err'), finite('scale_bias'), finite('w_mpjpe'),
                        finite('w_mpjpe_filtered'))
    stats = {'seeds': len(lists.get('scale_err', [])), 'failed': int(len(lists.get('scale_err', []))
                                                                     - err.size)}
    stats['err_median'] = float(np.median(err)) if err.size else math.nan
    stats['err_p90'] = float(np.percentile(err, 90)) if err.size else math.nan
    stats['bias_median'] = float(np.median(bias)) if bias.size else math.nan
    stats['w_mpjpe_median'] = float(np.median(w)) if w.size else math.nan
    stats['w_mpjpe_filtered_median'] = float(np.median(wf)) if wf.size else math.nan
    for key in ('statuses', 'ok_wrong', 'converged_wrong', 'ok_statuses', 'sigma_statuses',
                'cover1', 'cover2', 'cover1_own', 'cover2_own', 'relocking', 'after_ok',
                'after_ok_ok', 'published', 'runs_enough', 'published_enough', 'flow_poses',
                'flow_odometry', 'flow_frames', 'flow_joints'):  # pooled over the seeds
        stats[key] = int(np.sum(finite(key)))
    stats['runs'] = len(lists.get('statuses', []))
    worst = finite('scale_err_max')
    if worst.size:
        stats['scale_err_max'] = float(np.max(worst))
    for key in ('w_mpjpe_literal', 'w_mpjpe_vs_literal', 'online_err', 'online_final_err',
                'converged_s', 'fallback_pct', 'hmr_excess', 'camera_height_err', 'floor_err',
                'w_mpjpe_online', 'w_mpjpe_offline', 'ate_s_online', 'ate_s_offline',
                'sample_sigma', 'window_samples', 'first_ok_s', 'first_ok_samples',
                'samples'):
        values = finite(key)
        if values.size:
            stats[f'{key}_median'] = float(np.median(values))
    conv = finite('converged_s')
    if conv.size:
        stats['converged_s_p90'] = float(np.percentile(conv, 90))
    return stats


def render(summary: dict[str, Any], meta: dict[str, Any], paired: dict[Any, Any]) -> str:
    """The docs section: one row per scene (scenario at a rate), the default configuration beside
    the literal method (clean) and under a biased HMR; the estimator's figures; then the targets
    that do not hold (every figure: bench/results/accuracy.json; how each is taken:
    bench/_accuracy_runs.py; the targets: bench/_accuracy_targets.py)."""
    if 'report' in meta:
        head = (f"Command: `{meta['command']}`, its {meta['scenes']} scenes computed by "
                f"{meta['computed_by']}.")
    else:
        resumed = meta.get('resumed_scenes', 0)
        head = (f"Command: `{meta['command']}`. Wall time {meta['wall_s'] / 60:.0f} min" +
                (f" ({resumed} of {meta['scenes']} scenes from earlier invocations, --resume)"
                 if resumed else '') + '.')
    parts = [head + ' ' + machine_line(meta['machine']), '',
             'Default configuration, medians over seeds (clean/biased), each scenario at 30 Hz '
             '(`@30hz`) and at keyframe rate (`@kf`): offline |scale error| % (p90) against each '
             'frame\'s truth, its sign (bias); `literal`: the authors\' method; `online`: what '
             'the node publishes; W-MPJPE online/offline after convergence; `OK>5%`: % of '
             'statuses OK and converged while > 5 % off; the gravity frame\'s camera height and '
             'floor errors; `over HMR`: |err| minus the HMR\'s |bias| (+-4 %, composites 5 %). '
             '`composite_0N`/`steep_0N`: CMU 131_0N over fr2_desk/freiburg1_xyz. Definitions: '
             'bench/_accuracy_runs.py.', '']
    rows, estimator_rows = [], []
    for scene, by_condition in summary.items():
        ours, literal = by_condition.get('clean', {}).get('default'), by_condition.get(
            'clean', {}).get('literal')
        biased = by_condition.get('biased', {}).get('default')
        row: list[Any] = [scene, f"{ours['seeds'] if ours else 0}/"
                          f"{biased['seeds'] if biased else 0}"]
        if ours and literal:
            share = (100.0 * ours['ok_wrong'] / ours['statuses'] if ours.get('statuses')
                     else math.nan)
            row += [f"{ours['err_median']:.2f} ({ours['err_p90']:.2f})",
                    f"{ours['bias_median']:+.2f}",
                    f"{literal['err_median']:.2f}",
                    f"{ours.get('online_err_median', math.nan):.2f}",
                    f"{ours.get('w_mpjpe_online_median', math.nan):.0f}/"
                    f"{ours.get('w_mpjpe_offline_median', math.nan):.0f}", f'{share:.2g}',
                    f"{ours.get('camera_height_err_median', math.nan):.1f}, "
                    f"{100.0 * ours.get('floor_err_median', math.nan):.1f}"]
            covered = max(ours.get('sigma_statuses', 0), 1)

            def share(part: str, whole: str, cell: dict[str, Any] = ours) -> str:
                return (f"{100.0 * cell.get(part, 0) / cell[whole]:.0f}" if cell.get(whole)
                        else '')
            first = (f"{ours.get('first_ok_samples_median', math.nan):.0f}" if scene.endswith('@kf')
                     else f"{ours.get('first_ok_s_median', math.nan):.1f} s")
            estimator_rows.append([
                scene, f"{ours.get('window_samples_median', math.nan):.0f}",
                f"{ours.get('sample_sigma_median', math.nan):.2f}", first,
                share('after_ok_ok', 'after_ok'),
                f"{ours.get('published', 0)}/{ours.get('runs', 0)}",
                f"{share('flow_odometry', 'flow_poses')}/{share('flow_joints', 'flow_frames')}",
                f"{100.0 * ours.get('relocking', 0) / max(ours.get('statuses', 0), 1):.2g}",
                f"{100.0 * ours.get('cover1_own', 0) / covered:.0f}/"
                f"{100.0 * ours.get('cover2_own', 0) / covered:.0f}",
                f"{100.0 * ours.get('cover1', 0) / covered:.0f}/"
                f"{100.0 * ours.get('cover2', 0) / covered:.0f}",
                (f"{share('cover1', 'sigma_statuses', biased)}/"
                 f"{share('cover2', 'sigma_statuses', biased)}" if biased else '')])
        else:
            row += [''] * 8
        if biased:
            row += [f"{biased['err_median']:.2f} ({biased['err_p90']:.2f})",
                    f"{biased.get('hmr_excess_median', math.nan):+.2f}",
                    f"{biased.get('online_err_median', math.nan):.2f}"]
        else:
            row += [''] * 3
        rows.append(row)
    parts += [table(['scene', 'seeds', 'clean % (p90)', 'bias', 'literal', 'online',
                     'W-MPJPE on/off mm', 'OK>5%', 'camera %, floor cm', 'biased % (p90)',
                     'over HMR', 'online'], rows), '',
              'The estimator online (clean): the samples in its window (median), a sample\'s '
              'own spread (robust, %), the first OK (median: stamp seconds from the first '
              'accepted sample at 30 Hz, accepted samples at keyframe rate), the share of the '
              'statuses after it that are OK, the runs that published a scale, the share of '
              'SLAM poses with odometry / of joints frames with people published from each '
              'segment\'s first publication on, the share of statuses `relocking`, and the '
              'coverage of the truth of the moment at 1 / 2 sigma, on the statuses published: '
              'σ_stat (the estimate\'s own) once the run\'s own offline bias is taken out, the '
              'published `±` (σ_stat ⊕ σ_sys) against the truth itself, clean and biased '
              '(docs/method.md, "The two parts of the ±").',
              '', table(['scene', 'window n', 'sample sigma %', 'first OK', 'OK after %',
                         'published', 'flow odo/joints %', 'relocking %',
                         'σ_stat own 1/2 %', '± clean 1/2 %', '± biased 1/2 %'],
                        estimator_rows), '']
    for title, checks in (('issue 43', targets_43(summary, paired)),
                          ('issue 37, those that still apply', targets_37(summary, paired)),
                          ('issue 30, those that still apply', targets_30(summary))):
        if not checks:
            continue
        failing: dict[str, list[str]] = {}
        for name, target, measured, ok in checks:
            if not ok:
                failing.setdefault(target, []).append(f'`{name}` ({measured})')
        parts += [f'### Targets ({title}; default configuration, clean unless said)', '',
                  f"{sum(ok for *_, ok in checks)} of {len(checks)} hold" +
                  ('; not met:' if failing else '.'), '']
        parts += [f'- {target}: ' + ', '.join(where) for target, where in failing.items()]
        parts += ['']
    return '\n'.join(parts).rstrip()


def _rounded(value: Any) -> Any:
    """Floats to 4 significant digits, recursively (the per-scene file stays small)."""
    if isinstance(value, float):
        return float(f'{value:.4g}') if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_rounded(v) for v in value]
    return value


def _load_done(path: Path | None, tasks: list[Task]) -> list[dict[str, Any]]:
    """Results of an interrupted run (one JSON per line) that belong to this run's tasks: a
    (scenario, seed, condition) at each of its rates."""
    if path is None or not path.exists():
        return []
    wanted = {(*t[:3], rate): set(t[3]) for t in tasks for rate in t[4]}
    out = []
    for line in path.read_text().splitlines():
        try:
            r = json.loads(line)
        except ValueError:
            continue  # a line cut short by the interruption
        key = (r['scenario'], r['seed'], r['condition'], r.get('rate', native(r['scenario'])))
        if key in wanted and wanted[key] <= set(r['rows']):
            out.append(r)
    return out


def _pairs(results: list[dict[str, Any]]) -> dict[Any, Any]:
    """The paired comparison with the baseline, when its results are there."""
    return pairs(results, BASELINE.read_text()) if BASELINE.exists() else {}


def report(path: Path, computed_by: str, argv: list[str] | None, write: bool) -> int:
    """``--report``: the summary of every scene in ``path`` (a --resume file), printed and
    written like a run's."""
    results = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    order = {name: k for k, name in enumerate(SCENARIOS)}
    results.sort(key=lambda r: (r['condition'] != 'clean', order.get(r['scenario'], len(order)),
                                r['seed']))
    meta = {'command': command_line(__file__, ['--report', str(path)]), 'machine': machine(),
            'report': str(path),
            'computed_by': computed_by or '?', 'scenes': len(results),
            'seeds': max((r['seed'] for r in results), default=-1) + 1}
    summary = summarise(results)
    text = render(summary, meta, _pairs(results))
    print(text)
    if write:
        _write(meta, summary, results, text)
    return 0


def _write(meta: dict[str, Any], summary: dict[str, Any], results: list[dict[str, Any]],
           text: str) -> None:
    """bench/results/accuracy.json, accuracy_runs.jsonl and the docs section."""
    write_json('accuracy', {'meta': meta, 'summary': summary})
    # every scene's figures, one line each (the evidence behind the medians)
    with (RESULTS / 'accuracy_runs.jsonl').open('w') as f:
        for r in results:
            f.write(json.dumps(_rounded(r), separators=(',', ':')) + '\n')
    write_section('accuracy', '## Accuracy (`bench/accuracy.py`)\n\n' + text, ACCURACY_DOC)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seeds', type=int, default=20)
    parser.add_argument('--scenarios', nargs='+', default=list(SCENARIOS), choices=SCENARIOS)
    parser.add_argument('--configs', nargs='+', default=list(CONFIGS), choices=list(CONFIGS))
    parser.add_argument('--conditions', nargs='+', default=['clean', 'biased'],
                        choices=['clean', 'biased'])
    parser.add_argument('--rates', nargs='+', default=list(RATES), choices=RATES,
                        help='30hz: every frame; kf: the keyframes (bench/_keyframes.py)')
    parser.add_argument('--workers', type=int, default=len(os.sched_getaffinity(0)))
    parser.add_argument('--quick', action='store_true', help='3 seeds (a smoke run)')
    parser.add_argument('--planted', action='store_true',
                        help='simulated walkers keep their stance feet planted (no foot roll: the '
                             'simulator before issue 30, for comparisons; implies --no-write)')
    parser.add_argument('--no-write', action='store_true', help='print only (no results, no docs)')
    parser.add_argument('--resume', type=Path, metavar='JSONL',
                        help='append each scene\'s result here and skip the scenes already in it')
    parser.add_argument('--report', type=Path, metavar='JSONL',
                        help='run nothing: summarise and write the scenes of a --resume file '
                             '(those of several invocations, whatever their seeds)')
    parser.add_argument('--computed-by', default='', help='with --report: the invocations that '
                        'computed its scenes, for the docs')
    args = parser.parse_args(argv)
    if args.report:
        return report(args.report, args.computed_by, argv, not args.no_write)
    seeds = 3 if args.quick else args.seeds
    scenarios = [s for s in args.scenarios if s not in COMPOSITES or SHARED.is_dir()]
    rates = tuple(args.rates)
    tasks: list[Task] = [(name, seed, condition, args.configs, rates, args.planted)
                         for condition in args.conditions for name in scenarios
                         for seed in range(seeds)
                         if not (name in PLANTED and condition != 'clean')]
    start = time.perf_counter()
    results = _load_done(args.resume, tasks)
    resumed = len(results)
    done = {(r['scenario'], r['seed'], r['condition'], r.get('rate', native(r['scenario'])))
            for r in results}
    todo = [(*t[:4], tuple(rate for rate in t[4] if (*t[:3], rate) not in done), t[5])
            for t in tasks]
    todo = [t for t in todo if t[4]]
    count = sum(len(t[4]) for t in tasks)
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        for k, found in enumerate(pool.map(run_task, todo), 1):
            for result in found:
                results.append(result)
                if args.resume:
                    with args.resume.open('a') as f:
                        f.write(json.dumps(result) + '\n')
            print(f'[{len(results)}/{count}] {todo[k - 1][0]} seed {todo[k - 1][1]} '
                  f'{todo[k - 1][2]}', file=sys.stderr, flush=True)
    summary = summarise(results)
    meta = {'command': command_line(__file__, argv),
            'machine': machine(), 'wall_s': time.perf_counter() - start, 'seeds': seeds,
            'scenes': count, 'resumed_scenes': resumed}
    text = render(summary, meta, _pairs(results))
    print(text)
    if not (args.no_write or args.planted):
        _write(meta, summary, results, text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
