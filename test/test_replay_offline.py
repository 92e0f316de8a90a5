"""``hac replay``'s offline mode: the offline estimate (``offline_scale``) on samples with known
answers (a constant scale, drift, a slow wander, resets, few samples), and both modes replayed and
scored (offline at least as accurate as online, following a drift, one scale per segment); the
deferred outputs resolved with the schedule equal a second run with it."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scenes import NS, walking_scene
from test_replay import (  # noqa: F401 (walk_bag: a fixture)
    REPO,
    _assert_clean_error,
    hac,
    walk_bag,
    write_recording,
)

from hac_ros.core.offline import offline_scale
from hac_ros.core.rules.params import HacParams
from hac_ros.replay.replayer import replay


# ============================================================================ the offline estimate
def _stamps(seconds: float, rate: float = 30.0) -> np.ndarray:
    return (np.arange(0.0, seconds, 1.0 / rate) * NS).astype(np.int64) + NS


def test_offline_constant_scale_is_the_sequence_median_and_no_drift_is_seen_in_noise():
    rng = np.random.default_rng(1)
    stamps = _stamps(300.0)
    samples = 2.5 * (1.0 + 0.05 * rng.standard_t(3, len(stamps)))  # heavy-tailed noise
    schedule = offline_scale(stamps, samples, [], window_s=30.0, min_samples=10)
    (segment,) = schedule.segments
    assert not segment.drift
    # the median of the samples, each weighing the stamp time since the previous one kept, to a
    # tenth of a millisecond (the two whose noise made them negative are left out: their
    # neighbours weigh twice as much)
    kept = samples > 0
    weights = np.round(np.diff(stamps[kept], prepend=stamps[kept][0] - NS // 30) / 1e5) / 1e4
    order = np.argsort(samples[kept])
    cumulative = np.cumsum(weights[order])
    k = int(np.searchsorted(cumulative, 0.5 * cumulative[-1] * (1 - 1e-9)))
    middle = samples[kept][order]
    expected = (middle[k] + middle[k + 1]) / 2 if np.isclose(cumulative[k], 0.5 * cumulative[-1],
                                                             rtol=1e-9) else middle[k]
    assert segment.median == pytest.approx(float(expected), rel=1e-12)
    assert np.all(schedule.at(stamps) == segment.median)
    assert schedule(int(stamps[0]) - NS) == segment.median  # before and after the samples too
    assert schedule(int(stamps[-1]) + 100 * NS) == segment.median


def test_offline_follows_a_drifting_scale_including_the_ends():
    rng = np.random.default_rng(2)
    stamps = _stamps(120.0)
    truth = 2.0 + 0.6 * (stamps - stamps[0]) / (stamps[-1] - stamps[0])  # +30 % over two minutes
    samples = truth * (1.0 + 0.03 * rng.standard_normal(len(stamps)))
    schedule = offline_scale(stamps, samples, [], window_s=30.0, min_samples=10)
    assert schedule.segments[0].drift
    error = np.abs(schedule.at(stamps) / truth - 1.0)
    assert error.max() < 0.01  # a median would be 13 % off at the ends
    assert abs(np.median(samples) / truth[0] - 1.0) > 0.1


def test_offline_slow_wander_is_not_taken_for_drift():
    """A constant scale whose samples wander slowly (AR(1): 3 %, 10 s) as well as scatter: the
    smoother finds no evidence of drift, and the segment keeps its median (docs/replay.md)."""
    for seed in range(5):
        rng = np.random.default_rng(seed)
        stamps = _stamps(120.0)
        wander = np.zeros(len(stamps))
        a = np.exp(-1.0 / (30.0 * 10.0))
        for i in range(1, len(stamps)):
            wander[i] = a * wander[i - 1] + np.sqrt(1.0 - a * a) * rng.normal(0.0, 0.03)
        samples = 2.5 * np.exp(wander + rng.normal(0.0, 0.025, len(stamps)))
        schedule = offline_scale(stamps, samples, [], window_s=30.0, min_samples=10)
        assert not schedule.segments[0].drift, seed
        assert np.all(schedule.at(stamps) == np.median(samples)), seed


def test_offline_each_segment_between_resets_has_its_own_scale():
    rng = np.random.default_rng(3)
    stamps = _stamps(90.0)
    resets = [int(stamps[900]), int(stamps[2000])]
    truth = np.select([stamps < resets[0], stamps < resets[1]], [2.5, 0.4], 7.0)
    samples = truth * (1.0 + 0.03 * rng.standard_normal(len(stamps)))
    schedule = offline_scale(stamps, samples, resets, window_s=30.0, min_samples=10)
    assert [s.start_ns for s in schedule.segments][1:] == resets
    np.testing.assert_allclose(schedule.at(stamps), truth, rtol=0.005)
    assert schedule(resets[0] - 1) == pytest.approx(2.5, rel=0.005)
    assert schedule(resets[0]) == pytest.approx(0.4, rel=0.005)  # the reset stamp is the new map's


def test_offline_segment_with_few_samples_has_its_scale_flagged_and_fewer_than_3_none():
    """Fewer than min_samples but at least 3 samples: the segment gets its scale, flagged
    ``few`` (issue 43); fewer than 3: none."""
    stamps = _stamps(10.0)
    for last, scale in ((5, 2.0), (2, math.nan)):
        reset = int(stamps[-last])
        schedule = offline_scale(stamps, np.full(len(stamps), 2.0), [reset], window_s=30.0,
                                 min_samples=10)
        assert schedule(int(stamps[0])) == 2.0 and not schedule.segments[0].few
        assert schedule.segments[1].samples == last and schedule.segments[1].few
        assert schedule(reset) == scale or (math.isnan(scale) and math.isnan(schedule(reset)))


# ============================================================================ accuracy of the modes
BAGS = REPO / 'bags'
# markers do not change any estimate and cost time; the humans unfiltered (the scale is judged)
NO_MARKERS = HacParams(publish_markers=False, human_filter='none')


def _on_stamps(run, stamps):
    """A replayed run restricted to ``stamps`` (to compare two runs on the same frames)."""
    from hac_ros.recording.tracks import CameraTrack, JointsTrack, Replayed, ScaleTrack

    o, j, s = run.odometry, run.joints, run.scale
    ko, kj, ks = (np.isin(x.stamps_ns, stamps) for x in (o, j, s))
    return Replayed(CameraTrack(o.stamps_ns[ko], o.positions[ko], o.rotations[ko]),
                    JointsTrack(j.stamps_ns[kj], [x for x, k in zip(j.joints, kj) if k]),
                    ScaleTrack(s.stamps_ns[ks], s.values[ks]), run.diagnostics, run.samples)


def _both_modes(source: Path, tmp_path: Path, params: HacParams):
    from hac_ros.recording.tracks import read_output

    runs = {}
    for mode in ('online', 'offline'):
        replay(source, tmp_path / mode, params, mode=mode)
        runs[mode] = read_output(tmp_path / mode)
    return runs


def test_offline_is_at_least_as_accurate_as_online_on_walk(tmp_path):
    """On a clean walk (no HMR depth bias: the truth is the best scale there is)."""
    from hac_ros.evaluation.evaluate import row_metrics
    from hac_ros.recording.tracks import read_truth
    from hac_ros.simulate import make_scenario
    from hac_ros.simulate import write_recording as simulate_recording

    source = simulate_recording(make_scenario('walk', seed=0, duration=20.0, hmr_bias=0.0),
                                tmp_path / 'walk')
    runs = _both_modes(source, tmp_path, NO_MARKERS)
    truth = read_truth(source)
    online = row_metrics(runs['online'], truth)
    # on the frames the online mode publishes (it waits for min_samples), and on all of them
    offline_same = row_metrics(_on_stamps(runs['offline'], runs['online'].odometry.stamps_ns), truth)
    offline_all = row_metrics(runs['offline'], truth)
    assert offline_all['camera_frames'] > online['camera_frames']  # offline: every frame
    assert offline_all['scale_error_frames_pct'] <= online['scale_error_frames_pct'] + 0.1
    for row in (offline_same,):  # the other metrics on the frames both publish
        # both a fraction of a percent on a clean walk: no worse beyond 0.1 point of noise
        assert row['scale_error_frames_pct'] <= online['scale_error_frames_pct'] + 0.1
        # online converges once its own uncertainty is under 1 %, late in this 20 s walk, with
        # about the information offline has: W-MPJPE, a few 100-frame chunks, then follows the
        # fraction of a point of scale difference (0.1 point is ~6 mm here)
        assert row['w_mpjpe_mm'] <= online['w_mpjpe_mm'] + 10.0
        assert row['ate_m'] <= online['ate_m']
        # metrics that a scale off by a fraction of a percent moves only by noise (here the online
        # scale's wander can even offset the SLAM's own drift): no worse beyond that noise
        assert row['ate_s_m'] <= online['ate_s_m'] + 0.01  # 10 mm (0.1 point of 10 m)
        assert row['wa_mpjpe_mm'] <= online['wa_mpjpe_mm'] + 2.0  # 2 mm
        assert row['rte_pct'] <= online['rte_pct'] + 0.1  # 0.1 percentage point


def test_offline_follows_a_drifting_scale_where_online_lags(tmp_path):
    from hac_ros.evaluation.evaluate import row_metrics
    from hac_ros.recording.tracks import read_truth

    def truth(t: int) -> float:
        return 2.0 + 0.6 * t / 199  # +30 % over 20 s

    source = write_recording(tmp_path / 'drift', walking_scene(frames=200, stride=0.025),
                             cloud_every=10, scale_of=truth)
    params = NO_MARKERS.replace(window_s=6.0)
    runs = _both_modes(source, tmp_path, params)
    rows = {mode: row_metrics(run, read_truth(source)) for mode, run in runs.items()}
    # the constant median would be 6-13 % off at the ends; offline stays within the samples' own
    # bias (the cone median reads ~2 % low on this grazing floor, docs/method.md)
    assert rows['offline']['scale_error_frames_max_pct'] < 4.0
    assert rows['offline']['scale_error_frames_pct'] < 2.5
    assert rows['offline']['scale_error_frames_pct'] < rows['online']['scale_error_frames_pct']
    scales = runs['offline'].scale.values
    assert scales[-1] / scales[0] > 1.2  # it follows the drift (+30 %); a median would be flat


def test_offline_estimates_each_segment_of_a_reset_on_its_own(tmp_path):
    from hac_ros.recording.tracks import read_truth

    source = BAGS / 'reset_short'  # the SLAM re-initialises at 6 s with a new scale
    summary = replay(source, tmp_path / 'offline', NO_MARKERS)
    assert [r.cause for r in summary.resets] == ['map_frame']
    assert len(summary.offline.segments) == 2
    runs = _both_modes(source, tmp_path / 'both', NO_MARKERS)
    truth = read_truth(source)
    scale = runs['offline'].scale
    true_now = truth.scale.at(scale.stamps_ns)
    assert len(set(true_now.tolist())) == 2
    for value in set(true_now.tolist()):
        in_segment = true_now == value
        assert len(set(scale.values[in_segment].tolist())) == 1  # one estimate per segment ...
        assert scale.values[in_segment][0] == pytest.approx(value, rel=0.03)  # ... its own truth
    # online, neither 6 s segment is long enough for the estimate's uncertainty to fall under
    # converged_max_rel_sigma at 10 Hz: nothing metric is published (test_estimator.py)


@pytest.mark.parametrize('base', [False, True])
def test_deferred_outputs_resolved_with_the_schedule_equal_a_run_with_that_schedule(base):
    """The offline mode runs the calibrator once with its metric outputs deferred and resolves them
    with the schedule (hac_ros.core.stream.metric_stage): exactly what a second run with the schedule
    gives, across a SLAM reset (the anchor) and with a base frame (the odometry's base offset)."""
    from dataclasses import fields

    from hac_ros.core.basics.outputs import ResetOut, SampleOut
    from hac_ros.core.calibrator import Calibrator
    from hac_ros.core.stream.metric_stage import MetricStage
    from hac_ros.recording.reader import Recording
    from hac_ros.replay.feeder import CoreFeeder, InputTopics, offline_run

    params = HacParams(human_filter='none')  # offline, the humans are smoothed after resolving
    if base:
        params = params.replace(base_frame='base_link',
                                base_to_camera=[0.1, 0.0, 0.5, 0.5, -0.5, 0.5, -0.5])
    with Recording(BAGS / 'reset_short') as recording:
        calibrator = offline_run(recording, params)
        records = calibrator.journal
        samples = [o for o in records if isinstance(o, SampleOut) and o.accepted]
        resets = [o.stamp_ns for o in records if isinstance(o, ResetOut)]
        assert resets, 'the recording has a SLAM reset'
        schedule = offline_scale(np.array([s.stamp_ns for s in samples]),
                                 np.array([s.scale for s in samples]), resets, params.window_s,
                                 params.min_samples)
        # without the final planes: the direct run below aligns with the planes of the moment
        resolved = MetricStage(calibrator.metric.config).resolve(records, schedule)
        direct: list = []
        CoreFeeder(recording, InputTopics.check(recording, params),
                   Calibrator(params, schedule=schedule)).run(direct.extend)
    assert [type(o).__name__ for o in resolved] == [type(o).__name__ for o in direct]
    assert sum(type(o).__name__ == 'OdometryOut' for o in direct) > 100

    def same(a, b) -> bool:
        if hasattr(a, '__dataclass_fields__'):
            return all(same(getattr(a, f.name), getattr(b, f.name)) for f in fields(a))
        if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
            return a is not None and b is not None and np.array_equal(a, b, equal_nan=True)
        return a == b or (a != a and b != b)  # NaN == NaN here

    for a, b in zip(resolved, direct):
        assert same(a, b), [(f.name, getattr(a, f.name), getattr(b, f.name)) for f in fields(a)
                            if not same(getattr(a, f.name), getattr(b, f.name))]


def test_offline_odometry_covariance_is_finite_from_the_first_pose(tmp_path):
    """Offline, poses before the first sample are published with the segment's scale: their
    covariance takes the segment's standard error (never NaN)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    replay(BAGS / 'reset_short', tmp_path / 'out', NO_MARKERS)
    with AnyReader([tmp_path / 'out'], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        conns = [c for c in reader.connections if c.topic == '/hac/odometry']
        covariances = np.array([reader.deserialize(raw, conns[0].msgtype).pose.covariance
                                for _, _, raw in reader.messages(connections=conns)])
    assert len(covariances) > 300 and np.isfinite(covariances).all()
    assert (covariances[:, 0] > 1e-6).mean() > 0.9  # the scale's share on top of the floor


def test_a_corrupt_message_in_a_ros1_bag_is_a_clear_error(walk_bag, tmp_path):
    """A ROS 1 message that does not convert to ROS 2 CDR (here a truncated SLAM pose) stops the
    replay with a "corrupt" error naming the topic, and leaves no OUT."""
    from rosbags.convert import convert
    from rosbags.rosbag1 import Reader as Reader1
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.typesys import Stores, get_typestore

    noetic = get_typestore(Stores.ROS1_NOETIC)
    good = tmp_path / 'good.bag'
    convert([walk_bag], good, dst_storage='', dst_version=None, compress=None, compress_mode='',
            default_typestore=get_typestore(Stores.ROS2_JAZZY), typestore=noetic,
            exclude_topics=[], include_topics=[], exclude_msgtypes=[], include_msgtypes=[])
    bad = tmp_path / 'bad.bag'
    with Reader1(good) as reader, Writer1(bad) as writer:
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=noetic)
                 for c in reader.connections}
        poses = 0
        for conn, log_ns, raw in reader.messages():
            if conn.topic == '/slam/pose':
                poses += 1
                if poses == 20:
                    raw = raw[:10]  # truncated inside the header
            writer.write(conns[conn.id], log_ns, raw)
    result = hac('replay', str(bad), '-o', str(tmp_path / 'out'), '--mode', 'online')
    _assert_clean_error(result, 'corrupt')
    assert '/slam/pose' in result.stderr
    assert not (tmp_path / 'out').exists()
