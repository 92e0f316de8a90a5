"""bench/paired.py: the per-seed rule that says whether an accuracy scene got worse."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'bench'))
from paired import compare, load


def _lines(scenario: str, rate: str | None, errors: np.ndarray, condition: str = 'clean') -> str:
    """bench/accuracy.py scene lines: one per seed, the default row's signed offline error
    ``errors`` (%), its absolute value and an online error 0.1 point above it."""
    out = []
    for seed, signed in enumerate(errors):
        line = {'scenario': scenario, 'seed': seed, 'condition': condition,
                'rows': {'default': {'scale_bias': float(signed), 'scale_err': abs(float(signed)),
                                     'online_err': abs(float(signed)) + 0.1, 'statuses': 10,
                                     'ok_wrong': 0}}}
        if rate is not None:
            line['rate'] = rate
        out.append(json.dumps(line))
    return '\n'.join(out)


def _line(lines: list[dict], scene: str, figure: str) -> dict:
    return next(line for line in lines if line['scenario'] == scene and line['figure'] == figure)


def test_a_scene_is_worse_only_beyond_its_paired_noise_and_the_signed_error_is_never_judged(
) -> None:
    rng = np.random.default_rng(0)
    old_errors = 1.0 + 0.05 * rng.standard_normal(20)
    old = load(_lines('walk', '30hz', old_errors) + '\n' + _lines('steep_01', None, -old_errors),
               'default', 'clean')
    # walk: every seed 0.3 point further off; steep_01 (no rate: its native keyframes): its
    # negative bias halved, so its signed error moves towards zero by 0.5 point
    new = load(_lines('walk', '30hz', old_errors + 0.3) + '\n'
               + _lines('steep_01', 'kf', -0.5 * old_errors), 'default', 'clean')
    lines = compare(new, old)
    walk = _line(lines, 'walk@30hz', 'offline %')
    assert walk['worse'] and walk['n'] == 20 and abs(walk['moved'] - 0.3) < 1e-9
    assert _line(lines, 'walk@30hz', 'online %')['worse']
    assert not _line(lines, 'walk@30hz', 'bias %')['worse']  # shown, never judged
    steep = _line(lines, 'steep_01@kf', 'offline %')
    assert not steep['worse'] and steep['moved'] < -0.4
    assert _line(lines, 'steep_01@kf', 'bias %')['moved'] > 0.4
    assert not _line(lines, 'steep_01@kf', 'OK>5% share')['worse']


def test_a_move_within_the_paired_noise_is_not_worse() -> None:
    old_errors = np.linspace(0.5, 1.5, 20)
    # a noisy scene: each seed 1 point up or down, 0.3 point up on the median
    new_errors = old_errors + 0.3 + np.where(np.arange(20) % 2, 1.0, -1.0)
    lines = compare(load(_lines('crowd', '30hz', new_errors), 'default', 'clean'),
                    load(_lines('crowd', '30hz', old_errors), 'default', 'clean'))
    offline = _line(lines, 'crowd@30hz', 'offline %')
    assert offline['moved'] > 0.1 and 2.0 * offline['se'] > offline['moved']
    assert not offline['worse']


def test_a_run_that_never_published_online_leaves_its_seed_out_of_the_online_line() -> None:
    errors = np.full(20, 1.0)
    new_text = _lines('stairs', '30hz', errors).replace('"online_err": 1.1', '"online_err": NaN', 3)
    lines = compare(load(new_text, 'default', 'clean'),
                    load(_lines('stairs', '30hz', errors), 'default', 'clean'))
    assert _line(lines, 'stairs@30hz', 'online %')['n'] == 17
    assert _line(lines, 'stairs@30hz', 'offline %')['n'] == 20
