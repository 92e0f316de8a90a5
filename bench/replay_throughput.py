#!/usr/bin/env python3
"""Replay throughput: frames per second and real-time factor of ``hac replay``, CDR bytes to OUT.

    python bench/replay_throughput.py [--duration 600] [--rate 30] [--map-points 100000]
                                      [--profile-duration 60] [--keep DIR]

The recording: ``--duration`` seconds at ``--rate`` Hz of the core benchmark's room scene (a person
walking a circle, the camera following; bench/core_speed.py ``room_scene``), SLAM poses and HMR
joints every frame, and a ``--map-points`` map (floor and walls) republished every second, as a
SLAM system republishes its map; mcap, written to a temporary directory first (not timed). Timed:
``replay()`` from opening the recording to the renamed OUT, in ``online`` mode (one pass) and
``offline`` mode (the default: one run with deferred metric outputs, then resolved and written), including reading, CDR decoding, map indexing, the core,
message conversion, serialization and writing. A cProfile of an online replay of the first
``--profile-duration`` seconds says where the time goes. Prints, writes
bench/results/replay_throughput.json and the ``replay_throughput`` section of docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import cProfile
import io
import math
import pstats
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import machine, machine_line, table, write_json, write_section  # noqa: E402
from core_speed import TRUE_SCALE, room_scene  # noqa: E402

from hac_ros.core.numeric import NS  # noqa: E402
from hac_ros.replay import replay  # noqa: E402

NAME = 'replay_throughput'
TARGET_RTF = 50.0  # issue 6: at least 50x real time
GOAL_RTF = 100.0
# Where the time goes: the cumulative time of these functions (disjoint parts of the replay loop).
PARTS = (
    ('reading the recording (rosbags mcap reader)', (('hac_ros/replay.py', 'messages'),)),
    ('decoding poses and joints from CDR (msg_adapters.cdr)',
     (('msg_adapters/cdr.py', 'parse_pose_cdr'), ('msg_adapters/cdr.py', 'parse_joints_cdr'))),
    ('map: read header, decode points, build index',
     (('msg_adapters/cdr.py', 'parse_cloud_cdr'), ('hac_ros/inputs.py', 'index_cloud'))),
    ('core: the calibrator', (('hac_ros/core/calibrator.py', 'add_pose'),
                              ('hac_ros/core/calibrator.py', 'add_joints'),
                              ('hac_ros/core/calibrator.py', 'add_camera_info'),
                              ('hac_ros/core/calibrator.py', 'add_map_index'),
                              ('hac_ros/core/calibrator.py', 'flush'))),
    ('outputs -> CDR bytes (hac_ros/messages.py, msg_adapters.cdr_write)',
     (('hac_ros/messages.py', 'convert'), ('hac_ros/messages.py', 'samples_message'))),
    ('writing OUT (rosbags mcap writer)', (('rosbags/rosbag2/writer.py', 'write'),)),
)


# ============================================================================ the recording
def write_recording(path: Path, duration_s: float, rate: float, map_points: int) -> dict:
    """The benchmark recording (mcap). Returns its frame count and size."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from msg_adapters import joints_to_pose_array, rosbags_types, rt_to_pose_stamped, xyz_to_cloud

    typestore = get_typestore(Stores.ROS2_JAZZY)
    types = rosbags_types()
    frames = int(round(duration_s * rate))
    stamps, R_slam, c_slam, joints_cam, map_fn = room_scene(frames, rate)
    points = map_fn(map_points)
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    conn_pose = writer.add_connection('/slam/pose', 'geometry_msgs/msg/PoseStamped', typestore=typestore)
    conn_joints = writer.add_connection('/hmr/joints', 'geometry_msgs/msg/PoseArray', typestore=typestore)
    conn_cloud = writer.add_connection('/slam/cloud', 'sensor_msgs/msg/PointCloud2', typestore=typestore)
    next_map_ns = int(stamps[0])
    for t, stamp in enumerate(stamps.tolist()):
        if stamp >= next_map_ns:
            cloud = xyz_to_cloud(points, stamp, 'map', types)
            writer.write(conn_cloud, stamp, typestore.serialize_cdr(cloud, 'sensor_msgs/msg/PointCloud2'))
            next_map_ns += NS
        writer.write(conn_pose, stamp, typestore.serialize_cdr(
            rt_to_pose_stamped(R_slam[t], c_slam[t], stamp, 'map', types),
            'geometry_msgs/msg/PoseStamped'))
        writer.write(conn_joints, stamp, typestore.serialize_cdr(
            joints_to_pose_array(joints_cam[t], stamp, 'camera', types), 'geometry_msgs/msg/PoseArray'))
    writer.close()
    size = sum(f.stat().st_size for f in path.iterdir())
    return {'frames': frames, 'duration_s': frames / rate, 'maps': int(np.ceil(frames / rate)),
            'bytes': size}


