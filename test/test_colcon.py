"""``colcon build`` of the package into a temporary workspace, as a ROS user builds it.

The repository is copied to ``<tmp>/src/hac_ros`` (the build never writes into the repository) and
built with colcon-core + colcon-ros from the venv. Then the installed ``hac_node`` is started
from the install space with the installed parameters file and, once it says it is up, stopped with
SIGINT. No fixed sleep: a busy machine may take many seconds to import rclpy, numpy and scipy.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# what a source checkout does not ship: virtualenv, VCS, build outputs, caches, recordings
NOT_SOURCE = ('.venv', '.git', 'build', 'install', 'log', 'out', 'bags', '__pycache__',
              '*.egg-info', '.pytest_cache', '.hypothesis', 'results')
BUILD_TIMEOUT_S = 300
NODE_START_S = 120.0  # at most, to import, read the parameters file and say it is up
EXIT_S = 60.0  # at most, to exit after SIGINT (generous: a loaded machine)
UP = 'contact_mode'  # in the line hac_node logs when it has subscribed and starts spinning

pytest.importorskip('colcon_core')
pytest.importorskip('colcon_ros')


@pytest.mark.slow
def test_colcon_build_installs_the_node_and_the_ament_marker(tmp_path):
    shutil.copytree(REPO, tmp_path / 'src' / 'hac_ros', ignore=shutil.ignore_patterns(*NOT_SOURCE),
                    symlinks=True)
    build = subprocess.run([sys.executable, '-m', 'colcon', 'build', '--base-paths', 'src'],
                           cwd=tmp_path, capture_output=True, text=True, timeout=BUILD_TIMEOUT_S)
    assert build.returncode == 0, build.stdout + build.stderr
    install = tmp_path / 'install' / 'hac_ros'
    node = install / 'lib' / 'hac_ros' / 'hac_node'
    assert node.is_file() and os.access(node, os.X_OK)
    assert (install / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'hac_ros').is_file()
    config = install / 'share' / 'hac_ros' / 'config' / 'hac.yaml'
    for path in (config, install / 'share' / 'hac_ros' / 'package.xml',
                 install / 'share' / 'hac_ros' / 'launch' / 'hac.launch.py',
                 install / 'share' / 'hac_ros' / 'rviz' / 'hac.rviz',
                 install / 'share' / 'hac_ros' / 'config' / 'fastdds_large_data.xml'):
        assert path.is_file(), path

    # the installed executable runs from the install space with the installed parameters file
    site = next((install / 'lib').glob('python3*/site-packages'))
    env = {**os.environ, 'PYTHONPATH': f'{site}{os.pathsep}{os.environ.get("PYTHONPATH", "")}',
           'RCUTILS_COLORIZED_OUTPUT': '0'}
    probe = subprocess.run([sys.executable, '-c', 'import hac_ros.ros.node; print(hac_ros.ros.node.__file__)'],
                           env=env, capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert probe.returncode == 0 and probe.stdout.strip().startswith(str(install)), probe
    process = subprocess.Popen([str(node), '--ros-args', '--params-file', str(config)], env=env,
                               cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                               text=True)
    lines: list[str] = []  # its log (rclpy logs to stderr), read as it comes

    def read() -> None:
        assert process.stderr is not None
        for line in process.stderr:
            lines.append(line)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    deadline = time.monotonic() + NODE_START_S
    try:
        while not any(UP in line for line in lines):
            assert process.poll() is None, f'hac_node exited early: {"".join(lines)}'
            assert time.monotonic() < deadline, f'hac_node not up in {NODE_START_S} s: {lines}'
            time.sleep(0.1)
        process.send_signal(signal.SIGINT)
        assert process.wait(EXIT_S) == 0, ''.join(lines)
    finally:
        if process.poll() is None:
            process.kill()
        reader.join(EXIT_S)
    err = ''.join(lines)
    assert 'unknown parameter' not in err and 'Traceback' not in err, err
