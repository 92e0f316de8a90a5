"""SLAM poses given the other way round: the world in the camera (T_cw) read as the camera in the
map, the most common pose mistake (ORB-SLAM's TrackMonocular returns T_cw). Caught by the people's
body axes, which line up in the map only under the right rotation (hac_ros.core.bodies.convention_check),
on simulated scenes and on the real trajectories of the bench's composites."""
from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from hac_ros.bridge.messages import OutputMessages
from hac_ros.core.basics.outputs import DiagnosticsOut, NoticeOut, Output
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.rules.health import OK, HealthMonitor
from hac_ros.core.rules.params import HacParams
from hac_ros.simulate import make_scenario
from hac_ros.simulate.feed import feed_events

BENCH = Path(__file__).resolve().parents[1] / 'bench'


@pytest.fixture(scope='module')
def bench() -> Iterator[None]:
    """bench/ importable: its scenes are the ones the check's thresholds were measured on."""
    sys.path.insert(0, str(BENCH))
    yield
    sys.path.remove(str(BENCH))


def inverted(events: list) -> list:
    """The same inputs with every SLAM pose (R_wc, c) replaced by its inverse (R_wcᵀ, -R_wcᵀ c)."""
    out = []
    for stamp, kind, payload in events:
        if kind == 'pose':
            R, c, *rest = payload
            payload = (R.T, -R.T @ c, *rest)
        out.append((stamp, kind, payload))
    return out


def run(scene, events: list) -> tuple[Calibrator, list[Output]]:
    cal = Calibrator(HacParams())
    cal.add_camera_info(scene.K, scene.width, scene.height)
    return cal, feed_events(cal, events) + cal.flush()


def simulated(name: str, seed: int, rate: str):
    from _accuracy_runs import scene_from_scenario
    from _keyframes import at_keyframes

    scene = scene_from_scenario(make_scenario(name, seed=seed, hmr_bias=0.0))
    return at_keyframes(scene) if rate == 'kf' else scene


def composite(shared: Path, name: str, seed: int):
    from _accuracy_runs import scene_from_composite
    from accuracy import COMPOSITES
    from composite import build

    sequence, motion = COMPOSITES[name]
    return scene_from_composite(build(shared, seed, 0.0, sequence, motion, rate=30.0), seed)


def caught(outputs: list[Output]) -> list[NoticeOut]:
    return [o for o in outputs if isinstance(o, NoticeOut) and o.cause == 'convention_pose_inverted']


def assert_caught_and_never_ok_after(cal: Calibrator, outputs: list[Output]) -> None:
    notice, = caught(outputs)
    assert notice.level == 'warn' and 'T_cw' in notice.text and 'publish its inverse' in notice.text
    assert 'pose_inverted' in cal.status().suspects
    monitor = HealthMonitor()
    after = [o.status for o in outputs if isinstance(o, DiagnosticsOut)
             and o.status.stamp_ns >= notice.stamp_ns]
    assert after and all(monitor.assess(status).level != OK for status in after)
    diag = OutputMessages(HacParams()).diagnostics(cal.status())
    assert b'suspect.pose_inverted' in diag


def test_inverted_poses_of_a_turning_camera_are_caught(bench):
    scene = simulated('ego', 1, '30hz')
    cal, outputs = run(scene, inverted(scene.events))
    assert_caught_and_never_ok_after(cal, outputs)


def test_inverted_poses_of_a_real_slam_trajectory_are_caught(bench, shared_data):
    """CMU 131_02 walked in front of the ORB-SLAM trajectory of TUM fr2_desk, 30 Hz."""
    scene = composite(shared_data, 'composite_02', 0)
    cal, outputs = run(scene, inverted(scene.events))
    assert_caught_and_never_ok_after(cal, outputs)


@pytest.mark.parametrize('name, rate', [
    ('ego', '30hz'), ('ego', 'kf'), ('handstand', '30hz'), ('office', '30hz'), ('skate', 'kf'),
    ('stairs', '30hz'), ('reset', '30hz'), ('crowd', 'kf')])
def test_correct_poses_are_never_taken_for_inverted(bench, name, rate):
    """People on their hands, seated and lying, a SLAM that re-initialises, keyframes: the bodies
    line up under the right rotation at least as well as under its transpose."""
    scene = simulated(name, 2, rate)
    cal, outputs = run(scene, scene.events)
    assert not caught(outputs) and 'pose_inverted' not in cal.status().suspects


@pytest.mark.parametrize('name', ['composite_01', 'steep_03'])
def test_correct_real_trajectories_are_never_taken_for_inverted(bench, shared_data, name):
    scene = composite(shared_data, name, 1)
    cal, outputs = run(scene, scene.events)
    assert not caught(outputs)
    # and the evidence is clear the other way: the right rotation lines the bodies up better
    spread = [1.0 - np.linalg.eigvalsh(t / cal.check._axes_people)[-1] for t in cal.check._axes]
    assert spread[0] < 0.8 * spread[1]
