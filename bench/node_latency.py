#!/usr/bin/env python3
"""Node latency: joints in → world joints out over DDS, with a large map republished at 1 Hz.

    python bench/node_latency.py [--map-points 100000] [--duration 20] [--publishers one|split]

``hac_node`` runs in a subprocess with the installed defaults (config/hac.yaml: best-effort
pose/joints, transient-local map, markers on). This process plays the simulator's ``walk`` live at
30 Hz (SLAM pose, then the HMR joints of the same stamp, stamped with the wall clock) and
republishes a map of N points every second (the walk's map resampled to N points, pre-serialized
once, its stamp patched into the CDR bytes). With ``--publishers split`` the joints come from a
process of their own (bench/hmr_publisher.py), as from an HMR model beside the SLAM system: this
process then plays the SLAM side (poses and map). Measured after a warm-up:

- latency: from just before a joints message is published to the arrival of the
  ``/hac/human_joints`` of the same stamp (p50, p99, max), both ends in this process: in the
  subscription's callback (a raw subscription: the stamp is read from the CDR bytes, so this
  process does not deserialize 24 poses into Python objects before it reads the clock), and, beside
  it, at this process's DDS reader (rmw's ``received_timestamp``: before this process's executor
  dispatches the message);
- frames dropped: joints published without world joints back (and the node's own counts of
  rejected frames, from /diagnostics);
- the node's CPU share (user + system time of the node process from /proc/<pid>/stat over the
  measurement, in % of one core);
- map ingestion on the node's builder thread, measured here on the same bytes: the CDR header
  (parse_cloud_cdr), rclpy's deserialize_message for comparison, the point decoding and the index.

Sets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a domain of its own. Prints a table, merges the
run into bench/results/node_latency.json (one entry per map size) and writes the
``node_latency`` section of docs/benchmarks.md.
"""
from __future__ import annotations

import os

# before rclpy is imported: DDS stays on this machine, on a domain no test or user shares
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('ROS_STATIC_PEERS', None)
os.environ['ROS_DOMAIN_ID'] = str(10 + (os.getpid() + 45) % 90)

import argparse  # noqa: E402
import json  # noqa: E402
import signal  # noqa: E402
import struct  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import RESULTS, machine, machine_line, run_machine, table, write_json, write_section  # noqa: E402

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402

from hac_ros.core.calibrator import Calibrator  # noqa: E402
from hac_ros.core.params import HacParams  # noqa: E402
from hac_ros.node import DDS_PROFILE_VARIABLES  # noqa: E402
from msg_adapters.cdr import cloud_points, parse_cloud_cdr  # noqa: E402
from hac_ros.simulate import make_scenario  # noqa: E402
from hac_ros.spin_thread import SpinThread  # noqa: E402
from msg_adapters import (joints_to_pose_array, rclpy_types, rt_to_pose_stamped,  # noqa: E402
                          xyz_to_cloud)

REPO = Path(__file__).resolve().parents[1]
NAME = 'node_latency'
RATE_HZ = 30.0  # camera rate: one SLAM pose and one joints message per frame
MAP_PERIOD_S = 1.0  # map republished at 1 Hz
WARMUP_S = 4.0  # first map, convergence (min_samples frames) and DDS warm-up: not measured
DRAIN_S = 2.0  # after the last frame: wait for the last outputs
STARTUP_S = 30.0
NEAR_MAP_S = 0.3  # a frame sent within this long after a map publish is "near a map"
TAKE_SETTLE_S = 0.3  # a published map is in the subscriber's queue after this long
SPLIT_LEAD_S = 0.5  # split publishers: the first frame is due this long after the plan is sent
HMR_DELAY_S = 0.002  # split publishers: the joints follow the pose of their stamp by this long
MAP_JITTER_REL = 1e-3  # resampled map points move by this fraction of the map's extent
TYPES = rclpy_types()
CLK_TCK = os.sysconf('SC_CLK_TCK')
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
OUTPUT_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
INPUT_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def resample_map(points_map: np.ndarray, count: int, seed: int = 0) -> np.ndarray:
    """``count`` points on the same surfaces: a subset, or copies jittered by MAP_JITTER_REL."""
    rng = np.random.default_rng(seed)
    if count <= len(points_map):
        return points_map[rng.choice(len(points_map), count, replace=False)]
    extent = float(np.linalg.norm(np.ptp(points_map, axis=0)))
    picks = points_map[rng.integers(0, len(points_map), count - len(points_map))]
    jitter = rng.normal(scale=MAP_JITTER_REL * extent, size=picks.shape)
    return np.vstack([points_map, picks + jitter])


