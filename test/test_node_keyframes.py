"""hac_node over DDS at keyframe rate (issue 43): a composite of real ORB-SLAM keyframes of TUM
fr2_desk and a real CMU walk (bench/composite.py), imported as a user imports a SLAM's and an HMR's
files (``hac import``), played by ``hac play`` into the node (a separate process). Once the node
has converged, every SLAM pose gets its odometry: at least 95 % of them arrive (DDS is reliable
here; the margin is for a loaded machine).
"""
from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

rclpy = pytest.importorskip('rclpy')
pytestmark = [pytest.mark.slow, pytest.mark.ros]  # hac_node as a subprocess

from test_node_process import STARTUP_S, Client, start_node, stop, wait_for

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / 'bench'))
RATE = 4.0  # keyframes come at about 1.3 Hz: four times real time is still slow for the node


def stamp_of(msg) -> int:
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def composite_recording(shared: Path, out: Path) -> tuple[Path, list[int]]:
    """The keyframe composite as files a SLAM and an HMR write, imported; its pose stamps."""
    from composite import HEIGHT, WIDTH, build

    from hac_ros.cli import main as hac

    data = build(shared, seed=0, sequence='fr2_desk', motion=0)
    out.mkdir()
    stamps_s = data.stamps_ns / 1e9
    quats = Rotation.from_matrix(data.R_wc_slam).as_quat()
    lines = [f'{t:.9f} ' + ' '.join(f'{v:.9f}' for v in (*c, *q))
             for t, c, q in zip(stamps_s, data.c_slam, quats)]
    (out / 'trajectory.tum').write_text('\n'.join(lines) + '\n')
    np.save(out / 'map.npy', data.points_slam)
    np.savez(out / 'joints.npz', stamps=data.frame_stamps_ns / 1e9,
             joints=data.joints_cam[:, None])
    K = data.K
    camera = f'{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]},{WIDTH},{HEIGHT}'
    code = hac(['import', '-o', str(out / 'recording'), '--trajectory',
                str(out / 'trajectory.tum'), '--map', str(out / 'map.npy'), '--joints',
                str(out / 'joints.npz'), '--camera', camera])
    assert code == 0
    return out / 'recording', [int(round(t * 1e9)) for t in stamps_s]


@pytest.fixture
def client():
    c = Client()
    yield c
    c.close()


def test_the_node_publishes_odometry_for_every_keyframe_once_converged(shared_data, tmp_path,
                                                                         client):
    recording, pose_stamps = composite_recording(shared_data, tmp_path / 'composite')
    node = start_node(tmp_path, {})
    try:
        assert wait_for(client.node_is_up, STARTUP_S), 'hac_node did not come up'
        for publisher in client.publishers.values():  # hac play publishes: one publisher each
            client.io.destroy_publisher(publisher)
        play = subprocess.run([sys.executable, '-m', 'hac_ros.cli', 'play', str(recording),
                               '--rate', str(RATE), '--wait', str(STARTUP_S)], cwd=REPO,
                              capture_output=True, text=True, timeout=300)
        assert play.returncode == 0, play.stdout + play.stderr
        wait_for(lambda: client.received['/hac/odometry'] and
                 stamp_of(client.received['/hac/odometry'][-1]) == pose_stamps[-1], 30.0)
    finally:
        code, log = stop(node, signal.SIGINT)
    assert code == 0, log
    poses = client.received['/hac/pose']
    assert poses, log
    first = min(stamp_of(m) for m in poses)
    after = [s for s in pose_stamps if s >= first]
    odometry = {stamp_of(m) for m in client.received['/hac/odometry']}
    share = sum(s in odometry for s in after) / len(after)
    assert share >= 0.95, (share, len(after), log)
    levels = [ord(m.status[0].level) for m in client.received['/diagnostics'] if m.status]
    messages = [m.status[0].message for m in client.received['/diagnostics'] if m.status]
    assert 0 in levels, messages[::5]  # and it said OK
