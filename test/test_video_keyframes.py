"""Keyframes of a video (hac_ros.video.keyframes) on real photos moved by known amounts: a still
camera gets one keyframe per second and says it never moved, a panning one gets keyframes by
motion, a rate gets its rate, and no gap is ever over a second."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import OPENCV_DATA

from hac_ros.core.basics.errors import ArgumentError


@pytest.fixture(scope='module')
def photo(people_extra) -> np.ndarray:
    import cv2

    bgr = cv2.imread(str(OPENCV_DATA / 'building.jpg'))
    if bgr is None:
        pytest.skip('building.jpg missing (apt-get install opencv-doc)')
    return np.ascontiguousarray(bgr[:, :, ::-1])


def panned(photo: np.ndarray, shifts_px: list[float], size=(320, 240)) -> list[np.ndarray]:
    """Windows of ``photo`` moved right by each shift (pixels): a camera panning over it."""
    import cv2

    frames = []
    for x in shifts_px:
        M = np.float32([[1, 0, -x], [0, 1, 0]])
        frames.append(cv2.warpAffine(photo, M, size, flags=cv2.INTER_LINEAR))
    return frames


def choose(frames, fps, **kwargs):
    from hac_ros.video.keyframes import MotionKeyframes

    chooser = MotionKeyframes(fps, **kwargs)
    flags = [chooser.add(f) for f in frames]
    return chooser, chooser.finish(), flags


def test_a_still_camera_gets_one_keyframe_a_second_and_is_known_still(photo):
    rng = np.random.default_rng(0)
    frames = [np.clip(f.astype(int) + rng.normal(0, 2, f.shape), 0, 255).astype(np.uint8)
              for f in panned(photo, [0.0] * 25)]
    chooser, choice, _ = choose(frames, fps=10.0)
    assert choice.index.tolist() == [0, 10, 20, 24]
    assert choice.why == ['first', 'gap', 'gap', 'last']
    assert chooser.most_motion < 0.01  # hac video's STILL: refused, pointing to static_camera


def test_a_panning_camera_gets_keyframes_by_motion_never_a_second_apart(photo):
    # 12 px a frame at 320 px: 6 % of the width (the default motion) in 1.6 frames
    frames = panned(photo, [12.0 * i for i in range(20)])
    chooser, choice, _ = choose(frames, fps=2.0)
    assert choice.why[0] == 'first' and 'motion' in choice.why
    gaps = np.diff(choice.index)
    assert gaps.max() <= 2  # fps 2: at most a second
    assert chooser.most_motion > 0.03
    # 4 px a frame: 6 % in 4.8 frames
    frames = panned(photo, [4.0 * i for i in range(40)])
    _, choice, _ = choose(frames, fps=30.0)
    assert set(choice.why[1:-1]) == {'motion'}
    assert np.diff(choice.index).min() >= 4 and np.diff(choice.index).max() <= 6
    assert choice.index[-1] == 39


@pytest.mark.parametrize('fps, rate', [(30.0, 1.0), (7.5, 1.0), (10.0, 3.0), (25.0, 2.0)])
def test_a_rate_keeps_every_gap_within_its_period(photo, fps, rate):
    frames = panned(photo, [0.5 * i for i in range(int(4 * fps) + 1)])
    _, choice, _ = choose(frames, fps=fps, rate_hz=rate)
    gaps_s = np.diff(choice.index) / fps
    assert gaps_s.max() <= 1.0 / rate + 1e-9
    assert len(choice.index) >= 4 * rate  # about the rate, never far below it
    assert choice.index[0] == 0 and choice.index[-1] == len(frames) - 1


@pytest.mark.parametrize('rate', [0.5, 0.0, -1.0, float('nan'), float('inf')])
def test_a_rate_that_leaves_gaps_over_a_second_is_refused_naming_it(rate):
    from hac_ros.video.keyframes import check_rate

    with pytest.raises(ArgumentError, match='keyframe_rate'):
        check_rate(rate)
