"""Correct runs look correct: nothing at WARNING or above on the bundled recordings (issue 36).

What every correct run meets is said at INFO: waiting for the first map, a sample the outlier gate
kept out, a SLAM re-initialisation (a reset: what a SLAM does, counted in /diagnostics). The
HMR focal-length line comes only when ``hmr_focal_px`` is set (it then says the correction made).
"""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from scenes import walking_scene

from hac_ros.core.basics.outputs import NoticeOut
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.rules.params import HacParams

REPO = Path(__file__).resolve().parents[1]
LEVEL = re.compile(r'^hac \w+: (debug|info|warning|error|critical): ', re.M)


def _hac(*argv: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'hac_ros.cli', *argv], cwd=cwd, text=True,
                          capture_output=True, timeout=600)


def _levels(stderr: str) -> list[str]:
    return LEVEL.findall(stderr)


@pytest.mark.parametrize('mode', ['offline', 'online'])
def test_hac_replay_of_the_demo_recording_logs_nothing_at_warning_or_above(tmp_path, mode):
    result = _hac('replay', 'bags/demo_walk', '-o', str(tmp_path / 'out'), '--mode', mode)
    assert result.returncode == 0, result.stderr
    levels = _levels(result.stderr)
    assert levels and set(levels) == {'info'}, result.stderr  # waiting for the first map: INFO
    assert 'waiting for the first map' in result.stderr
    assert 'focal' not in result.stderr  # hmr_focal_px 0: nothing the user must act on


def test_make_demo_logs_nothing_at_warning_or_above(tmp_path):
    """``make demo`` is ``python -m hac_ros.cli demo`` (here into a directory of its own)."""
    result = _hac('demo', '-o', str(tmp_path / 'out'))
    assert result.returncode == 0, result.stderr
    assert set(_levels(result.stderr)) <= {'info'}, result.stderr
    assert 'warning' not in result.stderr.lower() and 'Traceback' not in result.stderr


def test_the_one_reset_of_reset_short_is_logged_at_info(tmp_path):
    result = _hac('replay', 'bags/reset_short', '-o', str(tmp_path / 'out'))
    assert result.returncode == 0, result.stderr
    resets = [line for line in result.stderr.splitlines() if 'estimator reset' in line]
    assert len(resets) == 1 and resets[0].startswith('hac replay: info: t+6.000 s'), resets
    assert set(_levels(result.stderr)) == {'info'}, result.stderr


def _no_map_notices(outputs: list) -> list[NoticeOut]:
    return [o for o in outputs if isinstance(o, NoticeOut) and o.cause == 'no_map']


def test_waiting_for_the_first_map_is_info_but_frames_without_a_map_later_warn():
    """no_map before any map came is waiting (INFO); once a map was in use, frames that find
    none (the SLAM re-initialised and sent no map yet) are a rejection worth a warning."""
    scene = walking_scene(frames=40)
    floor = scene.floor_points_slam()

    def feed(map_until: int | None) -> list:
        calibrator = Calibrator(HacParams(ground_mode='none'))
        outputs: list = []
        for t, stamp in enumerate(scene.stamps_ns.tolist()):
            if map_until is not None and t == 0:
                outputs += calibrator.add_map(stamp, floor, 'map')
            frame = 'map' if map_until is None or t < map_until else 'map_1'  # a new SLAM map
            outputs += calibrator.add_pose(stamp, scene.R_wc_slam[t], scene.c_slam[t], frame)
            outputs += calibrator.add_joints(stamp, scene.joints_cam[t][None], 'camera')
        return outputs + calibrator.flush()

    waiting = _no_map_notices(feed(None))
    assert [n.level for n in waiting] == ['info'] and 'waiting for the first map' in waiting[0].text
    lost = _no_map_notices(feed(20))
    assert [n.level for n in lost] == ['warn'] and 'rejected input (no_map)' in lost[0].text