# ============================================================================ measurements
def timed_replay(source: Path, out: Path, mode: str) -> dict:
    start = time.perf_counter()
    summary = replay(source, out, mode=mode, progress=False)
    wall = time.perf_counter() - start
    out_bytes = sum(f.stat().st_size for f in out.iterdir())
    return {'mode': mode, 'wall_s': wall, 'frames': summary.status.frames,
            'frames_per_s': summary.status.frames / wall, 'scale': summary.status.scale,
            'outputs': summary.outputs, 'output_bytes': out_bytes}


def profile_replay(source: Path, out: Path) -> tuple[list[tuple[str, float]],
                                                    list[tuple[str, float, float]], float]:
    """Shares of the replay's wall time by part, and the top functions by own time, of one online
    replay with everything on one thread (maps too) under cProfile."""
    profiler = cProfile.Profile()
    start = time.perf_counter()
    profiler.enable()
    replay(source, out, mode='online', progress=False, map_thread=False)  # all on this thread
    profiler.disable()
    wall = time.perf_counter() - start
    stats = pstats.Stats(profiler, stream=io.StringIO()).stats  # type: ignore[attr-defined]
    total = max(ct for (_, _, name), (_, _, _, ct, _) in stats.items()
                if name == 'replay')
    parts = []
    for label, functions in PARTS:
        cumulative = sum(ct for (filename, _, name), (_, _, _, ct, _) in stats.items()
                         if any(filename.endswith(f) and name == n for f, n in functions))
        parts.append((label, cumulative / total))
    parts.append(('the rest (replay loop, progress, summary)', 1.0 - sum(v for _, v in parts)))
    functions = sorted(((_short(f'{fn}:{line}({name})'), tt, ct)
                        for (fn, line, name), (_, _, tt, ct, _) in stats.items()),
                       key=lambda f: -f[1])
    return parts, functions[:12], wall


def _length(seconds: float) -> str:
    return f'{seconds / 60:.0f}-minute' if seconds >= 60 else f'{seconds:.0f}-second'


def _short(where: str) -> str:
    for marker in ('site-packages/', '/work/main/', 'lib/python3'):
        if marker in where:
            where = where.split(marker, 1)[1]
    return where


