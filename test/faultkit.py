"""What the fault suites share: a recording run through the node's core as ``hac replay --mode
online`` does (:class:`Run`), the /diagnostics a replay wrote, a live ``hac_node`` in this process
beside an input/output node (:class:`LiveNode`), and waiting with an upper bound."""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from injected import finite_abs_max

from hac_ros.bridge.topics import BY_KEY
from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import (
    CloudOut,
    DiagnosticsOut,
    HumanJointsOut,
    OdometryOut,
    Output,
    PoseOut,
    ScaleOut,
    Status,
)
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.rules.params import HacParams
from hac_ros.recording.reader import Recording
from hac_ros.replay.feeder import CoreFeeder, InputTopics


@dataclass
class Run:
    """What the core published for a recording, in order (as ``hac replay --mode online``)."""

    calibrator: Calibrator
    outputs: list[Output] = field(default_factory=list)

    def of(self, kind: type) -> list[Any]:
        return [o for o in self.outputs if isinstance(o, kind)]

    @property
    def scales(self) -> np.ndarray:
        return np.array([o.scale for o in self.of(ScaleOut)])

    @property
    def statuses(self) -> list[Status]:
        return [o.status for o in self.of(DiagnosticsOut)]

    def largest_value_m(self) -> float:
        """The largest |value| in every metric output (inf when one is not finite)."""
        arrays = [o.position_metric for o in self.of(PoseOut)]
        arrays += [o.position_metric for o in self.of(OdometryOut)]
        arrays += [o.points_metric for o in self.of(CloudOut)]
        arrays += [o.joints_metric for o in self.of(HumanJointsOut)]
        return finite_abs_max(arrays)


def run_online(path: Path, params: HacParams | None = None) -> Run:
    params = params or HacParams()
    run = Run(Calibrator(params))
    with Recording(path) as recording:
        CoreFeeder(recording, InputTopics.check(recording, params), run.calibrator).run(
            run.outputs.extend)
    return run


def written_diagnostics(path: Path) -> list[tuple[int, int, str, dict[str, str]]]:
    """(stamp ns, level, message, values) of every /diagnostics message written to ``path``."""
    with Recording(path) as recording:
        out = []
        for _, msg in recording.read('/diagnostics'):
            status = msg.status[0]
            stamp = msg.header.stamp.sec * NS + msg.header.stamp.nanosec
            out.append((stamp, int.from_bytes(bytes(status.level), 'little')
                        if isinstance(status.level, (bytes, bytearray)) else int(status.level),
                        status.message, {kv.key: kv.value for kv in status.values}))
    return out


def wait_until(predicate: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True



def _rclpy_types() -> Any:
    from msg_adapters import rclpy_types

    return rclpy_types()


class LiveNode:
    """hac_node in this process (its own context, this process's domain) beside a node that
    publishes inputs and records outputs, spun on one thread."""

    OUTPUTS: ClassVar[dict[str, str]] = {BY_KEY[key].rooted: BY_KEY[key].msgtype
                                         for key in ('scale', 'human_joints', 'diagnostics')}

    def __init__(self, **params: Any) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.parameter import Parameter
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        from hac_ros.ros.node import HacNode
        from hac_ros.ros.spin_thread import SpinThread

        self.context = Context()
        rclpy.init(context=self.context)
        self.node = HacNode(context=self.context, parameter_overrides=[
            Parameter(name, value=value) for name, value in params.items()])
        self.io = rclpy.create_node('hac_faults_io', context=self.context)
        self.received: dict[str, list[Any]] = {topic: [] for topic in self.OUTPUTS}
        for topic, msgtype in self.OUTPUTS.items():
            self.io.create_subscription(_rclpy_types().get(msgtype), topic,
                                        lambda m, t=topic: self.received[t].append(m),
                                        QoSProfile(depth=1000,
                                                   reliability=ReliabilityPolicy.RELIABLE))
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.io)
        self.spinner = SpinThread(self.executor)

    def statuses(self) -> list[tuple[int, str, dict[str, str]]]:
        """(level, message, values) of each /diagnostics status received, in order."""
        out = []
        for msg in list(self.received['/diagnostics']):
            for status in msg.status:
                level = status.level
                level = level[0] if isinstance(level, (bytes, bytearray)) else int(level)
                out.append((level, status.message, {kv.key: kv.value for kv in status.values}))
        return out

    def close(self) -> None:
        import rclpy

        self.spinner.close()
        self.node.destroy_node()
        self.io.destroy_node()
        rclpy.shutdown(context=self.context)