def set_cdr_stamp(raw: bytearray, stamp_ns: int) -> None:
    """Patch header.stamp (the first 8 payload bytes of a little-endian CDR message)."""
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    struct.pack_into('<iI', raw, 4, sec, nanosec)


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (fields 14 and 15 of /proc/<pid>/stat)."""
    stat = Path(f'/proc/{pid}/stat').read_text()
    fields = stat[stat.rindex(')') + 2:].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def ingest_costs(raw: bytes, repeats: int = 5) -> dict[str, float]:
    """What the node does with one map message, timed here on the same bytes (ms, median of n)."""
    calibrator = Calibrator(HacParams())
    times: dict[str, list[float]] = {}

    def timed(key: str, fn: Any) -> Any:
        start = time.perf_counter()
        value = fn()
        times.setdefault(key, []).append((time.perf_counter() - start) * 1e3)
        return value

    for _ in range(repeats):
        cloud = timed('cdr_header_ms', lambda: parse_cloud_cdr(raw))
        timed('deserialize_message_ms',
              lambda: deserialize_message(raw, TYPES.get('sensor_msgs/msg/PointCloud2')))
        points = timed('decode_points_ms', lambda: cloud_points(cloud))
        timed('index_build_ms', lambda: calibrator.build_index(cloud.stamp_ns, points,
                                                               cloud.frame_id))
    return {key: float(np.median(values)) for key, values in times.items()}


def executor_take_costs(raw: bytes, repeats: int = 5) -> dict[str, float]:
    """Executor time to take one map message (ms, median): raw bytes vs a deserialized message.

    What each kind of subscription costs the executor's thread before any callback work: the
    node's raw subscription copies the serialized bytes; a typed one deserializes them.
    """
    cloud_type = TYPES.get('sensor_msgs/msg/PointCloud2')
    qos = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE)
    node = rclpy.create_node('hac_latency_take')
    publisher = node.create_publisher(cloud_type, '/hac_bench/take', qos)
    costs: dict[str, float] = {}
    for raw_subscription in (True, False):
        received: list[int] = []
        subscription = node.create_subscription(cloud_type, '/hac_bench/take',
                                                lambda _: received.append(1), qos,
                                                raw=raw_subscription)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        deadline = time.monotonic() + 10.0
        while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        times = []
        for _ in range(repeats):
            count = len(received)
            publisher.publish(raw)
            time.sleep(TAKE_SETTLE_S)  # delivered into the subscription's queue, not yet taken
            start = time.perf_counter()
            executor.spin_once(timeout_sec=1.0)
            times.append((time.perf_counter() - start) * 1e3)
            if len(received) != count + 1:
                raise RuntimeError('the map message was not taken in one spin')
        costs['take_raw_ms' if raw_subscription else 'take_deserialized_ms'] = float(
            np.median(times))
        executor.remove_node(node)
        executor.shutdown()
        node.destroy_subscription(subscription)
    node.destroy_node()
    return costs


class Bench:
    """The playing and recording side, in this process."""

    def __init__(self, scenario: Any, map_raw: bytearray, split: bool = False) -> None:
        rclpy.init()
        self.node = rclpy.create_node('hac_latency_bench')
        self.pose_pub = self.node.create_publisher(TYPES.get('geometry_msgs/msg/PoseStamped'),
                                                   '/slam/pose', INPUT_QOS)
        # split: the joints come from a process of their own (bench/hmr_publisher.py)
        self.joints_pub = None if split else self.node.create_publisher(
            TYPES.get('geometry_msgs/msg/PoseArray'), '/hmr/joints', INPUT_QOS)
        self.map_pub = self.node.create_publisher(TYPES.get('sensor_msgs/msg/PointCloud2'),
                                                  '/slam/cloud', LATCHED)
        self.sent: dict[int, int] = {}  # joints stamp -> perf_counter_ns just before publishing
        self.sent_wall: dict[int, int] = {}  # joints stamp -> time_ns just before publishing
        self.received: dict[int, int] = {}  # joints stamp -> perf_counter_ns in the callback
        # joints stamp -> time_ns at which this process's DDS reader received the world joints
        # (rmw's received_timestamp: before this process's executor dispatched it)
        self.received_dds: dict[int, int] = {}
        self.diagnostics: dict[str, str] = {}
        self.node.create_subscription(TYPES.get('geometry_msgs/msg/PoseArray'), '/hac/human_joints',
                                      self._on_joints, OUTPUT_QOS, raw=True)
        self.node.create_subscription(TYPES.get('diagnostic_msgs/msg/DiagnosticArray'),
                                      '/diagnostics', self._on_diagnostics, OUTPUT_QOS)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.spinner = SpinThread(self.executor, 'hac_latency_spin')
        self.scenario = scenario
        self.map_raw = map_raw
        self.map_frame = scenario.slam_frame_ids[0]
        self.stop = threading.Event()
        self.maps_sent = 0
        self.map_times: list[int] = []  # perf_counter_ns just before each map publish

    def _on_joints(self, data: bytes, info: dict[str, Any]) -> None:
        now = time.perf_counter_ns()
        sec, nanosec = struct.unpack_from('<iI', data, 4)  # header.stamp, first in the payload
        stamp = sec * 1_000_000_000 + nanosec
        self.received.setdefault(stamp, now)
        self.received_dds.setdefault(stamp, info['received_timestamp'])

    def _on_diagnostics(self, msg: Any) -> None:
        self.diagnostics = {kv.key: kv.value for kv in msg.status[0].values}

    def node_is_up(self) -> bool:
        return (self.pose_pub.get_subscription_count() > 0 and
                (self.joints_pub is None or self.joints_pub.get_subscription_count() > 0) and
                self.map_pub.get_subscription_count() > 0 and
                self.node.count_publishers('/hac/human_joints') > 0)

    def publish_map(self) -> None:
        set_cdr_stamp(self.map_raw, time.time_ns())
        self.map_times.append(time.perf_counter_ns())
        self.map_pub.publish(bytes(self.map_raw))
        self.maps_sent += 1

    def map_loop(self) -> None:
        while not self.stop.wait(MAP_PERIOD_S):
            self.publish_map()

    def frame_count(self, seconds: float) -> int:
        sc = self.scenario
        return min(len(sc.pose_stamps_ns), len(sc.joints_stamps_ns), int(seconds * RATE_HZ))

    def pose_messages(self, frames: int) -> list[Any]:
        """The first ``frames`` SLAM poses as PoseStamped messages (stamps set when published)."""
        sc = self.scenario
        return [rt_to_pose_stamped(sc.slam_R_wc[i], sc.slam_c[i], 0, self.map_frame, TYPES)
                for i in range(frames)]

    def play(self, seconds: float) -> None:
        """Frames at RATE_HZ for ``seconds`` of wall time, poses and joints from this process."""
        sc = self.scenario
        frames = self.frame_count(seconds)
        poses = self.pose_messages(frames)
        joints = [joints_to_pose_array(np.asarray(sc.joints_cam[i]), 0, sc.camera_frame, TYPES)
                  for i in range(frames)]
        start = time.perf_counter()
        for i in range(frames):
            delay = start + i / RATE_HZ - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            sec, nanosec = divmod(time.time_ns(), 1_000_000_000)
            for msg in (poses[i], joints[i]):
                msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
            self.pose_pub.publish(poses[i])
            stamp = sec * 1_000_000_000 + nanosec
            self.sent_wall[stamp] = time.time_ns()
            self.sent[stamp] = time.perf_counter_ns()
            self.joints_pub.publish(joints[i])

    def play_split(self, seconds: float, hmr: subprocess.Popen) -> None:
        """The SLAM side of a split run: poses at RATE_HZ, the joints of the same stamps from
        ``hmr`` (bench/hmr_publisher.py, ready), HMR_DELAY_S after each pose; the joints' publish
        instants are read back from it into ``sent`` and ``sent_wall``."""
        frames = self.frame_count(seconds)
        poses = self.pose_messages(frames)
        period = int(round(1e9 / RATE_HZ))
        start_perf = time.perf_counter_ns() + int(SPLIT_LEAD_S * 1e9)
        start_stamp = time.time_ns() + int(SPLIT_LEAD_S * 1e9)
        plan = {'start_perf_ns': start_perf, 'start_stamp_ns': start_stamp, 'period_ns': period,
                'delay_ns': int(HMR_DELAY_S * 1e9), 'frames': frames}
        hmr.stdin.write(json.dumps(plan) + '\n')
        hmr.stdin.flush()
        for i in range(frames):
            delay = (start_perf + i * period - time.perf_counter_ns()) / 1e9
            if delay > 0:
                time.sleep(delay)
            msg = poses[i]
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(start_stamp + i * period,
                                                                    1_000_000_000)
            self.pose_pub.publish(msg)
        line = hmr.stdout.readline()
        if not line:
            raise RuntimeError('the HMR publisher ended without its report')
        for stamp, perf_ns, wall_ns in json.loads(line)['sent']:
            self.sent[stamp] = perf_ns
            self.sent_wall[stamp] = wall_ns

    def close(self) -> None:
        self.stop.set()
        self.spinner.close()
        self.node.destroy_node()
        rclpy.try_shutdown()


# The floor: a node that only echoes each joints message's bytes to /hac/human_joints (raw
# subscriptions, QoS as hac_node's defaults). Its latency is what rclpy and DDS cost on this machine.
ECHO_NODE = """
import sys
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, DurabilityPolicy
from geometry_msgs.msg import PoseArray, PoseStamped
from sensor_msgs.msg import PointCloud2
sys.setswitchinterval(0.0005)
rclpy.init()
node = rclpy.create_node('hac_echo')
best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
latched = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
out = node.create_publisher(PoseArray, '/hac/human_joints', 100)
node.create_subscription(PoseArray, '/hmr/joints', out.publish, best_effort, raw=True)
node.create_subscription(PoseStamped, '/slam/pose', lambda data: None, best_effort, raw=True)
node.create_subscription(PointCloud2, '/slam/cloud', lambda data: None, latched, raw=True)
try:
    rclpy.spin(node)
