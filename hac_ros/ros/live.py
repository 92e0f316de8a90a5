"""``hac demo --live``: ``hac_node`` fed a recording by ``hac play``, judged by what comes back.

:func:`live_run` starts ``hac_node`` as a process of its own (as a user runs it), waits until its
inputs and outputs are connected over DDS, plays the recording into it with
:class:`~hac_ros.ros.player.Player`, records every output that comes back, stops the node with
SIGINT and returns a :class:`LiveSummary`: the summary ``hac replay --mode online`` prints, made
from ``/diagnostics`` (the estimator's counts, at most one second of stamp time behind the end)
and ``/hac/scale`` (the final scale).

Every participant stays on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``), in the
domain of ``ROS_DOMAIN_ID`` when it is set, else in one of its own; the domain is reported.
"""
from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hac_ros.bridge.topics import DIAGNOSTICS, NODE_TOPICS, SCALE
from hac_ros.core.basics.errors import HacError
from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import Status
from hac_ros.core.rules.params import NODE_NAME
from hac_ros.core.rules.status_shares import StatusShares
from hac_ros.files.params_file import check_params_file
from hac_ros.ros.liveness import STEADY_CLOCK_REASONS

log = logging.getLogger(__name__)

# what comes back: every output topic of the node (hac_ros.bridge.topics)
OUTPUTS = {topic.rooted: topic for topic in NODE_TOPICS}
STARTUP_S = 60.0  # the node imports numpy/scipy/rclpy and joins discovery (a loaded machine)
QUIET_S = 2.0  # after the play, the outputs have settled when nothing came for this long
SETTLE_MAX_S = 60.0
EXIT_S = 10.0
POLL_S = 0.05


@dataclass
class LiveSummary:
    """What came back from the node: the last status (from /diagnostics, its ``scale`` the last
    /hac/scale, metres per SLAM unit), messages received per output topic, the messages played,
    the wall time, the domain, and the node's log."""

    input_path: Path
    status: Status
    received: dict[str, int]
    played: int
    wall_s: float
    domain_id: int
    status_stamp_ns: int = -1
    start_ns: int = 0
    node_log: str = field(default='', repr=False)
    statuses: StatusShares = field(default_factory=StatusShares)  # the stamp-time /diagnostics

    def text(self) -> str:
        s = self.status
        behind = ''
        if self.status_stamp_ns >= 0:
            behind = f' (counts as of t+{(self.status_stamp_ns - self.start_ns) / NS:.3f} s)'
        rejected = ', '.join(f'{k} {v}' for k, v in sorted(s.rejected.items())) or 'none'
        received = ', '.join(f'{t} {n}' for t, n in sorted(self.received.items())) or 'nothing'
        return '\n'.join([
            f'hac demo (live): {self.input_path} -> hac_node over DDS (ROS_DOMAIN_ID '
            f'{self.domain_id}, localhost)',
            f'  frames {s.frames}, people {s.people}, input messages {self.played}{behind}',
            f'  final scale {s.scale:.6g} m/SLAM unit, spread {s.spread:.3g} (the last /hac/scale)',
            f'  statuses ({self.statuses.total} /diagnostics, one per second): '
            f'{self.statuses.text()}',
            f'  estimator at the end: {s.samples} samples in the window, '
            f'{"converged" if s.converged else "not converged"}, status '
            f'{self.statuses.last_text()}',
            f'  fallback rate {100 * s.fallback_rate:.1f} % (map hits {s.map_hits}, ground plane '
            f'{s.ground_fallbacks})',
            f'  rejected: {rejected}',
            f'  resets {s.resets}',
            f'  received: {received}',
            f'  wall time {self.wall_s:.2f} s'])


def status_from_diagnostics(values: dict[str, str], stamp_ns: int) -> Status:
    """The node's :class:`Status` from the key-values of its /diagnostics status."""
    def number(key: str, default: float = float('nan')) -> float:
        try:
            return float(values[key])
        except (KeyError, ValueError):
            return default

    def count(key: str) -> int:
        return int(number(key, 0.0))

    rejected = {k.split('.', 1)[1]: int(v) for k, v in values.items()
                if k.startswith('rejected.') and v.isdigit()}
    return Status(stamp_ns=stamp_ns, converged=values.get('converged') == 'true',
                  scale=number('scale'), spread=number('spread'), samples=count('samples'),
                  frames=count('frames'), people=count('people'), map_hits=count('map_hits'),
                  ground_fallbacks=count('ground_fallbacks'), resets=count('resets'),
                  rejected=rejected, map_points=count('map_points'),
                  spread_stat=number('spread_stat'), publishing=values.get('publishing') == 'true')


def stamp_time_status(msg: Any) -> bool:
    """Whether a /diagnostics message is one of the node's stamp-time statuses, not the last one
    republished by its steady-clock timer when no input or no status came (reasons ``no_input``,
    ``no_status``; stamped with the node's clock, not in the recording's time: docs/node.md,
    "Diagnostics")."""
    if not msg.status:
        return False
    values = {kv.key: kv.value for kv in msg.status[0].values}
    return not set(values.get('reasons', '').split(',')) & set(STEADY_CLOCK_REASONS)


def level_and_reasons(msg: Any) -> tuple[int, list[str]]:
    """The level and the ``reasons`` of a /diagnostics message's (first) status."""
    status = msg.status[0]
    level = status.level
    level = int.from_bytes(level, 'little') if isinstance(level, (bytes, bytearray)) else int(level)
    values = {kv.key: kv.value for kv in status.values}
    return level, [r for r in values.get('reasons', '').split(',') if r]


