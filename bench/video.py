#!/usr/bin/env python3
"""``hac video`` on rendered rooms with real people (bench/_video_scene.py): accuracy over paths
and seeds, and how the time grows with the keyframes.

    python bench/video.py accuracy [--paths sweep forward arc] [--seeds 0 1] [--frames 30]
    python bench/video.py speed [--keyframes 30 60 120] [--threads 2 1]

accuracy: each (path, seed) renders ``--frames`` frames at 640 x 480, 2 frames per second, every
person of one stature (seed 0: 1.59 m, seed 1: 1.72 m, 4 % under and over the model's prior;
odd seeds with motion blur and sensor noise), runs ``hac video`` with self-calibration and
keyframes by motion, and reports: keyframes registered, the focal's error, ATE after an SE(3) fit
over the path's length, the metric frame's up against the truth's, the scale's error against the
truth (Sim(3) fit of the reconstruction's cameras), the error the people alone leave (the same
joints on the true poses and map: :func:`_video_scene.people_alone`) and the body-size prior's
prediction (the model's prior stature P over the billboards' S, P the median of S times the
people-alone scale over the runs).

speed: one 640 x 480 sweep of the most ``--keyframes`` frames, taken whole and thinned evenly to
each count of ``--keyframes`` (every frame a keyframe: ``--keyframe-rate`` = the frames' rate), timed by stage, with each thread count of ``--threads``
(fewer threads at the smallest count only); and the keyframe choice per frame of a real video
(vtest.avi), which a clip of 30 frames per second pays on every frame.

Writes bench/results/video.json (accuracy) and bench/results/video_speed.json.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import _video_scene as vs
from _report import command_line, machine, write_json

from hac_ros.core.basics.errors import HacError
from hac_ros.files.tum import quats_to_rotations, read_tum
from hac_ros.video.pipeline import VideoOptions, video

STATURES = (1.59, 1.72)
FPS = 2.0
SIZE = (640, 480)


def one_run(path: str, seed: int, frames: int, work: Path) -> list[dict[str, Any]]:
    """One scene through hac video twice: self-calibrated, then with the true intrinsics given
    (the keyframes and people from the cache)."""
    stature = STATURES[seed % 2]
    noisy = seed % 2 == 1
    start = time.perf_counter()
    scene = vs.build(path, frames=frames, size=SIZE, statures=(stature,) * 3, fps=FPS,
                     seed=seed, blur=3 if noisy else 1, noise=3.0 if noisy else 0.0)
    render_s = time.perf_counter() - start
    folder = scene.write_folder(work / 'frames')
    K = scene.K
    runs = []
    for given in (False, True):
        out = work / ('out_given' if given else 'out')
        row: dict[str, Any] = {'path': path, 'seed': seed, 'stature_m': stature,
                               'blur_noise': noisy, 'frames': frames, 'intrinsics_given': given}
        camera = f'{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}' if given else None
        try:
            result = video(folder, out, VideoOptions(fps=FPS, cache=work / 'cache',
                                                     camera=camera))
        except HacError as exc:  # refused: a result too (the gates said no)
            runs.append(row | {'refused': str(exc).split(': ', 1)[-1]})
            continue
        stamps_ns, positions, quats = read_tum(out / 'camera_metric.tum')
        metric = vs.aligned(scene, stamps_ns / 1e9, positions, quats_to_rotations(quats))
        stamps_ns, positions, quats = read_tum(out / 'camera_slam.tum')
        slam = vs.aligned(scene, stamps_ns / 1e9, positions, quats_to_rotations(quats))
        alone = vs.people_alone(scene, out / 'inputs' / 'joints.npz',
                                work / ('alone_given' if given else 'alone'))
        assert result.replay is not None and result.replay.final_scale is not None
        scale = result.replay.final_scale
        runs.append(row | {
            'keyframes': result.keyframes,
            'registered': len(result.model.names) / result.keyframes,
            'focal_err': float(result.model.K[0, 0] / scene.K[0, 0] - 1),
            'reprojection_px': result.model.reprojection_px,
            'path_m': scene.path_length, 'ate_rel': metric['ate_rel'],
            'up_deg': metric['up_deg'], 'scale_err': float(scale / slam['scale'] - 1),
            'people_alone_err': float(alone - 1), 'samples': result.replay.status.samples,
            'people': result.people,
            'seconds': {'render': render_s, **result.seconds, **result.model.seconds}})
    return runs


def accuracy(args: argparse.Namespace, argv: list[str] | None) -> dict[str, Any]:
    runs: list[dict[str, Any]] = []
    for path in args.paths:
        for seed in args.seeds:
            with tempfile.TemporaryDirectory() as scratch:
                work = args.keep / f'{path}_{seed}' if args.keep else Path(scratch)
                both = one_run(path, seed, args.frames, work)
            runs += both
            for run in both:
                how = 'given K' if run['intrinsics_given'] else 'self-calibrated'
                if 'refused' in run:
                    print(f"{path} seed {seed} ({how}): refused: {run['refused']}", flush=True)
                    continue
                print(f"{path} seed {seed} ({how}): registered {run['registered']:.0%}, focal "
                      f"{run['focal_err']:+.1%}, ATE {run['ate_rel']:.2%} of "
                      f"{run['path_m']:.1f} m, up {run['up_deg']:.1f} deg, scale "
                      f"{run['scale_err']:+.2%} (people alone {run['people_alone_err']:+.2%}), "
                      f"{run['samples']} samples", flush=True)
    refused = [r for r in runs if 'refused' in r]
    runs = [r for r in runs if 'refused' not in r]
    # the model's prior stature as the people alone show it (true geometry, true intrinsics)
    prior = float(np.median([r['stature_m'] * (1 + r['people_alone_err']) for r in runs
                             if r['intrinsics_given']]))
    for run in runs:
        run['predicted_err'] = prior / run['stature_m'] - 1
        run['beyond_prediction'] = (1 + run['scale_err']) / (1 + run['predicted_err']) - 1
        run['beyond_people_alone'] = (1 + run['scale_err']) / (1 + run['people_alone_err']) - 1

    def stats(key: str, given: bool) -> dict[str, float]:
        values = np.array([r[key] for r in runs if r['intrinsics_given'] == given])
        size = np.abs(values)
        return {'median': float(np.median(size)), 'p90': float(np.percentile(size, 90)),
                'bias': float(np.median(values)), 'worst': float(size.max())}

    keys = ('ate_rel', 'up_deg', 'beyond_prediction', 'beyond_people_alone', 'focal_err')
    return {'command': command_line('bench/video.py', argv), 'machine': machine(),
            'prior_stature_m': prior, 'runs': runs, 'refused': refused,
            'summary': {how: {key: stats(key, given) for key in keys}
                        | {'registered_min': min(r['registered'] for r in runs
                                                 if r['intrinsics_given'] == given)}
                        for how, given in (('self_calibrated', False), ('given', True))}}


def speed(args: argparse.Namespace, argv: list[str] | None) -> dict[str, Any]:
    most = max(args.keyframes)
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        root = Path(scratch)
        start = time.perf_counter()
        scene = vs.build('sweep', frames=most, size=SIZE, statures=(1.59,) * 3, fps=FPS)
        render_s = time.perf_counter() - start
        everything = scene.write_folder(root / 'all')
        for count in sorted(args.keyframes):
            folder = root / f'frames_{count}'  # every (most / count)-th: the whole 3 m path
            folder.mkdir()
            for k, i in enumerate(np.linspace(0, most - 1, count).round().astype(int)):
                os.link(everything / f'frame_{i:05d}.png', folder / f'frame_{k:05d}.png')
            for threads in args.threads:
                if threads != max(args.threads) and count != min(args.keyframes):
                    continue  # fewer threads: at the smallest count only
                result = video(folder, root / f'out_{count}_{threads}',
                               VideoOptions(fps=FPS, keyframe_rate=FPS, threads=threads,
                                            cache=root / f'cache_{threads}'))
                seconds = {**result.seconds, **result.model.seconds}
                total = sum(v for k, v in result.seconds.items())
                rows.append({'keyframes': count, 'threads': threads, 'seconds': seconds,
                             'total_s': total, 'keyframes_per_min': 60 * count / total,
                             'registered': len(result.model.names) / result.keyframes})
                print(f"{count} keyframes, {threads} threads: {total:.0f} s "
                      + ', '.join(f'{k} {v:.0f} s' for k, v in seconds.items()), flush=True)
    return {'command': command_line('bench/video.py', argv), 'machine': machine(),
            'size': list(SIZE), 'render_s': render_s, 'rows': rows,
            'keyframe_choice_ms_per_frame': keyframe_choice_ms()}


def keyframe_choice_ms() -> float:
    """Milliseconds per frame of the keyframe stage's choice (decoding and tracking) on a real
    video: vtest.avi, 795 frames of 768 x 576 (a rendered clip has too few frames between its
    keyframes to show it)."""
    import cv2

    from hac_ros.video.keyframes import MotionKeyframes

    video = cv2.VideoCapture(str(vs.OPENCV_DATA / 'vtest.avi'))
    chooser = MotionKeyframes(10.0)
    start, frames = time.perf_counter(), 0
    while True:
        ok, bgr = video.read()
        if not ok:
            break
        chooser.add(bgr[:, :, ::-1])
        frames += 1
    video.release()
    return 1e3 * (time.perf_counter() - start) / max(1, frames)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest='what', required=True)
    acc = sub.add_parser('accuracy')
    acc.add_argument('--paths', nargs='+', default=['sweep', 'forward', 'arc'],
                     choices=('sweep', 'forward', 'arc'))
    acc.add_argument('--seeds', nargs='+', type=int, default=[0, 1])
    acc.add_argument('--frames', type=int, default=30)
    acc.add_argument('--keep', type=Path, default=None, metavar='DIR',
                     help='keep each run\'s frames, cache and outputs in DIR/<path>_<seed>')
    spd = sub.add_parser('speed')
    spd.add_argument('--keyframes', nargs='+', type=int, default=[30, 60, 120])
    spd.add_argument('--threads', nargs='+', type=int, default=[2, 1])
    parser.add_argument('--no-write', action='store_true')
    args = parser.parse_args(argv)
    if args.what == 'accuracy':
        result = accuracy(args, argv)
        name = 'video'
    else:
        result = speed(args, argv)
        name = 'video_speed'
    if not args.no_write:
        write_json(name, result)
    return 0


if __name__ == '__main__':
    sys.exit(main())
