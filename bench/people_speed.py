#!/usr/bin/env python3
"""hac_people_node's speed: images per second on one core, and its overhead over the bare model.

    python bench/people_speed.py [--images 20] [--rounds 3]

Two 640 x 480 images (bench/_people_scenes.py): one person (basketball1.png) and four people
standing side by side (``four_standing``), each with ``person_detector`` hog (the default) and
none. Per case, alternated ``--rounds`` times in one run:

- **bare**: this process, pinned to one core, calls the model (``PoseModel.detect``) on the image
  ``--images`` times: CPU seconds per image (and wall);
- **node**: ``hac_people_node`` as a process of its own (``num_threads 1``: pinned to one core),
  fed the same image ``--images`` times as ``sensor_msgs/Image`` over DDS, one at a time (each
  waits for its ``hmr/joints``, so nothing is dropped): the node process's CPU seconds per image
  (from /proc: receiving, decoding, the model, the lifting, publishing, its executor and
  /diagnostics).

Images per second = 1 / CPU seconds per image (what one core sustains). The ratio node / bare is
the node's overhead (target <= 1.3x; CPU time, so another process's load on the machine does not
enter it). Writes bench/results/people_speed.json and its section of docs/benchmarks.md.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _domain import claim_domain

claim_domain()  # before rclpy: LOCALHOST and a domain of 90..99 no other benchmark holds

import argparse
import signal
import subprocess
import time
from typing import Any

import numpy as np
from _people_scenes import four_standing, still
from _report import check, command_line, machine, publish, section, table

NAME = 'people_speed'
TARGET = 1.3
CASES = (('1 person', 'basketball1.png'), ('4 people', 'four_standing'))
DETECTORS = ('hog', 'none')
CLK_TCK = os.sysconf('SC_CLK_TCK')


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` (its threads included)."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def bare(model: Any, rgb: np.ndarray, n: int) -> tuple[float, float, int]:
    """(CPU s per image, wall s per image, people found) of n model calls in this process."""
    people = len(model.detect(rgb))  # warm
    cpu, wall = time.process_time(), time.perf_counter()
    for _ in range(n):
        model.detect(rgb)
    return (time.process_time() - cpu) / n, (time.perf_counter() - wall) / n, people


class NodeRun:
    """hac_people_node in a process of its own, and this process's publisher/subscriber."""

    def __init__(self, detector: str) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        from hac_ros.ros.spin_thread import SpinThread
        from msg_adapters import rclpy_types

        self.types = rclpy_types()
        self.process = subprocess.Popen(
            [sys.executable, '-m', 'hac_ros.ros.people_node', '--ros-args', '-p', 'num_threads:=1',
             '-p', 'max_rate_hz:=0.0', '-p', f'person_detector:={detector}'],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        rclpy.init()
        self.node = rclpy.create_node('hac_bench_camera')
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.image = self.node.create_publisher(self.types.get('sensor_msgs/msg/Image'),
                                                'camera/image_raw', reliable)
        self.info = self.node.create_publisher(self.types.get('sensor_msgs/msg/CameraInfo'),
                                               'camera/camera_info', reliable)
        self.answers: list[Any] = []
        self.node.create_subscription(self.types.get('geometry_msgs/msg/PoseArray'),
                                      'hmr/joints', self.answers.append, reliable)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.spinner = SpinThread(self.executor)
        deadline = time.monotonic() + 120
        while (self.image.get_subscription_count() == 0
               or self.node.count_publishers('hmr/joints') == 0):
            if time.monotonic() > deadline or self.process.poll() is not None:
                raise RuntimeError('hac_people_node did not come up')
            time.sleep(0.05)
        self.stamp = 1_000_000_000

    def feed(self, rgb: np.ndarray, n: int) -> tuple[float, int]:
        """(node CPU s per image, people per image) over n images, one at a time."""
        from msg_adapters import intrinsics_to_camera_info
        from msg_adapters.image import rgb_to_image

        height, width = rgb.shape[:2]
        K = np.array([[525.0, 0, width / 2], [0, 525.0, height / 2], [0, 0, 1]])

        def one(patience_s: float = 120.0) -> Any:
            self.stamp += 100_000_000
            self.info.publish(intrinsics_to_camera_info(K, width, height, self.stamp,
                                                        'camera_optical', self.types))
            before = len(self.answers)
            self.image.publish(rgb_to_image(rgb, self.stamp, 'camera_optical', self.types))
            deadline = time.monotonic() + patience_s
            while len(self.answers) == before:
                if time.monotonic() > deadline:
                    return None
                time.sleep(0.001)
            return self.answers[-1]
        # warm: until an image is answered (the first may come before its CameraInfo)
        deadline = time.monotonic() + 120
        while one(5.0) is None:
            if time.monotonic() > deadline:
                raise RuntimeError('hac_people_node did not answer')
        one()
        start = cpu_seconds(self.process.pid)
        answers = [one() for _ in range(n)]
        if any(a is None for a in answers):
            raise RuntimeError('hac_people_node did not answer an image')
        people = [len(a.poses) // 33 for a in answers]
        return (cpu_seconds(self.process.pid) - start) / n, int(np.median(people))

    def close(self) -> None:
        import rclpy

        self.spinner.close()
        self.node.destroy_node()
        rclpy.try_shutdown()
        os.killpg(self.process.pid, signal.SIGINT)
        self.process.wait(timeout=60)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--images', type=int, default=20)
    parser.add_argument('--rounds', type=int, default=3)
    parser.add_argument('--no-write', action='store_true')
    args = parser.parse_args(argv)
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # bare: one core
    from hac_ros.people.model import PoseModel

    images = {'basketball1.png': still('basketball1.png'), 'four_standing': four_standing()}
    rows, results, checks = [], [], []
    for detector in DETECTORS:
        model = PoseModel(person_detector=detector)
        run = NodeRun(detector)
        try:
            for label, image in CASES:
                rgb = images[image]
                ratios, bare_cpu, node_cpu, walls = [], [], [], []
                for _ in range(args.rounds):
                    cpu, wall, found = bare(model, rgb, args.images)
                    node, people = run.feed(rgb, args.images)
                    bare_cpu.append(cpu)
                    node_cpu.append(node)
                    walls.append(wall)
                    ratios.append(node / cpu)
                ratio = float(np.median(ratios))
                result = {'case': label, 'detector': detector, 'people_found': found,
                          'people_published': people, 'bare_cpu_ms': 1e3 * float(np.median(bare_cpu)),
                          'bare_wall_ms': 1e3 * float(np.median(walls)),
                          'node_cpu_ms': 1e3 * float(np.median(node_cpu)), 'ratio': ratio,
                          'ratios': ratios}
                results.append(result)
                print(result, flush=True)
                rows.append([label, detector, found, people,
                             f"{1e3 / result['bare_cpu_ms']:.1f}",
                             f"{1e3 / result['node_cpu_ms']:.1f}", f"{result['bare_cpu_ms']:.1f}",
                             f"{result['bare_wall_ms']:.1f}", f"{result['node_cpu_ms']:.1f}",
                             f'{ratio:.2f}x'])
                checks.append(check(f'people node CPU per image vs bare model ({label}, '
                                    f'{detector})', f'{ratio:.2f}x', f'<= {TARGET}x',
                                    ratio <= TARGET))
        finally:
            run.close()
            model.close()
    info = machine()
    body = table(['image (640 x 480)', 'person_detector', 'people found', 'published',
                  'bare images/s', 'node images/s', 'bare CPU ms', 'bare wall ms',
                  'node CPU ms', 'node / bare'], rows)
    what = ('One core (the bench process and the node each pinned to one). Bare: '
            '`PoseModel.detect` in a loop; node: `hac_people_node` fed the same image over DDS '
            'one at a time, its process\'s CPU time per image (receive, decode, model, lifting, '
            'publish). Images/s = 1 / CPU seconds per image. Median of '
            f'{args.rounds} alternated rounds of {args.images} images. Target: node / bare <= '
            f'{TARGET}x. The wall ms are the host\'s raw data (other users load it).')
    markdown = section('People node speed (`bench/people_speed.py`)', command_line(__file__, argv),
                       what, body, info)
    data = {'machine': info, 'results': results, 'checks': checks}
    if not args.no_write:
        publish(NAME, data, markdown)
    print(markdown)
    return 0 if all(c['met'] for c in checks) else 1


if __name__ == '__main__':
    sys.exit(main())
