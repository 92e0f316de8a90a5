#!/usr/bin/env python3
"""Input variants against the SMPL-24 optical-frame case, on the same recordings, over many seeds.

    python bench/variants.py [--seeds 20] [--scenarios walk crowd ...] [--workers 2]

Each scene (a clean simulated scenario at its own duration, or a clean real-data composite of
bench/composite.py) is run through the core's offline estimate (bench/_accuracy_runs.py:
``run_ours``, the replay's default) as it comes and as a real pipeline may deliver it:

- every other layout the simulator writes (``coco17``, ...): the HMR model's joints in that
  layout (the simulator writes the layout; the composite's joints are mapped by
  ``hac_ros.simulate.skeletons``), ``joint_layout`` set;
- ``focal``: an HMR model that assumed a focal length of 800 px on the camera (the people at
  800/f times their depth), ``hmr_focal_px: 800``;
- ``body_frame``: SLAM poses of an x-forward, z-up camera frame, ``pose_to_optical`` set;
- ``imported``: the scene written as files (TUM trajectory, the last map as .npy, joints .npz)
  and read back by ``hac import`` (simulated scenes only: the composite has no recording).

Per variant: the median and p90 of the absolute scale error (%), the median signed error, and the
median over the seeds of (variant error − SMPL-24 error) in points: issue 21's target is that
no variant is worse than the SMPL-24 case by more than 0.5 point. Writes
bench/results/variants.json and the ``variants`` section of docs/accuracy.md.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import (
    ACCURACY_DOC,
    command_line,
    machine,
    machine_line,
    table,
    write_json,
    write_section,
)

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / 'shared' / 'data'
SCENARIOS = ('walk', 'crowd', 'stairs', 'static', 'composite')
sys.path.insert(0, str(REPO))
from hac_ros.simulate.skeletons import simulated_layouts

OTHER_LAYOUTS = tuple(name for name in simulated_layouts() if name != 'smpl24')
VARIANTS = ('smpl24', *OTHER_LAYOUTS, 'focal', 'body_frame', 'imported')
HMR_FOCAL_PX = 800.0
BODY_FRAME_Q = [-0.5, 0.5, -0.5, 0.5]
TARGET_POINTS = 0.5


def _focal(events: list, fx: float) -> list:
    """The joints as an HMR model with focal HMR_FOCAL_PX places them: z + z_root (f_a/f − 1)."""
    out = []
    for stamp, kind, payload in events:
        if kind == 'joints':
            joints = payload[0].copy()
            joints[:, :, 2] += joints[:, 0:1, 2] * (HMR_FOCAL_PX / fx - 1.0)  # SMPL-24 root
            payload = (joints, *payload[1:])
        out.append((stamp, kind, payload))
    return out


def _body_frame(events: list) -> list:
    """SLAM poses of the body frame: R_map_body = R_map_optical · R(q)^T."""
    from scipy.spatial.transform import Rotation

    R_q = Rotation.from_quat(BODY_FRAME_Q).as_matrix()
    return [(s, k, (p[0] @ R_q.T, *p[1:]) if k == 'pose' else p) for s, k, p in events]


def _imported(sc: Any, scene: Any, params: Any, directory: Path) -> dict[str, float]:
    """The scenario through files and ``hac import``, then the replay's own input path
    (``hac_ros.replay.feeder.offline_run``): its figures."""
    from _accuracy_runs import figures

    from hac_ros.files.importer import import_files
    from hac_ros.files.tum import rotations_to_quats, write_tum
    from hac_ros.recording.reader import Recording
    from hac_ros.replay.feeder import offline_run

    write_tum(directory / 'slam.tum', sc.pose_stamps_ns, sc.slam_c, rotations_to_quats(sc.slam_R_wc))
    np.save(directory / 'map.npy', sc.maps[-1].points_slam.astype(float))
    row = {int(s): i for i, s in enumerate(sc.pose_stamps_ns)}
    joints = np.full((len(row), max(len(j) for j in sc.joints_cam), 24, 3), np.nan)
    for k, stamp in enumerate(sc.joints_stamps_ns):
        joints[row[int(stamp)], :len(sc.joints_cam[k])] = sc.joints_cam[k]
    np.savez(directory / 'joints.npz', stamps=sc.pose_stamps_ns / 1e9, joints=joints)
    (fx, _, cx), (_, fy, cy) = sc.K[:2].tolist()
    import_files(directory / 'rec', directory / 'slam.tum', directory / 'map.npy',
                 directory / 'joints.npz', camera=f'{fx},{fy},{cx},{cy},{sc.width},{sc.height}',
                 joint_layout='smpl24')
    with Recording(directory / 'rec') as rec:
        cal = offline_run(rec, params)
    return figures(scene, params, cal, {})


def run_task(task: tuple[str, int]) -> dict[str, Any]:
    """One scene (scenario, seed) through every variant."""
    import dataclasses

    from _accuracy_runs import Scene, run_ours, scene_from_composite, scene_from_scenario

    from hac_ros.core.rules.params import HacParams
    from hac_ros.simulate import make_scenario
    from hac_ros.simulate.skeletons import to_layout

    name, seed = task
    base = HacParams()
    rows: dict[str, dict[str, float]] = {}
    sc = None
    if name == 'composite':
        from composite import build

        scene = scene_from_composite(build(SHARED, seed, hmr_bias=0.0), seed)
    else:
        sc = make_scenario(name, seed=seed, hmr_bias=0.0)
        scene = scene_from_scenario(sc)
    variants: dict[str, tuple[Scene, HacParams]] = {
        'smpl24': (scene, base),
        'focal': (dataclasses.replace(scene, events=_focal(scene.events, float(scene.K[0, 0]))),
                  base.replace(hmr_focal_px=HMR_FOCAL_PX)),
        'body_frame': (dataclasses.replace(scene, events=_body_frame(scene.events)),
                       base.replace(pose_to_optical=BODY_FRAME_Q))}
    for layout in OTHER_LAYOUTS:
        if sc is not None:  # the simulator writes the layout (its own detection and noise)
            other = scene_from_scenario(make_scenario(name, seed=seed, hmr_bias=0.0,
                                                      joint_layout=layout))
        else:
            other = dataclasses.replace(scene, events=[
                (s, k, (to_layout(p[0], layout), *p[1:]) if k == 'joints' else p)
                for s, k, p in scene.events],
                joints_world=[to_layout(j, layout) for j in scene.joints_world])
        variants[layout] = (other, base.replace(joint_layout=layout))
    figures = {variant: run_ours(v_scene, params, {}) for variant, (v_scene, params)
               in variants.items()}
    if sc is not None:
        with tempfile.TemporaryDirectory() as tmp:
            figures['imported'] = _imported(sc, scene, base, Path(tmp))
    for variant, row in figures.items():
        rows[variant] = {k: row[k] for k in ('scale_err', 'scale_bias')}
    return {'scenario': name, 'seed': seed, 'rows': rows}


def summarise(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Per scenario (and 'all') and variant: median, p90 |error|, median bias, and the median
    over the seeds of the error's excess over SMPL-24 (points)."""
    out: dict[str, Any] = {}
    for scenario in [*SCENARIOS, 'all']:
        mine = [r for r in results if scenario in ('all', r['scenario'])]
        if not mine:
            continue
        out[scenario] = {}
        for variant in VARIANTS:
            pairs = [(r['rows'][variant], r['rows']['smpl24']) for r in mine
                     if variant in r['rows']]
            if not pairs:
                continue
            err = np.array([v['scale_err'] for v, _ in pairs])
            excess = np.array([v['scale_err'] - b['scale_err'] for v, b in pairs])
            out[scenario][variant] = {
                'median': float(np.nanmedian(err)), 'p90': float(np.nanpercentile(err, 90)),
                'bias': float(np.nanmedian([v['scale_bias'] for v, _ in pairs])),
                'excess': float(np.nanmedian(excess)), 'scenes': len(pairs)}
    return out