def domain_id() -> int:
    """ROS_DOMAIN_ID when set, else one of this process's own (10..99: clear of 0 and of
    Linux's ephemeral ports)."""
    value = os.environ.get('ROS_DOMAIN_ID', '')
    return int(value) if value.isdigit() else 10 + os.getpid() % 90


class _Collector:
    """A subscriber node recording the node's outputs (spun on a thread)."""

    def __init__(self, context: Any) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        from hac_ros.ros.spin_thread import SpinThread
        from msg_adapters import rclpy_types

        types = rclpy_types()
        self.node = rclpy.create_node('hac_demo_live', context=context)
        self.counts: Counter[str] = Counter()
        self.last: dict[str, Any] = {}
        self.statuses = StatusShares()  # the node's stamp-time statuses, as they came
        self.last_arrival = time.monotonic()
        self._lock = threading.Lock()
        for topic, entry in OUTPUTS.items():
            durability = (DurabilityPolicy.TRANSIENT_LOCAL if entry.latched
                          else DurabilityPolicy.VOLATILE)
            qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                             durability=durability)
            self.node.create_subscription(types.get(entry.msgtype), topic, self._recorder(topic),
                                          qos)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(self.node)
        self.spinner = SpinThread(executor, 'hac_demo_live')

    def _recorder(self, topic: str) -> Callable[[Any], None]:
        def record(msg: Any) -> None:
            with self._lock:
                self.counts[topic] += 1
                if topic != DIAGNOSTICS.rooted or stamp_time_status(msg):
                    self.last[topic] = msg
                if topic == DIAGNOSTICS.rooted and stamp_time_status(msg):
                    self.statuses.add(*level_and_reasons(msg))
                self.last_arrival = time.monotonic()
        return record

    def connected(self) -> bool:
        return all(self.node.count_publishers(t) > 0 for t in OUTPUTS)

    def close(self) -> None:
        self.spinner.close()
        self.node.destroy_node()


def start_node(params_file: str | Path | None, env: dict[str, str]) -> subprocess.Popen:
    """``hac_node`` as a process of its own (``python -m hac_ros.ros.node``)."""
    command = [sys.executable, '-m', 'hac_ros.ros.node']
    if params_file:
        command += ['--ros-args', '--params-file', str(params_file)]
    return subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)


def stop_node(process: subprocess.Popen) -> str:
    """SIGINT, then the node's log (killed if it does not exit within EXIT_S)."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        out, _ = process.communicate(timeout=EXIT_S)
    except subprocess.TimeoutExpired:
        process.kill()
        out, _ = process.communicate()
    return out or ''


def live_run(recording: str | Path, rate: float = 1.0, params_file: str | Path | None = None,
             stop: threading.Event | None = None) -> LiveSummary:
    """Play ``recording`` into a fresh ``hac_node`` (module docstring) at ``rate`` times real
    time; ``params_file``: the node's parameters file (default: its defaults); ``stop``: set it
    to end the play early. HacError when the node does not come up."""
    import rclpy
    from rclpy.context import Context

    from hac_ros.recording.reader import Recording
    from hac_ros.ros.player import Player, check_rate

    check_rate(rate)
    if not Path(recording).exists():
        raise HacError(f'recording {recording} does not exist')
    if params_file:  # what rcl would refuse, said here in one line rather than by the node
        check_params_file(params_file)
    with Recording(recording) as rec:
        start_ns = rec.start_ns
    domain = domain_id()
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'  # this process's participants too
    env = {**os.environ, 'ROS_DOMAIN_ID': str(domain), 'PYTHONUNBUFFERED': '1',
           'RCUTILS_COLORIZED_OUTPUT': '0'}
    started = time.monotonic()
    node = start_node(params_file, env)
    context = Context()
    rclpy.init(args=[], context=context, domain_id=domain)
    collector = None
    node_log = ''
    try:
        collector = _Collector(context)
        with Player(recording, rate=rate, context=context) as player:
            deadline = time.monotonic() + STARTUP_S
            while not (collector.connected() and player.connected()):
                if node.poll() is not None or time.monotonic() > deadline:
                    node_log = stop_node(node)
                    raise HacError(f'{NODE_NAME} did not come up within {STARTUP_S:.0f} s:\n'
                                   f'{node_log.strip()}')
                time.sleep(POLL_S)
            log.info('%s is up: playing %s at %gx', NODE_NAME, recording, rate)
            stats = player.run(stop)
        _settle(collector)
    finally:
        node_log = node_log or stop_node(node)
        if collector is not None:
            collector.close()
        rclpy.try_shutdown(context=context)
    diagnostics = collector.last.get(DIAGNOSTICS.rooted)
    if diagnostics is None or not diagnostics.status:
        raise HacError(f'{NODE_NAME} published no /diagnostics:\n{node_log.strip()}')
    from msg_adapters import stamp_to_ns

    stamp = stamp_to_ns(diagnostics.header.stamp)
    status = status_from_diagnostics({kv.key: kv.value for kv in diagnostics.status[0].values},
                                     stamp)
    if SCALE.rooted in collector.last:
        status.scale = float(collector.last[SCALE.rooted].data)
    return LiveSummary(Path(recording), status, dict(collector.counts), stats.total,
                       time.monotonic() - started, domain, stamp, start_ns, node_log,
                       collector.statuses)


def _settle(collector: _Collector) -> None:
    """Wait until no output has arrived for QUIET_S (the node has caught up)."""
    deadline = time.monotonic() + SETTLE_MAX_S
    while time.monotonic() < deadline and time.monotonic() - collector.last_arrival < QUIET_S:
        time.sleep(POLL_S)
