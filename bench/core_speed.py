#!/usr/bin/env python3
"""Core speed: per-frame calibration cost against map size, beside the literal authors' method.

    python bench/core_speed.py [--sizes 10000 100000 1000000] [--frames 200]

Measured side by side in one run, on one core:
- per-frame calibration (contact selection, reference distance, estimator update; one person) with
  maps of each size, for ``lowest`` (one ray) and ``max_ratio`` (24 rays), after convergence;
- the literal method of the authors' code on the same frames and maps: every map point against
  every joint ray of the frame (cone cos > 0.999, median distance, maximum ratio);
- map ingestion: PointCloud2 CDR bytes → (N, 3) → queryable index;
- 1000 frames of the simulator's ``walk`` through the core, map ingestion excluded.
Prints a table, writes bench/results/core_speed.json and the ``core_speed`` section of
docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import machine, machine_line, table, write_json, write_section  # noqa: E402

from hac_ros.core.calibrator import Calibrator  # noqa: E402
from hac_ros.core.params import HacParams  # noqa: E402
from hac_ros.core.reference import MapIndex  # noqa: E402

TRUE_SCALE = 0.5
COS_AUTHORS = 0.999  # authors' code: cone cos > 0.999
WALK_REPEATS = 5  # the 1000-frame walk is timed this many times: median (and worst) reported
MODES = ('lowest_gravity', 'lowest', 'max_ratio')  # the default first


def room_scene(frames: int, rate: float = 30.0, seed: int = 0):
    """A person walking a 3 m circle in a 12 m room; a camera 1.5 m high following 4 m away.

    Returns stamps (F,), R_wc_slam (F,3,3), c_slam (F,3), joints_cam (F,24,3) and a function
    ``map_points(n) -> (n,3)`` (SLAM units): the floor (70 %) and walls (30 %), 1 cm noise.
    """
    rng = np.random.default_rng(seed)
    stance = np.array([[0, 0, .93], [.09, 0, .86], [-.09, 0, .86], [0, .01, 1.05], [.1, 0, .46],
                       [-.1, 0, .46], [0, .01, 1.18], [.1, .02, .08], [-.1, .02, .08], [0, .01, 1.26],
                       [.11, -.1, 0], [-.11, -.1, 0], [0, 0, 1.45], [.07, 0, 1.38], [-.07, 0, 1.38],
                       [0, -.02, 1.62], [.18, 0, 1.4], [-.18, 0, 1.4], [.22, 0, 1.12], [-.22, 0, 1.12],
                       [.24, -.03, .86], [-.24, -.03, .86], [.25, -.05, .78], [-.25, -.05, .78]])
    t = np.arange(frames) / rate
    angle = 0.3 * t
    person = np.stack([3 * np.cos(angle), 3 * np.sin(angle), np.zeros(frames)], 1)
    cam = person * (7.0 / 3.0) * [1, 1, 0] + [0, 0, 1.5]
    stamps = (t * 1e9).astype(np.int64) + 1_000_000_000
    R = np.empty((frames, 3, 3))
    J = np.empty((frames, 24, 3))
    for i in range(frames):
        z = person[i] + [0, 0, 0.3] - cam[i]
        z /= np.linalg.norm(z)
        x = np.cross(z, [0, 0, 1.0])
        x /= np.linalg.norm(x)
        R[i] = np.stack([x, np.cross(z, x), z], 1)
        body = stance + person[i]
        body[10 + i % 2, 2] += 0.08
        J[i] = (body - cam[i]) @ R[i] + rng.normal(0, 0.01, (24, 3))
    R0, c0 = R[0], cam[0]

    def to_slam(p):
        return (p - c0) @ R0 / TRUE_SCALE

    def map_points(n: int) -> np.ndarray:
        r = np.random.default_rng(n)
        nf = int(0.7 * n)
        floor = np.c_[r.uniform(-6, 6, (nf, 2)), np.zeros(nf)]
        nw = n - nf
        side = r.integers(0, 4, nw)
        u, h = r.uniform(-6, 6, nw), r.uniform(0, 3, nw)
        walls = np.where(side[:, None] == 0, np.c_[u, np.full(nw, 6.0), h],
                         np.where(side[:, None] == 1, np.c_[u, np.full(nw, -6.0), h],
                                  np.where(side[:, None] == 2, np.c_[np.full(nw, 6.0), u, h],
                                           np.c_[np.full(nw, -6.0), u, h])))
        return to_slam(np.vstack([floor, walls]) + r.normal(0, 0.01, (n, 3)))

    R_slam = np.einsum('ji,tjk->tik', R0, R)
    return stamps, R_slam, to_slam(cam), J, map_points


def literal_frame(points: np.ndarray, R_wc: np.ndarray, c: np.ndarray, joints_cam: np.ndarray) -> float:
    """The authors' per-frame computation: every point against every joint ray, the max ratio."""
    v = points - c
    dist = np.sqrt(np.einsum('ij,ij->i', v, v))
    d_a = np.linalg.norm(joints_cam, axis=1)
    rays = (joints_cam / d_a[:, None]) @ R_wc.T
    cos = (v @ rays.T) / dist[:, None]  # (N, 24)
    best = -math.inf
    for j in range(rays.shape[0]):
        inside = cos[:, j] > COS_AUTHORS
        if inside.any():
            best = max(best, d_a[j] / float(np.median(dist[inside])))
    return best