def render(summary: dict[str, Any], meta: dict[str, Any]) -> str:
    """One row per variant: the figures over every scene, then its excess over SMPL-24 per
    scenario and over all (points)."""
    scenes = [s for s in summary if s != 'all']
    rows = []
    for variant, c in summary['all'].items():
        excess = [summary[s][variant]['excess'] if variant in summary[s] else None for s in scenes]
        cells = ['' if variant == 'smpl24' or e is None else f'{e:+.2f}' for e in excess]
        failing = [s for s, e in zip(scenes, excess) if e is not None and e > TARGET_POINTS]
        met = '' if variant == 'smpl24' else (
            '**no**: ' + ', '.join(failing) if failing else 'yes')
        rows.append([variant, f"{c['median']:.2f}", f"{c['p90']:.2f}", f"{c['bias']:+.2f}", *cells,
                     '' if variant == 'smpl24' else f"{c['excess']:+.2f}", met, str(c['scenes'])])
    return (f"{machine_line(meta['machine'])}; `{meta['command']}`, {meta['wall_s']:.0f} s.\n\n"
            'Clean scenes (no HMR depth bias), offline estimate; |error| and bias in % over every '
            'scene. Per scene and overall: the median over the seeds of the variant\'s |error| minus '
            f'the SMPL-24 case\'s on the same scene, in points (target: <= +{TARGET_POINTS} on every '
            'scene); '
            '`imported` runs on the simulated scenes only.\n\n'
            + table(['variant', 'median', 'p90', 'bias', *scenes, 'all', 'target met', 'scenes'],
                    rows))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seeds', type=int, default=20)
    parser.add_argument('--scenarios', nargs='+', default=list(SCENARIOS), choices=SCENARIOS)
    parser.add_argument('--workers', type=int, default=len(os.sched_getaffinity(0)))
    parser.add_argument('--no-write', action='store_true', help='print only (no results, no docs)')
    args = parser.parse_args(argv)
    scenarios = [s for s in args.scenarios if s != 'composite' or SHARED.is_dir()]
    tasks = [(name, seed) for name in scenarios for seed in range(args.seeds)]
    start = time.perf_counter()
    results = []
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        for k, result in enumerate(pool.map(run_task, tasks), 1):
            results.append(result)
            print(f'[{k}/{len(tasks)}] {result["scenario"]} seed {result["seed"]}',
                  file=sys.stderr, flush=True)
    summary = summarise(results)
    meta = {'command': command_line(__file__, argv),
            'machine': machine(), 'wall_s': time.perf_counter() - start}
    text = render(summary, meta)
    print(text)
    if not args.no_write:
        write_json('variants', {'meta': meta, 'summary': summary, 'scenes': results})
        write_section('variants', '## Input variants (`bench/variants.py`)\n\n' + text, ACCURACY_DOC)
    return 0


if __name__ == '__main__':
    sys.exit(main())
