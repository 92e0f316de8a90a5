"""hac_node as users run it: a separate process started with a parameters file, stopped by a signal.

The test process publishes a simulated walk over DDS (localhost, this process's domain) and
receives the outputs; the node's stderr is read for its warnings.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')
pytestmark = [pytest.mark.slow, pytest.mark.ros]  # hac_node as a subprocess

from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from test_node import (
    FRAME_PERIOD_S,
    INPUTS,
    LATCHED,
    OUTPUTS,
    RELIABLE,
    SCALE_TOL,
    TYPES,
    scenario_recording,
    wait_for,
)

from hac_ros.ros.node import DDS_PROFILE_VARIABLES
from hac_ros.ros.spin_thread import SpinThread

REPO = Path(__file__).resolve().parents[1]
STARTUP_S = 90.0  # at most: the node imports numpy/scipy/rclpy and joins DDS discovery
# at most, for the exit code after SIGINT/SIGTERM (well under a second on a quiet machine; this
# bound only tells a hang from a busy machine)
EXIT_S = 30.0
VOLATILE = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


def start_node(tmp_path: Path, params: dict[str, Any],
               env: dict[str, str] | None = None, text: str | None = None) -> subprocess.Popen:
    """hac_node with a parameters file of ``params`` (or of the YAML ``text``)."""
    path = tmp_path / 'hac.yaml'
    path.write_text(text or yaml.safe_dump({'hac_node': {'ros__parameters': params}}))
    env = {**os.environ, 'PYTHONUNBUFFERED': '1', 'PYTHONFAULTHANDLER': '1',
           'RCUTILS_COLORIZED_OUTPUT': '0', **(env or {})}
    return subprocess.Popen([sys.executable, '-m', 'hac_ros.ros.node', '--ros-args', '--params-file',
                             str(path)], cwd=REPO, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def stop(process: subprocess.Popen, sig: int) -> tuple[int, str]:
    """Send ``sig``; the exit code (None if it hung) and everything the node wrote."""
    process.send_signal(sig)
    try:
        out, err = process.communicate(timeout=EXIT_S)
        return process.returncode, out + err
    except subprocess.TimeoutExpired:  # hung: SIGABRT makes faulthandler print every thread
        process.send_signal(signal.SIGABRT)
        try:
            out, err = process.communicate(timeout=EXIT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            out, err = process.communicate()
        return None, out + err


class Client:
    """The test side: input publishers, output recorders, one executor thread."""

    def __init__(self) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.io = rclpy.create_node('hac_process_test', context=self.context)
        self.publishers = {kind: self.io.create_publisher(
            TYPES.get(msgtype), topic, LATCHED if kind == 'cloud' else RELIABLE)
            for kind, (topic, msgtype) in INPUTS.items()}
        self.received: dict[str, list[Any]] = {topic: [] for topic in OUTPUTS}
        for topic, msgtype in OUTPUTS.items():
            self.io.create_subscription(TYPES.get(msgtype), topic,
                                        lambda m, t=topic: self.received[t].append(m), RELIABLE)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.io)
        self.spinner = SpinThread(self.executor)

    def node_is_up(self) -> bool:
        return all(pub.get_subscription_count() > 0 for pub in self.publishers.values()) and \
            all(self.io.count_publishers(topic) > 0 for topic in OUTPUTS)

    def close(self) -> None:
        self.spinner.close()
        self.io.destroy_node()
        rclpy.shutdown(context=self.context)


@pytest.fixture
def client():
    c = Client()
    yield c
    c.close()


def test_node_process_driven_by_hac_play_converges_warns_and_exits_cleanly_on_sigint(
        tmp_path, client):
    """hac_node and ``hac play`` as users run them: two processes, a recording played at twice
    real time into the node (maps latched, frames paced by their stamps)."""
    from hac_ros.simulate import make_scenario, write_recording

    walk = scenario_recording('walk', duration=10.0)
    recording = write_recording(make_scenario('walk', seed=0, duration=10.0, hmr_bias=0.0),
                                tmp_path / 'walk')
    node = start_node(tmp_path, {'publish_tf': True, 'min_samples': 10})
    try:
        assert wait_for(client.node_is_up, STARTUP_S), 'hac_node did not come up'
        # a volatile map publisher against the default cloud_qos transient_local
        client.io.create_publisher(TYPES.get('sensor_msgs/msg/PointCloud2'), '/slam/cloud',
                                   VOLATILE)
        play = subprocess.run([sys.executable, '-m', 'hac_ros.cli', 'play', str(recording),
                               '--rate', '2', '--wait', str(STARTUP_S)], cwd=REPO,
                              capture_output=True, text=True, timeout=120)
        assert play.returncode == 0, play.stdout + play.stderr
        assert 'published /camera/camera_info' in play.stdout
        last_joints = int(walk.joints_stamps[-1])
        answered = wait_for(lambda: client.received['/hac/human_joints'] and
                            client.received['/hac/human_joints'][-1].header.stamp.sec * 10**9 +
                            client.received['/hac/human_joints'][-1].header.stamp.nanosec
                            == last_joints, 60.0)
    finally:
        code, log = stop(node, signal.SIGINT)
    got = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
           for m in client.received['/hac/human_joints']]
    assert answered, (f'the last frame ({last_joints}) produced no world joints (received '
                      f'{len(got)}, the last {got[-3:]}); the node said:\n{log}')
    assert code == 0, log
    scale = client.received['/hac/scale'][-1].data
    assert abs(scale / walk.scale_at(int(walk.pose_stamps[-1])) - 1.0) < SCALE_TOL
    assert client.received['/hac/odometry'] and client.received['/diagnostics']
    warnings = [line for line in log.splitlines() if 'QoS mismatch on /slam/cloud' in line]
    assert len(warnings) == 1 and 'cloud_qos' in warnings[0] and "'volatile'" in warnings[0], log
    assert log.count('publish_tf set but tf2_ros is not available') == 1
    assert 'Traceback' not in log and 'error handling a' not in log


def test_node_process_exits_cleanly_on_sigterm(tmp_path, client):
    # integers where doubles are declared, as YAML writes them, are accepted
    node = start_node(tmp_path, {'cloud_qos': 'volatile', 'window_s': 30,
                                 'base_to_camera': [0, 0, 0, 0, 0, 0, 1]})
    try:
        assert wait_for(client.node_is_up, STARTUP_S)
    finally:
        code, log = stop(node, signal.SIGTERM)
    assert code == 0, log
    assert 'Traceback' not in log and 'unknown parameter' not in log


SHARED_PARAMS = """\
/**:
  ros__parameters:
    use_sim_time: false
slam_node:
  ros__parameters:
    vocabulary: orb.txt
/robot1/hac_node:
  ros__parameters:
    min_samples: 3
hac_nod:
  ros__parameters:
    min_samples: 4
hac_node:
  ros__parameters:
    window_sec: 20.0
    qos_overrides:
      /hac/pose:
        publisher:
          depth: 5
"""


def test_node_process_accepts_a_shared_file_and_warns_what_ros_would_ignore(tmp_path, client):
    """ROS's conventions are accepted in silence (``/**``, other nodes' and namespaces' sections,
    ``use_sim_time``, ``qos_overrides``); a misspelt parameter is named with the closest valid one
    and a misspelt node section is warned about; the node runs."""
    node = start_node(tmp_path, {}, text=SHARED_PARAMS)
    try:
        assert wait_for(client.node_is_up, STARTUP_S), 'hac_node did not come up'
    finally:
        code, log = stop(node, signal.SIGINT)
    assert code == 0, log
    warnings = [line for line in log.splitlines() if line.startswith('[WARN]')]
    assert len(warnings) == 2, log
    assert "unknown parameter 'window_sec' (did you mean 'window_s'?) ignored" in warnings[0]
    assert f"{tmp_path / 'hac.yaml'}: section 'hac_nod' is not /hac_node's" in warnings[1]
    assert 'Traceback' not in log


@pytest.mark.parametrize('params, reason', [
    ({'contact_mode': 'tallest'}, 'contact_mode'),
    ({'cone_angle_deg': 90.0}, 'cone_angle_deg'),
    ({'window_s': 'long'}, 'window_s'),
    ({'min_samples': 2.5}, 'min_samples'),
])
def test_node_process_refuses_invalid_parameters(tmp_path, params, reason):
    node = start_node(tmp_path, params)
    out, err = node.communicate(timeout=STARTUP_S)
    assert node.returncode == 2, out + err
    assert reason in err and 'Traceback' not in err


def _shm_segments() -> dict[str, int]:
    """Fast DDS shared-memory segments on this host: name -> size in bytes."""
    shm = Path('/dev/shm')
    return {p.name: p.stat().st_size for p in shm.glob('fastrtps_*')
            if not p.name.startswith('fastrtps_port') and not p.name.endswith('_el')}


@pytest.mark.skipif(os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp') != 'rmw_fastrtps_cpp'
                    or not Path('/dev/shm').is_dir(), reason='a Fast DDS shared-memory profile')
def test_node_process_runs_with_the_large_data_dds_profile(tmp_path, client):
    """config/fastdds_large_data.xml is a profile this Fast DDS loads: the node gets its 64 MiB
    segment, still talks to a participant on the built-in transports (this process), and uses a
    map much larger than the built-in 512 KiB segment."""
    from msg_adapters import cloud_to_xyz, stamp_to_ns, xyz_to_cloud

    profile = str(REPO / 'config' / 'fastdds_large_data.xml')
    walk = scenario_recording('walk', duration=4.0)
    before = _shm_segments()
    node = start_node(tmp_path, {}, dict.fromkeys(DDS_PROFILE_VARIABLES, profile))
    try:
        assert wait_for(client.node_is_up, STARTUP_S), 'hac_node did not come up'
        new = {name: size for name, size in _shm_segments().items() if name not in before}
        assert any(size >= 64 * 2**20 for size in new.values()), new
        rng = np.random.default_rng(0)
        for event in walk.events:
            msg = event.msg
            if event.kind == 'cloud':  # the walk's map made 250k points (4 MB, not thinned), same header
                points = cloud_to_xyz(msg)
                points = (points[rng.integers(0, len(points), 250_000)]
                          + rng.normal(0, 1e-3, (250_000, 3)))
                msg = xyz_to_cloud(points, stamp_to_ns(msg.header.stamp), msg.header.frame_id, TYPES)
            client.publishers[event.kind].publish(msg)
            time.sleep(0.5 if event.kind == 'cloud' else FRAME_PERIOD_S if event.kind == 'joints' else 0)

        def indexed() -> bool:
            diagnostics = client.received['/diagnostics']
            return bool(diagnostics) and any(kv.key == 'map_points' and kv.value == '250000'
                                             for kv in diagnostics[-1].status[0].values)
        assert wait_for(indexed, 60.0), 'the large map was not used'  # 250k points, a busy host
    finally:
        code, log = stop(node, signal.SIGINT)
    assert code == 0, log
    assert 'Traceback' not in log and 'XMLPARSER' not in log and 'Error' not in log, log