def time_frames(cal: Calibrator, stamps, R, c, J, start: int, count: int) -> np.ndarray:
    """Per-frame seconds of add_joints (the pose of the stamp is already in)."""
    out = np.empty(count)
    for k, i in enumerate(range(start, start + count)):
        cal.add_pose(int(stamps[i]), R[i], c[i], 'map')
        t0 = time.perf_counter()
        cal.add_joints(int(stamps[i]), J[i][None], 'camera')
        out[k] = time.perf_counter() - t0
    return out


def ingestion_seconds(points: np.ndarray) -> dict[str, float]:
    from rosbags.typesys import Stores, get_typestore

    from msg_adapters import cloud_points, parse_cloud_cdr, rosbags_types, xyz_to_cloud
    typestore = get_typestore(Stores.ROS2_JAZZY)
    msg = xyz_to_cloud(points, 0, 'map', rosbags_types(typestore))
    raw = typestore.serialize_cdr(msg, 'sensor_msgs/msg/PointCloud2')
    t0 = time.perf_counter()
    xyz = cloud_points(parse_cloud_cdr(raw))  # the node's raw path: header by hand, points by view
    t1 = time.perf_counter()
    MapIndex(xyz, 'map', 0, HacParams().index_max_points)
    t2 = time.perf_counter()
    return {'decode_s': t1 - t0, 'index_s': t2 - t1, 'total_s': t2 - t0}


