#!/usr/bin/env python3
"""Node memory: ``hac_node``'s resident size over an accelerated hour must stay flat.

    python bench/node_memory.py [--hours 1.0] [--fps 300] [--map-points 100000] [--warmup 0.1]

``hac_node`` runs in a process of its own with the checkout's config/hac.yaml. This process plays
``--hours`` of stamp time of the room scene (bench/_scene.py) at 30 Hz stamp rate but ``--fps``
frames per wall second: a SLAM pose and the HMR joints per frame, and a ``--map-points`` map every
stamp second (serialized once, its stamp patched). The node's resident set size (VmRSS of
/proc/<pid>/status) is sampled every wall second. The first ``--warmup`` fraction of the run is
not measured (the rolling window, the camera-path marker and the contact buffer fill up). Growth =
median RSS of the last 5 % of the samples / median of the first 5 % after the warm-up, minus 1.
Guard: < 5 %.

Sets the DDS environment through bench/node_latency.py (imported first). Prints, writes
bench/results/node_memory.json and its section of docs/benchmarks.md.
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import argparse
import tempfile
import time
from typing import Any

import node_latency as nl
import numpy as np
import rclpy
from _report import check, command_line, machine, publish, section, table
from _scene import NS, RATE_HZ, cloud_cdr, joints_cdr, pose_cdr, room_scene, set_cdr_stamp

NAME = 'node_memory'
TARGET_GROWTH = 0.05
EDGE = 0.05  # the share of the measured samples whose median is taken at each end


def rss_bytes(pid: int) -> int:
    """Resident set size of process ``pid``, bytes."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) * 1024
    raise RuntimeError(f'no VmRSS for process {pid}')


def run(hours: float, fps: float, map_points: int) -> dict[str, Any]:
    """Plays the scene to a fresh hac_node; returns the RSS samples (stamp s, frame, bytes)."""
    scene = room_scene(int(round(hours * 3600.0 * RATE_HZ)))
    cloud = bytearray(cloud_cdr(scene.map_points(map_points), 0))
    samples: list[tuple[float, int, int]] = []
    rclpy.init()
    with tempfile.TemporaryFile(mode='w+') as log:
        proc = nl.start_node('node', log)
        player = nl.Player(bytes(cloud))
        try:
            deadline = time.monotonic() + nl.STARTUP_S
            while not player.matched():
                if time.monotonic() > deadline or proc.poll() is not None:
                    raise RuntimeError('hac_node did not come up')
                time.sleep(0.05)
            start = next_sample = time.perf_counter()
            next_map_ns = int(scene.stamps_ns[0])
            for i, stamp in enumerate(scene.stamps_ns.tolist()):
                if stamp >= next_map_ns:
                    set_cdr_stamp(cloud, stamp)
                    player.map_pub.publish(bytes(cloud))
                    next_map_ns += NS
                player.pose_pub.publish(pose_cdr(scene.R_wc[i], scene.c[i], stamp))
                player.joints_pub.publish(joints_cdr(scene.joints_cam[i], stamp))
                now = time.perf_counter()
                if now >= next_sample:
                    samples.append(((stamp - scene.stamps_ns[0]) / NS, i, rss_bytes(proc.pid)))
                    next_sample = now + 1.0
                delay = start + (i + 1) / fps - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
            wall = time.perf_counter() - start
            time.sleep(nl.DRAIN_S)
            samples.append(((scene.stamps_ns[-1] - scene.stamps_ns[0]) / NS, len(scene),
                            rss_bytes(proc.pid)))
        finally:
            player.close()
            code = nl.stop_node(proc)
            rclpy.try_shutdown()
            log.seek(0)
            tail = log.read()[-2000:]
    if code != 0 or 'Traceback' in tail:
        print(f'hac_node exited with {code}:\n{tail}', file=sys.stderr)
    return {'hours_of_stamps': hours, 'frames': len(scene), 'wall_s': wall,
            'map_points': map_points, 'exit_code': code, 'frames_answered': len(player.received),
            'samples': [(round(float(t), 1), f, round(b / 2**20, 2)) for t, f, b in samples]}


def growth(samples_mb: np.ndarray, warmup: float) -> tuple[float, float, float]:
    """(RSS after the warm-up, RSS at the end, growth): medians of the first and last EDGE of
    the samples after the first ``warmup`` fraction."""
    measured = samples_mb[int(len(samples_mb) * warmup):]
    edge = max(1, int(len(measured) * EDGE))
    first, last = float(np.median(measured[:edge])), float(np.median(measured[-edge:]))
    return first, last, last / first - 1.0


def report(data: dict[str, Any]) -> str:
    rows = [[f"{data['hours_of_stamps']:g} h ({data['frames']:,} frames, a "
             f"{data['map_points']:,}-point map every second)",
             f"{data['wall_s'] / 60:.1f} min", data['frames_answered'],
             f"{data['rss_after_warmup_mb']:.1f}",
             f"{data['rss_final_mb']:.1f}", f"{100 * data['growth']:+.2f} %"]]
    return section(
        'Node memory', data['command'],
        '`hac_node` (its own process, config/hac.yaml) fed the room scene at 30 Hz stamp rate, '
        'faster than real time; its resident set size sampled every wall second. Growth: the '
        f'median RSS of the last {100 * EDGE:.0f} % of the samples over that of the first '
        f"{100 * EDGE:.0f} % after the warm-up (the first {100 * data['warmup']:.0f} % of the "
        f'run). Target: < {100 * TARGET_GROWTH:.0f} %. "frames answered": world joints received '
        'back.',
        table(['stamp time played', 'wall', 'frames answered', 'RSS after warm-up MB',
               'RSS at the end MB', 'growth'], rows),
        data['machine'])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--hours', type=float, default=1.0, help='stamp time played')
    parser.add_argument('--fps', type=float, default=300.0, help='frames per wall second')
    parser.add_argument('--map-points', type=int, default=100_000)
    parser.add_argument('--warmup', type=float, default=0.1,
                        help='fraction of the run not measured')
    args = parser.parse_args(argv)
    info = machine()
    data = run(args.hours, args.fps, args.map_points)
    after, final, grown = growth(np.array([s[2] for s in data['samples']]), args.warmup)
    data.update(machine=info, command=command_line(__file__, argv), warmup=args.warmup,
                rss_after_warmup_mb=after, rss_final_mb=final, growth=grown, checks=[check(
                    f"node RSS growth over {args.hours:g} h of stamps after warm-up",
                    f'{100 * grown:+.2f} %', f'< {100 * TARGET_GROWTH:.0f} %',
                    abs(grown) < TARGET_GROWTH)])
    markdown = report(data)
    publish(NAME, data, markdown)
    print(markdown)
    return 0 if data['exit_code'] == 0 else 1


if __name__ == '__main__':
    sys.exit(main())