# ============================================================================ main
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, default=600.0, help='recording length, s')
    parser.add_argument('--rate', type=float, default=30.0, help='frame rate, Hz')
    parser.add_argument('--map-points', type=int, default=100_000, help='points per map message')
    parser.add_argument('--profile-duration', type=float, default=60.0,
                        help='length of the profiled recording, s (0: no profile)')
    parser.add_argument('--keep', metavar='DIR', help='keep the recordings in DIR')
    parser.add_argument('--repeats', type=int, default=3, help='timed replays per mode')
    args = parser.parse_args(argv)

    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix='hac_bench_replay_'))
    work.mkdir(parents=True, exist_ok=True)
    try:
        source = work / 'recording'
        if source.exists():
            shutil.rmtree(source)
        t0 = time.perf_counter()
        info = write_recording(source, args.duration, args.rate, args.map_points)
        print(f'recording: {info["frames"]} frames, {info["maps"]} maps of {args.map_points} '
              f'points, {info["bytes"] / 1e6:.0f} MB (written in {time.perf_counter() - t0:.0f} s)')
        runs = []
        for mode in ('online', 'offline'):
            out = work / f'out_{mode}'
            tries = []
            for _ in range(args.repeats):  # this machine's speed drifts: median and range
                if out.exists():
                    shutil.rmtree(out)
                tries.append(timed_replay(source, out, mode))
                shutil.rmtree(out)
            walls = sorted(t['wall_s'] for t in tries)
            result = tries[[t['wall_s'] for t in tries].index(walls[len(walls) // 2])]
            result['walls_s'] = walls
            result['real_time_factor'] = info['duration_s'] / result['wall_s']
            result['real_time_factor_range'] = [info['duration_s'] / walls[-1],
                                                info['duration_s'] / walls[0]]
            runs.append(result)
            print(f'{mode:8s}: {result["wall_s"]:.1f} s (median of {len(walls)}), '
                  f'{result["frames_per_s"]:.0f} frames/s, {result["real_time_factor"]:.0f}x real '
                  f'time ({result["real_time_factor_range"][0]:.0f}-'
                  f'{result["real_time_factor_range"][1]:.0f}x), scale {result["scale"]:.4g} '
                  f'(true {TRUE_SCALE})')
        categories, functions, profile_wall = [], [], 0.0
        if args.profile_duration > 0:
            short = work / 'profiled'
            if short.exists():
                shutil.rmtree(short)
            write_recording(short, min(args.profile_duration, args.duration), args.rate,
                            args.map_points)
            out = work / 'out_profiled'
            if out.exists():
                shutil.rmtree(out)
            categories, functions, profile_wall = profile_replay(short, out)
            print('where the time goes (online replay under cProfile, one thread):')
            for label, share in categories:
                print(f'  {100 * share:5.1f} %  {label}')
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)

    info_machine = machine()
    data = {'machine': info_machine, 'recording': {**info, 'rate_hz': args.rate,
                                                   'map_points': args.map_points},
            'runs': runs, 'target_rtf': TARGET_RTF, 'goal_rtf': GOAL_RTF,
            'profile': {'duration_s': args.profile_duration, 'wall_s': profile_wall,
                        'categories': categories,
                        'top_functions': [{'function': f, 'own_s': o, 'cumulative_s': c}
                                          for f, o, c in functions]}}
    write_json(NAME, data)
    write_section(NAME, report(data))
    return 0


def report(data: dict) -> str:
    rec = data['recording']
    rows = [[r['mode'], f"{r['wall_s']:.1f}", f"{r['frames_per_s']:.0f}",
             f"{r['real_time_factor']:.0f}x",
             '{:.0f}–{:.0f}x'.format(*r.get('real_time_factor_range', [math.nan] * 2)),
             'yes' if r['real_time_factor'] >= data['target_rtf'] else 'no']
            for r in data['runs']]
    lines = [
        '## Replay throughput (`bench/replay_throughput.py`)',
        '',
        f"`hac replay` of a {_length(rec['duration_s'])} {rec['rate_hz']:.0f} Hz recording "
        f"({rec['frames']} frames: SLAM pose and HMR joints of one person each; a "
        f"{rec['map_points']:,}-point map republished every second, {rec['maps']} maps; "
        f"{rec['bytes'] / 1e6:.0f} MB mcap), from CDR bytes to the written OUT (mcap), markers on. "
        f"Target (issue 6): at least {data['target_rtf']:.0f}x real time (goal {data['goal_rtf']:.0f}x).",
        '',
        table(['mode', 'median wall (s)', 'frames/s', 'real-time factor', 'range over the runs',
               f">= {data['target_rtf']:.0f}x"], rows),
        '',
    ]
    prof = data['profile']
    if prof['categories']:
        lines += [f"Where the time goes: cProfile of an online replay of the first "
                  f"{prof['duration_s']:.0f} s, maps indexed on the same thread (share of the "
                  "replay's time by part; the profiler slows Python code more than native code):",
                  '',
                  table(['share', 'part'], [[f'{100 * s:.1f} %', k] for k, s in prof['categories']]),
                  '', 'Top functions by own time:', '',
                  table(['function', 'own (s)', 'cumulative (s)'],
                        [[f'`{f["function"]}`', f"{f['own_s']:.2f}", f"{f['cumulative_s']:.2f}"]
                         for f in prof['top_functions']]), '']
    lines.append(machine_line(data['machine']))
    return '\n'.join(lines)


if __name__ == '__main__':
    sys.exit(main())
