#!/usr/bin/env python3
"""Node memory: an accelerated hour through ``hac_node``; its resident size must stay flat.

    python bench/node_memory.py [--hours 1.0] [--fps 300] [--map-points 100000]

``hac_node`` runs in a subprocess with config/hac.yaml. This process plays ``--hours`` of stamp
time of the core benchmark's room scene (bench/core_speed.py ``room_scene``: a person walking a
circle, the camera following) at 30 Hz stamp rate but ``--fps`` frames per wall second: a SLAM
pose and the HMR joints per frame, and a ``--map-points`` map (pre-serialized once, its stamp
patched) every stamp second, as a SLAM system republishes its map. The node's resident set size
(VmRSS of /proc/<pid>/status) is sampled every wall second. Warm-up: the first ``--warmup``
fraction of the run (the rolling window, the camera-path marker and the ground-contact buffer
fill up; every buffer in the node is bounded). Growth = median RSS of the last 5 % of the samples
over the median of the first 5 % after the warm-up, minus 1. Target (issue 6): < 5 %.

Sets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a domain of its own (through node_latency).
Prints, writes bench/results/node_memory.json and the ``node_memory`` section of
docs/benchmarks.md.
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import node_latency as nl  # noqa: E402  (sets the DDS environment before rclpy is imported)

import argparse  # noqa: E402
import os  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402

from _report import machine, machine_line, table, write_json, write_section  # noqa: E402
from core_speed import room_scene  # noqa: E402
from msg_adapters import cdr_write, rt_to_pose_stamped, stamp_to_ns, xyz_to_cloud  # noqa: E402

NAME = 'node_memory'
STAMP_RATE_HZ = 30.0
TARGET_GROWTH = 0.05
EDGE = 0.05  # the share of samples averaged at each end of the measured part


def rss_bytes(pid: int) -> int:
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) * 1024
    raise RuntimeError(f'no VmRSS for process {pid}')


def run(hours: float, fps: float, map_points: int, warmup: float) -> dict[str, Any]:
    frames = int(round(hours * 3600.0 * STAMP_RATE_HZ))
    stamps, R, c, J, map_fn = room_scene(frames, STAMP_RATE_HZ)
    map_raw = bytearray(serialize_message(xyz_to_cloud(map_fn(map_points), 0, 'map', nl.TYPES)))

    rclpy.init()
    node = rclpy.create_node('hac_memory_bench')
    pose_pub = node.create_publisher(nl.TYPES.get('geometry_msgs/msg/PoseStamped'), '/slam/pose',
                                     nl.INPUT_QOS)
    joints_pub = node.create_publisher(nl.TYPES.get('geometry_msgs/msg/PoseArray'), '/hmr/joints',
                                       nl.INPUT_QOS)
    map_pub = node.create_publisher(nl.TYPES.get('sensor_msgs/msg/PointCloud2'), '/slam/cloud',
                                    nl.LATCHED)
    diagnostics: dict[str, str] = {}

    def on_diagnostics(msg: Any) -> None:
        diagnostics.update({kv.key: kv.value for kv in msg.status[0].values})
        diagnostics['_stamp_ns'] = str(stamp_to_ns(msg.header.stamp))

    node.create_subscription(nl.TYPES.get('diagnostic_msgs/msg/DiagnosticArray'), '/diagnostics',
                             on_diagnostics, nl.OUTPUT_QOS)
    env = {**os.environ, 'PYTHONUNBUFFERED': '1', 'RCUTILS_COLORIZED_OUTPUT': '0'}
    proc = subprocess.Popen([sys.executable, '-m', 'hac_ros.node', '--ros-args', '--params-file',
                             str(nl.REPO / 'config' / 'hac.yaml')], cwd=nl.REPO, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    samples: list[tuple[float, int, int]] = []  # (stamp seconds played, frame, RSS bytes)
    try:
        deadline = time.monotonic() + nl.STARTUP_S
        while not (pose_pub.get_subscription_count() and joints_pub.get_subscription_count()
                   and map_pub.get_subscription_count()):
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError('hac_node did not come up: ' + ' '.join(nl._stop(proc)[1:]))
            rclpy.spin_once(node, timeout_sec=0.05)
        pose = rt_to_pose_stamped(R[0], c[0], 0, 'map', nl.TYPES)
        start = time.perf_counter()
        next_sample = start
        next_map_ns = int(stamps[0])
        for i in range(frames):
            stamp = int(stamps[i])
            if stamp >= next_map_ns:
                nl.set_cdr_stamp(map_raw, stamp)
                map_pub.publish(bytes(map_raw))
                next_map_ns += 1_000_000_000
            pose = rt_to_pose_stamped(R[i], c[i], stamp, 'map', nl.TYPES)
            pose_pub.publish(pose)
            joints_pub.publish(cdr_write.pose_array(stamp, 'camera', J[i]))
            now = time.perf_counter()
            if now >= next_sample:
                samples.append(((stamp - stamps[0]) / 1e9, i, rss_bytes(proc.pid)))
                next_sample = now + 1.0
                rclpy.spin_once(node, timeout_sec=0.0)
            delay = start + (i + 1) / fps - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        wall = time.perf_counter() - start
        end = time.monotonic() + nl.DRAIN_S
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.1)
        samples.append(((int(stamps[-1]) - stamps[0]) / 1e9, frames, rss_bytes(proc.pid)))
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        code, _, err = nl._stop(proc)
    rss = np.array([s[2] for s in samples], dtype=float)
    measured = rss[int(len(rss) * warmup):]
    edge = max(1, int(len(measured) * EDGE))
    after_warmup = float(np.median(measured[:edge]))
    final = float(np.median(measured[-edge:]))
    growth = final / after_warmup - 1.0
    result = {
        'hours_of_stamps': hours, 'frames': frames, 'wall_s': wall, 'speed_x': hours * 3600 / wall,
        'map_points': map_points, 'maps': int(np.ceil(frames / STAMP_RATE_HZ)),
        'warmup_fraction': warmup,
        'rss_mb': {'start': float(rss[0]) / 2**20, 'after_warmup': after_warmup / 2**20,
                   'final': final / 2**20, 'max': float(rss.max()) / 2**20},
        'growth_after_warmup': growth, 'target_growth': TARGET_GROWTH,
        'node_frames': int(diagnostics.get('frames', 0)),
        'node_rejected': {k.split('.', 1)[1]: int(v) for k, v in diagnostics.items()
                          if k.startswith('rejected.')},
        'node_converged': diagnostics.get('converged'), 'node_scale': diagnostics.get('scale'),
        'node_exit_code': code,
        'samples': [(round(t, 1), f, round(b / 2**20, 2)) for t, f, b in samples],
    }
    if code != 0 or 'Traceback' in err:
        result['node_log_tail'] = err[-2000:]
    return result


def report(r: dict[str, Any], info: dict[str, Any]) -> str:
    mb = r['rss_mb']
    rows = [[f"{r['hours_of_stamps']:g} h ({r['frames']:,} frames, {r['maps']:,} maps of "
             f"{r['map_points']:,} points)", f"{r['wall_s'] / 60:.1f} min ({r['speed_x']:.0f}x)",
             r['node_frames'], f"{mb['start']:.0f}", f"{mb['after_warmup']:.1f}", f"{mb['final']:.1f}",
             f"{mb['max']:.1f}", f"{100 * r['growth_after_warmup']:+.2f} %",
             'yes' if abs(r['growth_after_warmup']) < r['target_growth'] else 'no']]
    return '\n'.join([
        '## Node memory (`bench/node_memory.py`)', '',
        'An accelerated run through `hac_node` (its own process, config/hac.yaml): 30 Hz stamps '
        'played faster than real time, SLAM pose + HMR joints per frame and a map every stamp '
        'second; the node\'s resident set size sampled every wall second. Growth: the median RSS '
        f"of the last {100 * EDGE:.0f} % of the samples over that of the first {100 * EDGE:.0f} % "
        f"after the warm-up (the first {100 * r['warmup_fraction']:.0f} % of the run). "
        f"Target (issue 6): < {100 * r['target_growth']:.0f} %. \"node frames\": frames the node "
        'processed, from its last /diagnostics.', '',
        table(['stamp time played', 'wall (speed-up)', 'node frames', 'RSS start MB',
               'RSS after warm-up MB', 'RSS final MB', 'RSS max MB', 'growth', '< 5 %'], rows), '',
        machine_line(info),
        'Re-run: `python bench/node_memory.py` (about 6 minutes at the default 300 frames/s).',
    ])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--hours', type=float, default=1.0, help='stamp time played')
    parser.add_argument('--fps', type=float, default=300.0, help='frames per wall second')
    parser.add_argument('--map-points', type=int, default=100_000)
    parser.add_argument('--warmup', type=float, default=0.1, help='fraction of the run not measured')
    args = parser.parse_args(argv)
    result = run(args.hours, args.fps, args.map_points, args.warmup)
    info = machine()
    write_json(NAME, {'machine': info, **result})
    markdown = report(result, info)
    write_section(NAME, markdown)
    print(markdown)
    return 0 if result['node_exit_code'] == 0 else 1


if __name__ == '__main__':
    sys.exit(main())
