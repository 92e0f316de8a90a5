#!/usr/bin/env python3
"""Core speed: per-frame calibration against the literal authors' method, as a ratio.

    python bench/core_speed.py [--sizes 10000 100000 1000000] [--frames 300] [--literal-frames 20]

On the room scene (bench/_scene.py) with a map of N points, side by side in one process pinned
to one core:
- ours: one frame = ``Calibrator.add_pose`` + ``add_joints`` of one stamp (one person), default
  parameters, after a 60-frame warm-up (the estimator converged);
- the literal method of the authors' code (:func:`literal_frame`) on the same frames and map.
The two are interleaved in blocks (one literal frame, then a block of ours), so both see the same
machine speed. Ratio = the literal method's median ms per frame / ours. Guard:
>= 100x at 1M points. Prints, writes bench/results/core_speed.json and its section of
docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import check, command_line, machine, publish, section, table
from _scene import CAMERA_FRAME, MAP_FRAME, TRUE_SCALE, RoomScene, room_scene

from hac_ros.core.calibrator import Calibrator
from hac_ros.core.rules.params import HacParams

NAME = 'core_speed'
AUTHORS_CONE_COS = 0.999  # the authors' code: a map point is on a joint's ray when cos > 0.999
WARMUP_FRAMES = 60
TARGET_RATIO = 100.0  # at 1M map points
TARGET_POINTS = 1_000_000


def literal_frame(points_map: np.ndarray, R_wc: np.ndarray, c_map: np.ndarray,
                  joints_cam: np.ndarray) -> float:
    """The authors' per-frame scale: every map point against every joint's ray.

    points_map: (N, 3) SLAM units, map frame; R_wc (3, 3), c_map (3,): the camera in the map frame;
    joints_cam: (24, 3) metres, camera optical frame. For each joint, the map points within the
    cone cos > 0.999 around its ray; the ratio of the joint's metric distance to their median SLAM
    distance; the largest ratio over the joints (metres per SLAM unit; -inf if no cone has points).
    """
    v = points_map - c_map
    dist = np.sqrt(np.einsum('ij,ij->i', v, v))
    joint_dist = np.linalg.norm(joints_cam, axis=1)
    rays_map = (joints_cam / joint_dist[:, None]) @ R_wc.T
    cos = (v @ rays_map.T) / dist[:, None]  # (N, 24)
    best = -math.inf
    for j in range(len(joints_cam)):
        inside = cos[:, j] > AUTHORS_CONE_COS
        if inside.any():
            best = max(best, joint_dist[j] / float(np.median(dist[inside])))
    return best


def pin_to_one_core() -> None:
    with contextlib.suppress(AttributeError, OSError):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def measure(scene: RoomScene, map_points: int, frames: int, literal_frames: int) -> dict[str, Any]:
    """Per-frame ms of ours and of the literal method, interleaved, on ``scene`` (at least
    WARMUP_FRAMES + ``frames`` long) with a ``map_points`` map."""
    points = scene.map_points(map_points)
    calibrator = Calibrator(HacParams())
    calibrator.add_map(int(scene.stamps_ns[0]), points, MAP_FRAME)

    def ours(i: int) -> float:
        stamp = int(scene.stamps_ns[i])
        start = time.perf_counter()
        calibrator.add_pose(stamp, scene.R_wc[i], scene.c[i], MAP_FRAME)
        calibrator.add_joints(stamp, scene.joints_cam[i][None], CAMERA_FRAME)
        return (time.perf_counter() - start) * 1e3

    for i in range(WARMUP_FRAMES):
        ours(i)
    ours_ms, literal_ms, literal_scales = [], [], []
    block = math.ceil(frames / literal_frames)
    for k in range(literal_frames):
        i = WARMUP_FRAMES + k
        start = time.perf_counter()
        literal_scales.append(literal_frame(points, scene.R_wc[i], scene.c[i], scene.joints_cam[i]))
        literal_ms.append((time.perf_counter() - start) * 1e3)
        for i in range(WARMUP_FRAMES + k * block, WARMUP_FRAMES + min(frames, (k + 1) * block)):
            ours_ms.append(ours(i))
    calibrator.flush()
    ours_median, literal_median = float(np.median(ours_ms)), float(np.median(literal_ms))
    return {'map_points': map_points, 'frames': len(ours_ms), 'literal_frames': literal_frames,
            'ours_median_ms': ours_median, 'ours_p99_ms': float(np.percentile(ours_ms, 99)),
            'literal_median_ms': literal_median, 'ratio': literal_median / ours_median,
            'ours_scale_error_%': abs(calibrator.scale / TRUE_SCALE - 1) * 100,
            'literal_scale_error_%': abs(float(np.median(literal_scales)) / TRUE_SCALE - 1) * 100}


def report(data: dict[str, Any]) -> str:
    rows = [[f"{r['map_points']:,}", f"{r['ratio']:.0f}x", r['ours_median_ms'],
             r['literal_median_ms'], r['ours_p99_ms'], f"{r['ours_scale_error_%']:.2f}",
             f"{r['literal_scale_error_%']:.2f}"] for r in data['sizes']]
    return section(
        'Core speed', data['command'],
        'Per-frame calibration (`add_pose` + `add_joints` of one stamp, one person, default '
        'parameters, after convergence) against the literal authors\' method (every map point '
        'against every joint ray, cone cos > 0.999, median distance, the largest ratio over the '
        'joints) on the same frames and map of the room scene, interleaved in one process pinned '
        f'to one core. Ratio: literal / ours, median ms per frame. Target: >= {TARGET_RATIO:.0f}x '
        f'at {TARGET_POINTS:,} points. The ms are this host\'s raw data.',
        table(['map points', 'ratio', 'ours median ms', 'literal median ms', 'ours p99 ms',
               'ours scale error %', 'literal scale error %'], rows),
        data['machine'])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[10_000, 100_000, 1_000_000],
                        help='map points')
    parser.add_argument('--frames', type=int, default=300, help='our timed frames per size')
    parser.add_argument('--literal-frames', type=int, default=20,
                        help="the literal method's timed frames per size")
    args = parser.parse_args(argv)
    pin_to_one_core()
    info = machine()
    scene = room_scene(WARMUP_FRAMES + max(args.frames, args.literal_frames))
    sizes = []
    for n in args.sizes:
        r = measure(scene, n, args.frames, args.literal_frames)
        sizes.append(r)
        print(f"{n:>9,} points: ours {r['ours_median_ms']:.3f} ms, literal "
              f"{r['literal_median_ms']:.1f} ms per frame: {r['ratio']:.0f}x", flush=True)
    command = command_line(__file__, argv)
    checks = [check(f'per-frame calibration at {r["map_points"]:,} points vs the literal method',
                    f"{r['ratio']:.0f}x", f'>= {TARGET_RATIO:.0f}x', r['ratio'] >= TARGET_RATIO)
              for r in sizes if r['map_points'] == TARGET_POINTS]
    data = {'machine': info, 'command': command, 'sizes': sizes, 'checks': checks}
    markdown = report(data)
    publish(NAME, data, markdown)
    print(markdown)
    return 0


if __name__ == '__main__':
    sys.exit(main())