def walk_1000_frames() -> dict[str, float]:
    from hac_ros.simulate import make_scenario
    from hac_ros.simulate.feed import scenario_events

    sc = make_scenario('walk', seed=0, duration=1000 / 30.0 + 1.0, rate=30.0)
    events = list(scenario_events(sc))
    # maps indexed beforehand: ingestion excluded
    indexed = [(stamp, kind, MapIndex(p[0], p[1], stamp) if kind == 'map' else p)
               for stamp, kind, p in events]
    frames = sum(1 for _, kind, _ in events if kind == 'joints')
    walls = []
    for _ in range(WALK_REPEATS):  # a fresh calibrator each time; the first run warms caches
        cal = Calibrator(HacParams())
        cal.add_camera_info(sc.K, sc.width, sc.height, sc.camera_frame)
        t0 = time.perf_counter()
        for stamp, kind, payload in indexed:
            if kind == 'map':
                cal.add_map_index(payload)
            elif kind == 'pose':
                cal.add_pose(stamp, *payload)
            else:
                cal.add_joints(stamp, *payload)
        cal.flush()
        walls.append(time.perf_counter() - t0)
    wall = float(np.median(walls))
    return {'frames': frames, 'repeats': WALK_REPEATS, 'wall_s': wall,
            'walls_s': walls, 'per_1000_frames_s': wall * 1000 / frames,
            'worst_per_1000_frames_s': max(walls) * 1000 / frames,
            'scale_error_%': abs(cal.scale / float(np.median(sc.true_scale)) - 1) * 100}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[10_000, 100_000, 1_000_000])
    parser.add_argument('--frames', type=int, default=200, help='timed frames per size and mode')
    parser.add_argument('--literal-frames', type=int, default=20)
    args = parser.parse_args()
    try:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    except (AttributeError, OSError):
        pass
    warm = 60
    stamps, R, c, J, map_points = room_scene(warm + args.frames)
    rows, results = [], {'machine': machine(), 'sizes': {}}
    for n in args.sizes:
        points = map_points(n)
        entry: dict[str, float] = {}
        for mode in MODES:
            cal = Calibrator(HacParams(contact_mode=mode))
            cal.add_map(int(stamps[0]), points, 'map')
            time_frames(cal, stamps, R, c, J, 0, warm)  # converge first
            assert cal.converged, 'the estimator did not converge in the warm-up'
            per = time_frames(cal, stamps, R, c, J, warm, args.frames)
            entry[f'{mode}_median_ms'] = float(np.median(per) * 1e3)
            entry[f'{mode}_p99_ms'] = float(np.percentile(per, 99) * 1e3)
            entry[f'{mode}_scale_error_%'] = abs(cal.scale / TRUE_SCALE - 1) * 100
        lit = np.empty(args.literal_frames)
        lit_scales = []
        for k in range(args.literal_frames):
            i = warm + k
            t0 = time.perf_counter()
            lit_scales.append(literal_frame(points, R[i], c[i], J[i]))
            lit[k] = time.perf_counter() - t0
        entry['literal_median_ms'] = float(np.median(lit) * 1e3)
        entry['literal_scale_error_%'] = abs(float(np.median(lit_scales)) / TRUE_SCALE - 1) * 100
        entry['speedup_lowest'] = entry['literal_median_ms'] / entry['lowest_median_ms']
        entry['speedup_max_ratio'] = entry['literal_median_ms'] / entry['max_ratio_median_ms']
        entry.update({f'ingest_{k}': v for k, v in ingestion_seconds(points).items()})
        results['sizes'][n] = entry
        entry['speedup_lowest_gravity'] = entry['literal_median_ms'] / entry['lowest_gravity_median_ms']
        rows.append([f'{n:,}', entry['lowest_gravity_median_ms'], entry['lowest_gravity_p99_ms'],
                     entry['lowest_median_ms'], entry['max_ratio_median_ms'],
                     entry['literal_median_ms'], entry['speedup_lowest_gravity'],
                     entry['speedup_max_ratio'], entry['ingest_total_s']])
        print(f'{n:>9,} points: lowest_gravity {entry["lowest_gravity_median_ms"]:.3f} ms, lowest '
              f'{entry["lowest_median_ms"]:.3f} ms, max_ratio {entry["max_ratio_median_ms"]:.3f} ms, '
              f'literal {entry["literal_median_ms"]:.1f} ms, ingest {entry["ingest_total_s"]:.3f} s',
              flush=True)
    results['walk_1000'] = walk_1000_frames()
    headers = ['map points', 'lowest_gravity (default) median ms', 'lowest_gravity p99 ms',
               'lowest median ms', 'max_ratio median ms', 'literal median ms',
               'speed-up (lowest_gravity)', 'speed-up (max_ratio)', 'ingest s']
    walk = results['walk_1000']
    text = '\n'.join([
        f'Command: `python bench/core_speed.py`. {machine_line(results["machine"])} '
        'Pinned to one core.', '',
        'Per-frame calibration after convergence (contact selection, ray query, estimator update; one '
        'person), beside the literal method of the authors\' code (every map point against every '
        'joint ray of the frame) on the same frames and maps, in the same run. Ingest: PointCloud2 '
        'CDR bytes → (N, 3) (the node\'s raw path) → k-d tree (thinned to index_max_points).', '',
        table(headers, rows), '',
        f'1000 frames of the simulated `walk` through the core (SLAM poses, HMR joints and maps in '
        f'processing order, maps indexed beforehand, default parameters): '
        f'{walk["per_1000_frames_s"]:.3f} s per 1000 frames (median of {walk["repeats"]} runs; '
        f'worst {walk["worst_per_1000_frames_s"]:.3f} s; {walk["frames"]} frames, scale error '
        f'{walk["scale_error_%"]:.2f} %). Target (issue 6): 0.2 s. The paper: 5 s per 1000 '
        'frames on an RTX 2080 Ti.'])
    print(text)
    write_json('core_speed', results)
    write_section('core_speed', '## Core speed (`bench/core_speed.py`)\n\n' + text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
