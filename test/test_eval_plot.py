"""``hac eval``, ``hac plot``, the TUM exports (against evo) and ``hac demo``."""
from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scenes import Scene, walking_scene
from test_replay import write_recording

from hac_ros.evaluation.evaluate import evaluate
from hac_ros.evaluation.plots import FIGSIZE, figure_size_px, make_plots
from hac_ros.files.tum import TUM_FILES
from hac_ros.replay.replayer import replay

REPO = Path(__file__).resolve().parents[1]
PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'


def hac(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'hac_ros.cli', *args], cwd=REPO, text=True,
                          capture_output=True, timeout=120)


def wavy_walk(frames: int) -> Scene:
    """The walking scene with a camera that also sways sideways and up and down (a path along one
    line leaves an alignment's rotation about that line undetermined, and evo refuses it)."""
    scene = walking_scene(frames=frames)
    t = np.arange(frames)
    scene.c_world[:, 1] += 0.4 * np.sin(t / 9.0)
    scene.c_world[:, 2] += 0.2 * np.sin(t / 5.0)
    return scene


@pytest.fixture(scope='module')
def replayed(tmp_path_factory) -> tuple[Path, Path, Path]:
    """(IN, OUT, TUM dir): a walking scene with noisy SLAM centres, replayed offline."""
    root = tmp_path_factory.mktemp('eval')
    source = write_recording(root / 'walk', wavy_walk(120), slam_noise=0.01)
    replay(source, root / 'out', export_tum=root / 'tum')
    return source, root / 'out', root / 'tum'


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) from the PNG's IHDR chunk."""
    head = path.read_bytes()[:24]
    assert head[:8] == PNG_SIGNATURE, f'{path} is not a PNG'
    assert head[12:16] == b'IHDR'
    return struct.unpack('>II', head[16:24])


# ============================================================================ eval
def test_eval_rows_compare_hac_with_no_calibration_and_the_true_scale(replayed, tmp_path):
    source, out, _ = replayed
    result = hac('eval', str(out), '--gt', str(source), '--json', str(tmp_path / 'e.json'), '--md',
                 str(tmp_path / 'e.md'))
    assert result.returncode == 0, result.stderr
    rows = json.loads((tmp_path / 'e.json').read_text())['rows']
    hac_row, none, true = rows['hac'], rows['no calibration'], rows['true scale']
    # the scene's true scale is 2.5: SLAM units as metres are 60 % off
    assert none['scale_error_pct'] == pytest.approx(60.0)
    assert true['scale_error_pct'] == pytest.approx(0.0, abs=1e-9)
    assert hac_row['scale_error_pct'] < 5.0  # the cone median's grazing-angle bias, docs/method.md
    # a wrong scale shows after an SE(3) alignment, not after a Sim(3) one
    assert none['ate_s_m'] > 10 * hac_row['ate_s_m']
    assert none['ate_m'] == pytest.approx(true['ate_m'], rel=1e-6)
    assert hac_row['ate_m'] == pytest.approx(true['ate_m'], rel=1e-6)
    assert none['w_mpjpe_mm'] > 5 * hac_row['w_mpjpe_mm'] > 0
    assert true['w_mpjpe_mm'] <= hac_row['w_mpjpe_mm']
    assert hac_row['pa_mpjpe_mm'] == pytest.approx(true['pa_mpjpe_mm'], abs=1e-6)  # scale-free
    assert none['rte_pct'] > hac_row['rte_pct']
    table = (tmp_path / 'e.md').read_text()
    assert table.splitlines()[0].startswith('| | ATE (m) | ATE-S (m) | RPE 1 s (m) | RPE (%) |')
    assert '| hac |' in table and '| no calibration |' in table and '| true scale |' in table
    assert table in result.stdout + '\n'


def test_tum_exports_load_in_evo_and_evo_ate_matches_hac_eval(replayed):
    from evo.core import metrics as evo_metrics
    from evo.core import sync
    from evo.tools import file_interface

    source, out, tum = replayed
    assert sorted(p.name for p in tum.iterdir()) == sorted(TUM_FILES.values())
    row = evaluate(out, source).rows['hac']
    for correct_scale, key in ((True, 'ate_m'), (False, 'ate_s_m')):
        ref = file_interface.read_tum_trajectory_file(str(tum / TUM_FILES['gt']))
        est = file_interface.read_tum_trajectory_file(str(tum / TUM_FILES['metric']))
        ref, est = sync.associate_trajectories(ref, est)
        est.align(ref, correct_scale=correct_scale)
        ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
        ape.process_data((ref, est))
        evo_mean = ape.get_statistic(evo_metrics.StatisticsType.mean)
        assert evo_mean > 1e-3  # the noisy SLAM makes it a real comparison
        assert row[key] == pytest.approx(evo_mean, rel=1e-6), key
    slam = file_interface.read_tum_trajectory_file(str(tum / TUM_FILES['slam']))
    assert slam.num_poses == 120


def test_eval_errors_are_clean(replayed, tmp_path):
    source, out, _ = replayed
    no_truth = write_recording(tmp_path / 'nogt', walking_scene(frames=20), gt=False)
    result = hac('eval', str(out), '--gt', str(no_truth))
    assert result.returncode == 2 and 'Traceback' not in result.stderr
    assert 'no ground truth' in result.stderr and '/slam/pose' in result.stderr
    result = hac('eval', str(source), '--gt', str(source))  # IN is not a replay output
    assert result.returncode == 2 and 'not a recording written by hac replay' in result.stderr


# ============================================================================ plots
def test_plots_are_real_images_of_the_expected_size(replayed, tmp_path):
    import matplotlib.image

    source, out, _ = replayed
    result = hac('plot', str(out), '--gt', str(source), '-o', str(tmp_path / 'figs'))
    assert result.returncode == 0, result.stderr
    for name in FIGSIZE:
        path = tmp_path / 'figs' / f'{name}.png'
        assert png_size(path) == figure_size_px(name)
        pixels = matplotlib.image.imread(path)
        assert pixels.shape[:2] == figure_size_px(name)[::-1]
        assert pixels[..., :3].std() > 0.05, f'{name} looks blank'


def test_plots_without_ground_truth(replayed, tmp_path):
    _, out, _ = replayed
    paths = make_plots(out, tmp_path / 'figs')
    assert set(paths) == set(FIGSIZE)
    assert all(png_size(p) == figure_size_px(n) for n, p in paths.items())


# ============================================================================ demo
@pytest.mark.slow
def test_demo_replays_evaluates_plots_and_replaces_earlier_results(replayed, tmp_path):
    source, _, _ = replayed
    out_dir = tmp_path / 'out'
    out_dir.mkdir()
    (out_dir / 'scale.png').write_text('stale')
    (out_dir / 'notes.txt').write_text('mine')
    for _ in range(2):  # the second run replaces the first run's results
        result = hac('demo', '--recording', str(source), '-o', str(out_dir))
        assert result.returncode == 0, result.stderr
    assert 'final scale' in result.stdout and '| hac |' in result.stdout
    assert (out_dir / 'notes.txt').read_text() == 'mine'
    assert png_size(out_dir / 'scale.png') == figure_size_px('scale')
    assert json.loads((out_dir / 'eval.json').read_text())['rows']['hac']['scale_error_pct'] < 5.0
    assert (out_dir / 'replay' / 'metadata.yaml').exists()
    assert np.loadtxt(out_dir / 'tum' / TUM_FILES['metric']).shape == (120, 8)