except KeyboardInterrupt:
    pass
"""


def run(map_points: int, duration: float, echo: bool = False,
        input_qos: str = 'best_effort', split: bool = False) -> dict[str, Any]:
    total = WARMUP_S + duration
    sc = make_scenario('walk', seed=0, duration=total + 1.0, hmr_bias=0.0)
    base_map = max(sc.maps, key=lambda m: len(m.points_slam))
    points = resample_map(np.asarray(base_map.points_slam, dtype=float), map_points)
    map_raw = bytearray(serialize_message(xyz_to_cloud(points, 0, base_map.frame_id, TYPES)))
    costs = ingest_costs(bytes(map_raw))
    bench = Bench(sc, map_raw, split)
    costs.update(executor_take_costs(bytes(map_raw)))

    params = REPO / 'config' / 'hac.yaml'
    env = {**os.environ, 'PYTHONUNBUFFERED': '1', 'RCUTILS_COLORIZED_OUTPUT': '0'}
    command = ([sys.executable, '-c', ECHO_NODE] if echo else
               [sys.executable, '-m', 'hac_ros.node', '--ros-args', '--params-file', str(params),
                '-p', f'input_qos:={input_qos}'])
    node = subprocess.Popen(command, cwd=REPO, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    hmr = None
    scratch = tempfile.TemporaryDirectory(prefix='hac_latency_')
    try:
        deadline = time.monotonic() + STARTUP_S
        while not bench.node_is_up():
            if time.monotonic() > deadline or node.poll() is not None:
                raise RuntimeError('hac_node did not come up: ' + ' '.join(_stop(node)[1:]))
            time.sleep(0.05)
        if split:
            joints_file = Path(scratch.name) / 'joints.npy'
            np.save(joints_file, np.stack([np.asarray(j, dtype=float) for j in
                                           sc.joints_cam[:bench.frame_count(total)]]))
            hmr = subprocess.Popen([sys.executable, str(REPO / 'bench' / 'hmr_publisher.py'),
                                    str(joints_file), sc.camera_frame], cwd=REPO, env=env,
                                   stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
            if json.loads(hmr.stdout.readline() or '{}').get('ready') is not True:
                raise RuntimeError('the HMR publisher did not match the node\'s subscription')
        bench.publish_map()
        mapper = threading.Thread(target=bench.map_loop, daemon=True)
        mapper.start()
        t_cpu0 = w_cpu0 = None
        measure_from = [0]

        def start_measuring() -> None:
            nonlocal t_cpu0, w_cpu0
            measure_from[0] = time.perf_counter_ns()
            t_cpu0, w_cpu0 = cpu_seconds(node.pid), time.perf_counter()

        timer = threading.Timer(WARMUP_S + (SPLIT_LEAD_S if split else 0.0), start_measuring)
        timer.start()
        own0 = time.process_time()
        if split:
            bench.play_split(total, hmr)
        else:
            bench.play(total)
        node_cpu = cpu_seconds(node.pid) - t_cpu0
        wall = time.perf_counter() - w_cpu0
        own_cpu = (time.process_time() - own0) / total
        time.sleep(DRAIN_S)
    finally:
        bench.close()
        code, out, err = _stop(node)
        if hmr is not None:
            _stop(hmr)
        scratch.cleanup()
    measured = {s: t for s, t in bench.sent.items() if t >= measure_from[0]}
    answered = [(s, t) for s, t in measured.items() if s in bench.received]
    latencies = np.array([(bench.received[s] - t) / 1e6 for s, t in answered])
    at_reader = np.array([(bench.received_dds[s] - bench.sent_wall[s]) / 1e6 for s, _ in answered])
    # frames sent while a map is in flight or being ingested vs the others
    map_times = np.array(bench.map_times, dtype=np.int64)
    since_map = np.array([(t - map_times[np.searchsorted(map_times, t) - 1]) / 1e9
                          if np.searchsorted(map_times, t) else np.inf for _, t in answered])
    near_map = since_map < NEAR_MAP_S
    rejected = {k.split('.', 1)[1]: int(v) for k, v in bench.diagnostics.items()
                if k.startswith('rejected.')}
    result = {
        'node': 'echo (the rclpy + DDS floor)' if echo else 'hac_node',
        'publishers': 'split' if split else 'one',
        'map_points': map_points, 'duration_s': duration, 'rate_hz': RATE_HZ,
        'frames_sent': len(measured), 'frames_answered': int(latencies.size),
        'frames_dropped': len(measured) - int(latencies.size),
        'dropped_at_s': [round((t - measure_from[0]) / 1e9, 3) for s, t in measured.items()
                         if s not in bench.received],
        'latency_ms': {'p50': _pct(latencies, 50), 'p90': _pct(latencies, 90),
                       'p99': _pct(latencies, 99),
                       'max': float(latencies.max()) if latencies.size else float('nan'),
                       'p99_near_map': _pct(latencies[near_map], 99),
                       'p99_away_from_map': _pct(latencies[~near_map], 99),
                       'frames_near_map': int(near_map.sum())},
        'latency_at_reader_ms': {'p50': _pct(at_reader, 50), 'p90': _pct(at_reader, 90),
                                 'p99': _pct(at_reader, 99),
                                 'max': float(at_reader.max()) if at_reader.size else float('nan')},
        'node_cpu_percent_of_one_core': 100.0 * node_cpu / wall,
        'bench_cpu_percent_of_one_core': 100.0 * own_cpu,
        'maps_sent': bench.maps_sent,
        'node_rejected': rejected,
        'node_map_points_indexed': int(bench.diagnostics.get('map_points', 0)),
        'node_exit_code': code,
        'ingest_ms': costs,
    }
    if code != 0 or 'Traceback' in err:
        result['node_log_tail'] = err[-2000:]
    return result


def _pct(values: np.ndarray, q: float) -> float:
    return float(np.percentile(values, q)) if values.size else float('nan')


def _stop(node: subprocess.Popen) -> tuple[int | None, str, str]:
    if node.poll() is None:
        node.send_signal(signal.SIGINT)
    try:
        out, err = node.communicate(timeout=10.0)
    except subprocess.TimeoutExpired:
        node.kill()
        out, err = node.communicate()
    return node.returncode, out, err


def report(runs: dict[str, dict[str, Any]], info: dict[str, Any]) -> str:
    rows = []
    for key in sorted(runs, key=lambda k: (k.startswith('echo'), runs[k]['map_points'], k)):
        r = runs[key]
        lat, ing = r['latency_ms'], r['ingest_ms']
        reader = r.get('latency_at_reader_ms', {})
        rows.append([r.get('node', 'hac_node'), r.get('publishers', 'one'),
                     r.get('input_qos', 'best_effort'), r.get('dds_profile') or 'built-in',
                     f"{r['map_points']:,}", f"{r['duration_s']:.0f}",
                     r['frames_sent'],
                     r['frames_dropped'], lat['p50'], lat['p99'], lat['max'],
                     reader.get('p50', '—'), reader.get('p99', '—'),
                     lat['p99_near_map'], lat['p99_away_from_map'],
                     r['node_cpu_percent_of_one_core'],
                     ing['decode_points_ms'], ing['index_build_ms'],
                     ing['take_raw_ms'] + ing['cdr_header_ms'], ing['take_deserialized_ms'],
                     ing['deserialize_message_ms'], run_machine(r.get('machine', {}))])
    headers = ['node', 'publishers', 'input_qos', 'DDS transports', 'map points', 'seconds',
               'frames', 'dropped', 'p50 ms', 'p99 ms', 'max ms', 'at the reader: p50 ms', 'p99 ms',
               f'p99 ms, < {NEAR_MAP_S:g} s after a map', 'p99 ms, other frames',
               'node CPU % of a core', 'builder: decode ms', 'builder: thin+index ms',
               'executor: raw take + header ms', 'executor: typed take ms (not used)',
               'deserialize_message ms (not used)', 'machine, commit']
    return '\n'.join([
        '## Node latency (`bench/node_latency.py`)', '',
        f'`hac_node` in its own process with config/hac.yaml; joints → `/hac/human_joints` latency '
        f'over DDS (localhost) at {RATE_HZ:.0f} Hz, the map republished every '
        f'{MAP_PERIOD_S:.0f} s; the first {WARMUP_S:.0f} s are not measured. Latency from just '
        'before the joints are published to the benchmark\'s callback for the world joints of the '
        'same stamp (a raw subscription: the stamp is read from the CDR bytes; the rows without an '
        '"at the reader" figure took a typed message, whose deserialization into 24 Python poses '
        'was counted too), and "at the reader": to '
        'the benchmark\'s DDS reader (rmw\'s received_timestamp, before its executor dispatches '
        'the message). "dropped" = joints '
        'sent without world joints back (best-effort input: a frame lost in transport counts). '
        'Map ingestion, timed in the benchmark process on the same bytes (median of 5): the '
        'executor thread only takes the raw message and reads its header; the builder thread '
        'decodes the points and thins and indexes them (`index_max_points`). For comparison, '
        'what a typed subscription would cost the executor (rclpy deserializes while taking) '
        'and `rclpy.serialization.deserialize_message` on the same bytes. The "echo" rows replace '
        'hac_node by a node that only republishes each joints message\'s bytes (raw '
        'subscriptions, same QoS): the latency rclpy and DDS alone cost on this machine, measured '
        'the same way. "publishers": `one` = this process publishes the map, the poses and the '
        'joints (as a bridge replaying every input would, or a SLAM node that also publishes the '
        'joints); `split` = the joints come from a process of their own (bench/hmr_publisher.py), '
        'stamped as the pose of the same image and published '
        f'{HMR_DELAY_S * 1e3:g} ms after it, as an HMR model beside a SLAM system.', '',
        table(headers, rows), '',
        'Rows keep their own run\'s machine: each command replaces only its row. The last run\'s:',
        machine_line(info),
        'Re-run: `python bench/node_latency.py --map-points 100000 --duration 60` and '
        '`--map-points 1000000 --duration 60` (add `--echo` for the floor, `--input-qos reliable` '
        'for reliable joints delivery, `--publishers split` for the joints from a process of '
        'their own, `--dds-profile config/fastdds_large_data.xml` for the Fast '
        'DDS profile with a 64 MiB shared-memory segment, docs/node.md).',
    ])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--map-points', type=int, default=100_000)
    parser.add_argument('--duration', type=float, default=20.0, help='measured seconds')
    parser.add_argument('--echo', action='store_true',
                        help='measure a node that only echoes the joints (the rclpy + DDS floor)')
    parser.add_argument('--input-qos', choices=('best_effort', 'reliable'), default='best_effort',
                        help="hac_node's input_qos (config/hac.yaml: best_effort); the benchmark "
                        'publishes reliably, so reliable makes the joints delivery reliable')
    parser.add_argument('--publishers', choices=('one', 'split'), default='one',
                        help='one: this process publishes the map, the poses and the joints; '
                        'split: the joints come from a process of their own '
                        '(bench/hmr_publisher.py), as from an HMR model beside a SLAM system')
    parser.add_argument('--dds-profile', metavar='XML',
                        help='a Fast DDS profile loaded by this process and the node (e.g. '
                        'config/fastdds_large_data.xml); default: the built-in transports')
    args = parser.parse_args(argv)
    if args.dds_profile:  # read once per process, when rclpy starts; the node inherits it
        profile = str(Path(args.dds_profile).resolve(strict=True))
        os.environ.update(dict.fromkeys(DDS_PROFILE_VARIABLES, profile))
    info = machine()  # before the run: its speed reference must not overlap the measurement
    result = run(args.map_points, args.duration, args.echo, args.input_qos,
                 args.publishers == 'split')
    result['input_qos'] = args.input_qos
    result['dds_profile'] = Path(args.dds_profile).name if args.dds_profile else ''
    result['machine'] = info
    path = RESULTS / f'{NAME}.json'
    previous = json.loads(path.read_text()) if path.exists() else {}
    # runs recorded before runs named their machine: the last one's, their commit that or older
    old = previous.get('machine', {})
    for kept in previous.get('runs', {}).values():
        kept.setdefault('machine', {**old, 'commit': f"<= {old.get('commit', '?')}"})
    key = f'echo_{args.map_points}' if args.echo else str(args.map_points)
    if args.input_qos != 'best_effort' and not args.echo:
        key += f'_{args.input_qos}'
    if args.dds_profile:
        key += '_' + Path(args.dds_profile).stem
    if args.publishers == 'split':
        key += '_split'
    runs = {**previous.get('runs', {}), key: result}
    write_json(NAME, {'machine': info, 'runs': runs})
    markdown = report(runs, info)
    write_section(NAME, markdown)
    print(json.dumps(result, indent=2, default=float))
    print(markdown)
    return 0 if result['node_exit_code'] == 0 else 1


if __name__ == '__main__':
    sys.exit(main())
