"""hac_node's intake under load: what it drops, what it coalesces, how far behind it says it is.

The rules are tested on the inbox itself with the arrival times given (no wall-clock race), and
over DDS on a live node made busy by holding its calibrator's lock from the test (the processing
thread waits, the executor keeps receiving): what a slow machine or a 1 kHz pose stream does to
it, made certain rather than hoped for.
"""
from __future__ import annotations

import re
import time
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from scenes import walking_scene
from test_node import PATIENCE_S, TYPES, harness, wait_for  # noqa: F401

from hac_ros.core.basics.numeric import NS
from hac_ros.core.rules.health import OK, WARN
from hac_ros.core.rules.params import HacParams
from hac_ros.ros.intake import STARTUP_FRAMES, Inbox, header_stamp_ns
from hac_ros.ros.liveness import Liveness
from msg_adapters import joints_to_pose_array, rt_to_pose_stamped, stamp_to_ns, xyz_to_cloud

MS = 1_000_000  # ns


def drain(inbox: Inbox) -> tuple[list[tuple[str, Any]], list[Any], list[Any]]:
    """Everything waiting, taken in order: (kind, data) of each item, the data of the joints
    frames dropped and of the poses coalesced meanwhile."""
    taken, dropped, coalesced = [], [], []
    while inbox.counts().waiting:
        took = inbox.get()
        assert took.item is not None
        taken.append((took.item.kind, took.item.data))
        dropped += [item.data for item in took.dropped]
        coalesced += [item.data for item in took.coalesced]
        inbox.done(took.item)
    return taken, dropped, coalesced


# ================================================================================ joints frames
def test_a_burst_the_node_catches_up_with_is_kept_and_a_slow_node_still_drops():
    """Frames every 33 ms, then ten at once (a publisher that stalled and caught up). A node that
    takes 2 ms a frame processes the ten within two input periods: none is dropped. One that
    takes a second a frame keeps joints_backlog_max (2) waiting and drops the oldest."""
    for cost_s, kept in ((0.002, 10), (1.0, 2)):
        inbox = Inbox(backlog_max=2)
        for k in range(8):  # the input period, measured from the arrivals: 33 ms
            inbox.put('joints', ('paced', k), arrived_s=100.0 + 0.033 * k)
            inbox.get()
        inbox.frame_cost_s = cost_s  # as the processing thread measures it
        for k in range(10):
            inbox.put('joints', ('burst', k), arrived_s=100.3 + 1e-5 * k)
        taken, dropped, _ = drain(inbox)
        assert [data for _, data in taken] == [('burst', k) for k in range(10 - kept, 10)]
        assert dropped == [('burst', k) for k in range(10 - kept)]
        counts = inbox.counts()
        assert counts.received['joints'] == 18 and counts.dropped == 10 - kept


def test_before_anything_is_measured_a_start_up_burst_waits():
    """No processing time measured yet (the node still making its first outputs): a burst of
    frames waits, up to STARTUP_FRAMES; beyond, the oldest are dropped."""
    inbox = Inbox(backlog_max=2)
    for k in range(STARTUP_FRAMES + 5):
        inbox.put('joints', k, arrived_s=1e-4 * k)
    taken, dropped, _ = drain(inbox)
    assert [data for _, data in taken] == list(range(5, STARTUP_FRAMES + 5))
    assert dropped == [0, 1, 2, 3, 4]


# ================================================================================ poses
def stamped_pose(stamp_ns: int) -> bytes:
    """CDR bytes with a header stamp, as a PoseStamped's begin (the inbox reads only that)."""
    return b'\x00\x01\x00\x00' + int(stamp_ns // NS).to_bytes(4, 'little', signed=True) \
        + int(stamp_ns % NS).to_bytes(4, 'little') + bytes(60)


def test_the_header_stamp_is_read_from_the_bytes_of_either_byte_order():
    assert header_stamp_ns(stamped_pose(12 * NS + 345)) == 12 * NS + 345
    big = b'\x00\x00\x00\x00' + (7).to_bytes(4, 'big') + (9).to_bytes(4, 'big')
    assert header_stamp_ns(big) == 7 * NS + 9
    assert header_stamp_ns(b'\x07\x07') is None and header_stamp_ns(b'\x00\x01\x00\x00') is None


def test_a_1khz_pose_stream_is_thinned_to_pose_coalesce_s_apart():
    """1 kHz poses, whether or not the node keeps up: it processes one every 10 ms of stamp time
    (pose_coalesce_s), the newest, and the pose just before each joints frame; every other is
    coalesced and counted. Nothing is lost from view: the gaps between the poses processed are at
    most 10 ms."""
    inbox = Inbox(backlog_max=100, coalesce_s=0.01)
    frames = {33, 66, 99}  # a joints frame arrives after the pose of these milliseconds
    for ms in range(120):
        stamp = NS + ms * MS
        inbox.put('pose', stamp, stamp_ns=header_stamp_ns(stamped_pose(stamp)))
        if ms in frames:
            inbox.put('joints', stamp)
    taken, dropped, coalesced = drain(inbox)
    poses = [data for kind, data in taken if kind == 'pose']
    assert not dropped and [data for kind, data in taken if kind == 'joints'] == \
        [NS + ms * MS for ms in sorted(frames)]
    assert len(poses) + len(coalesced) == 120 and inbox.counts().coalesced == len(coalesced)
    assert poses[0] == NS and poses[-1] == NS + 119 * MS  # the first and the newest
    assert all(NS + ms * MS in poses for ms in frames)  # the pose before each joints frame
    gaps = np.diff(poses)
    assert gaps.max() <= 10 * MS and len(poses) <= 120 // 10 + len(frames) + 2


@pytest.mark.parametrize('period_ms', [33, 20])
def test_poses_at_camera_rates_are_never_coalesced(period_ms):
    """30 and 50 Hz poses waiting behind a stuck processing thread: all of them are processed
    (their stamps are further apart than pose_coalesce_s), as the replay processes them."""
    inbox = Inbox(backlog_max=2, coalesce_s=0.01)
    stamps = [NS + k * period_ms * MS for k in range(50)]
    for stamp in stamps:
        inbox.put('pose', stamp, stamp_ns=stamp)
    taken, _, coalesced = drain(inbox)
    assert [data for _, data in taken] == stamps and not coalesced


def test_poses_out_of_order_or_back_in_time_are_not_coalesced():
    """The calibrator judges stamps that go back (a late pose, a recording played again): the
    inbox coalesces only poses whose stamps increase."""
    inbox = Inbox(backlog_max=2, coalesce_s=0.01)
    stamps = [NS, NS + MS, NS + 2 * MS, NS + MS // 2, NS + 3 * MS, NS - 30 * NS, NS - 30 * NS + MS]
    for stamp in stamps:
        inbox.put('pose', stamp, stamp_ns=stamp)
    taken, _, coalesced = drain(inbox)
    assert coalesced == [NS + MS]  # the only pose between two later ones within 10 ms
    assert [data for _, data in taken] == [s for s in stamps if s != NS + MS]


def test_pose_coalesce_s_zero_never_coalesces():
    inbox = Inbox(backlog_max=2, coalesce_s=0.0)
    for ms in range(30):
        inbox.put('pose', ms, stamp_ns=NS + ms * MS)
    assert len(drain(inbox)[0]) == 30


# ================================================================================ maps
def test_a_map_supersedes_the_maps_waiting_that_no_joints_frame_waits_behind():
    """A node behind its maps (maps every 100 ms of wall time on a slow machine): each new map
    replaces the waiting maps no joints frame needs, keeping the poses and the frames in order;
    a map a waiting joints frame follows is kept (that frame is measured against it). Without
    ``supersede`` (cloud_mode accumulate, or a cloud that could not be built: its rejection is
    counted by the calibrator) a map waits and is not replaced. Nothing is lost from the count."""
    inbox = Inbox(backlog_max=100)
    for k in range(5):  # maps and poses only: each map replaces the one before
        inbox.put('pose', ('pose', k), stamp_ns=k * NS)
        inbox.put('map', ('map', k), supersede=True)
    inbox.put('joints', 'frame')  # measured against map 4
    inbox.put('pose', ('pose', 5), stamp_ns=5 * NS)
    inbox.put('map', ('map', 5), supersede=True)
    inbox.put('map', ('map', 6), supersede=True)  # replaces map 5, not map 4
    taken, _, _ = drain(inbox)
    assert taken == [('pose', ('pose', 0)), ('pose', ('pose', 1)), ('pose', ('pose', 2)),
                     ('pose', ('pose', 3)), ('pose', ('pose', 4)), ('map', ('map', 4)),
                     ('joints', 'frame'), ('pose', ('pose', 5)), ('map', ('map', 6))]
    counts = inbox.counts()
    assert counts.superseded == 5
    assert counts.received['map'] == counts.processed['map'] + counts.superseded == 7
    accumulating = Inbox(backlog_max=100)
    for k in range(3):
        accumulating.put('map', k)
    assert [data for _, data in drain(accumulating)[0]] == [0, 1, 2]
    assert accumulating.counts().superseded == 0
    rejected = Inbox(backlog_max=100)
    rejected.put('map', 'built', supersede=True)
    rejected.put('map', 'empty cloud')  # its rejection must reach the calibrator
    rejected.put('map', 'newer', supersede=True)
    assert [data for _, data in drain(rejected)[0]] == ['empty cloud', 'newer']


def test_a_node_slower_than_its_poses_keeps_one_pose_and_map_per_waiting_frame():
    """Poses, frames and maps played faster than the node processes them (an hour of stamps at
    10x): 3000 pose+frame pairs and a map every tenth, the node taking one item for every two
    that arrive. The frames beyond joints_backlog_max are dropped, and with each the poses and
    maps that waited for it: the queue stays short however long the run, the newest pose
    survives, the maps keep reaching the calibrator, and every input is accounted for
    (processed, waiting, dropped, coalesced or superseded)."""
    inbox = Inbox(backlog_max=2)
    inbox.frame_cost_s = 0.01  # against a 1 ms input period: every frame beyond 2 is dropped
    longest, taken = 0, []
    for k in range(3000):
        if k % 10 == 0:
            inbox.put('map', ('map', k), supersede=True, arrived_s=k * 1e-3)
        inbox.put('pose', ('pose', k), stamp_ns=k * 33 * MS, arrived_s=k * 1e-3)
        inbox.put('joints', ('joints', k), arrived_s=k * 1e-3)
        longest = max(longest, sum(inbox.counts().waiting.values()))
        if k % 2:
            took = inbox.get()
            assert took.item is not None
            taken.append((took.item.kind, took.item.data))
            inbox.done(took.item)
    assert longest <= 8  # was 2000 and growing: every pose, and a map every ten
    rest = drain(inbox)[0]
    assert rest[-2:] == [('pose', ('pose', 2999)), ('joints', ('joints', 2999))]
    order = [data[1] for _, data in taken + rest]
    assert order == sorted(order)  # arrival order kept
    counts = inbox.counts()
    for kind, left_out in (('joints', counts.dropped), ('pose', counts.coalesced),
                           ('map', counts.superseded)):
        assert counts.received[kind] == counts.processed[kind] + left_out
    assert counts.processed['map'] >= 100 and counts.processed['pose'] >= 1000


# ================================================================================ lag
def test_the_lag_is_from_the_oldest_input_waiting_and_warns_over_latency_warn_s():
    """How far behind the node is: now minus the arrival of the oldest input not yet processed,
    poses included (the item in hand too). Over latency_warn_s: WARN latency, saying by how
    much; nothing waiting: no lag."""
    inbox = Inbox(backlog_max=2)
    assert inbox.oldest_arrival_s() is None
    now = time.monotonic()
    inbox.put('pose', 1, stamp_ns=NS, arrived_s=now - 0.75)
    inbox.put('joints', 1, arrived_s=now - 0.5)
    assert inbox.oldest_arrival_s() == now - 0.75
    took = inbox.get()  # in hand: still not processed
    assert inbox.oldest_arrival_s() == now - 0.75
    inbox.done(took.item)
    assert inbox.oldest_arrival_s() == now - 0.5
    params = HacParams(latency_warn_s=0.1)
    found, values = Liveness().findings(params, lag_s=0.75)
    assert [(f.reason, f.level) for f in found] == [('latency', WARN)]
    assert 'behind by 750 ms' in found[0].text and dict(values)['lag_ms'] == '750.0'
    assert Liveness().findings(params, lag_s=0.05)[0] == []


# ================================================================================ over DDS
def khz_walk(seconds: float) -> tuple[Any, list[tuple[str, int, Any]]]:
    """A walk seen by a SLAM that publishes poses at 1 kHz and an HMR model at 30 Hz (the pose of
    each joints stamp among them): the scene, and (kind, stamp, (R, c) or joints) in the order
    they are published, each frame's joints after its pose."""
    frames = int(seconds * 30) + 1
    scene = walking_scene(frames=frames, rate=30.0, stride=0.05)
    frame_ns = [NS + t * 33 * MS for t in range(frames)]
    R, c = scene.R_wc_slam, scene.c_slam
    events: list[tuple[str, int, Any]] = []
    for ms in range(0, 33 * (frames - 1) + 1):
        stamp = NS + ms * MS
        t = ms / 33.0
        k = min(int(t), frames - 2)
        position = c[k] + (t - k) * (c[k + 1] - c[k])  # linear between the frames' poses
        events.append(('pose', stamp, (R[k], position)))
        if ms % 33 == 0:
            events.append(('joints', stamp, scene.joints_cam[ms // 33]))
    assert [s for kind, s, _ in events if kind == 'joints'] == frame_ns
    return scene, events


def statuses(h: Any) -> list[tuple[int, str, dict[str, str]]]:
    out = []
    for _, msg in list(h.received['/diagnostics']):
        for status in msg.status:
            level = status.level
            level = level[0] if isinstance(level, (bytes, bytearray)) else int(level)
            out.append((level, status.message, {kv.key: kv.value for kv in status.values}))
    return out


def test_a_busy_node_coalesces_1khz_poses_says_it_is_behind_and_catches_up(harness):
    """1 kHz SLAM poses and 30 Hz joints into a node whose processing thread is held (the test
    holds its calibrator's lock, as a long computation would) until the oldest input has waited
    half a second: the poses waiting are coalesced to 10 ms apart (counted), no joints frame is
    lost, the first status after says WARN latency with the lag, none says OK while behind, the
    node catches up, and no /hac/odometry is published for a coalesced pose."""
    h = harness(min_samples=5, stale_after_s=60.0, log_period_s=0.0)
    scene, events = khz_walk(2.0)
    cloud = xyz_to_cloud(scene.floor_points_slam(), NS, 'map', TYPES)
    h.publishers['cloud'].publish(cloud)
    assert wait_for(lambda: h.node.maps.done >= 1, PATIENCE_S)
    inbox = h.node._inbox
    published = {'pose': [], 'joints': []}
    start = time.monotonic()
    with h.node.lock:  # the processing thread waits here; the executor keeps receiving
        for kind, stamp, data in events:  # at 1 kHz, ten poses at a time
            if kind == 'pose' and (stamp - NS) % (10 * MS) == 0:
                time.sleep(max(0.0, start + (stamp - NS) / NS - time.monotonic()))
            if kind == 'pose':
                msg = rt_to_pose_stamped(data[0], data[1], stamp, 'map', TYPES)
            else:
                msg = joints_to_pose_array(data, stamp, 'camera', TYPES)
            h.publishers[kind].publish(msg)
            published[kind].append(stamp)
        assert wait_for(lambda: inbox.counts().received.get('pose', 0) == len(published['pose'])
                        and inbox.counts().received.get('joints', 0)
                        == len(published['joints']), PATIENCE_S), inbox.counts()
        oldest = inbox.oldest_arrival_s()
        assert oldest is not None
        time.sleep(max(0.0, oldest + 0.5 - time.monotonic()))  # half a second behind, at least
        held = inbox.counts()
    assert held.coalesced >= len(published['pose']) - 2000 // 10 - len(published['joints']) - 2
    assert wait_for(lambda: not inbox.counts().waiting and not inbox.counts().in_hand,
                    PATIENCE_S), 'the node did not catch up'
    counts = inbox.counts()
    assert counts.received['pose'] == counts.processed['pose'] + counts.coalesced
    assert counts.received['joints'] == counts.processed['joints'] == len(published['joints'])
    assert counts.dropped == 0
    last = published['pose'][-1]
    assert wait_for(lambda: h.received['/hac/odometry'] and stamp_to_ns(
        h.received['/hac/odometry'][-1][1].header.stamp) == last, PATIENCE_S)
    # no odometry for a coalesced pose: far fewer odometry messages than poses
    odometry = h.stamps('/hac/odometry')
    assert len(odometry) <= counts.processed['pose'] and len(odometry) < len(published['pose']) / 4
    assert len(h.received['/hac/human_joints']) > 0.8 * len(published['joints'])
    assert h.node.core.rejected['poses_coalesced'] == counts.coalesced
    seen = statuses(h)
    behind = [s for s in seen if 'latency' in s[2]['reasons'].split(',')]
    assert behind and behind[0][0] == WARN and 'behind by' in behind[0][1], seen[:3]
    assert float(behind[0][2]['lag_ms']) >= 500.0
    warn_ms = 1e3 * h.node.params.latency_warn_s
    assert not [s for s in seen if s[0] == OK and float(s[2]['lag_ms']) > warn_ms]
    line = h.node.story.status_line()
    assert (f"joints frames received {len(published['joints'])} = processed "
            f"{len(published['joints'])} + dropped 0 + waiting 0") in line, line
    assert f'coalesced {counts.coalesced}' in line


def test_the_first_drop_says_the_processing_time_against_the_input_period(harness, capfd):
    """Frames paced, then a node held while 40 more come: the frames it cannot catch up with
    are dropped, and the one warning says how long a frame takes against the input period, and
    what to do (fewer map points, a lower rate, fewer people; joints_backlog_max trades drops for
    latency)."""
    from test_node import scenario_recording

    walk = scenario_recording('walk', duration=6.0)
    h = harness(joints_backlog_max=2)
    half = len(walk.events) // 2
    h.play(walk.events[:half], frame_period_s=0.02)
    assert wait_for(lambda: h.node._inbox.counts().processed.get('joints', 0) >= 20, PATIENCE_S)
    with h.node.lock:
        for event in walk.events[half:half + 120]:
            h.publishers[event.kind].publish(event.msg)
        assert wait_for(lambda: h.node._inbox.counts().dropped > 0, PATIENCE_S)
    # the count goes up under the node's lock, the warning is logged just after it: wait for both
    err: list[str] = []

    def warned() -> bool:
        err.extend(capfd.readouterr().err.splitlines())
        return any('frames_dropped' in x for x in err)

    assert wait_for(lambda: h.node.core.rejected['frames_dropped'] > 0, PATIENCE_S)
    assert wait_for(warned, PATIENCE_S)
    line = next(x for x in err if 'frames_dropped' in x)
    assert line.startswith('[WARN]')
    assert re.search(r'processing takes [0-9.]+ ms per frame .* against an input period of '
                     r'[0-9.]+ ms', line), line
    assert 'what to do:' in line and 'index_max_points' in line and 'latency' in line


def test_the_arrival_is_when_the_middleware_received_the_message():
    """A message that waited 0.2 s for the executor arrived 0.2 s before its callback ran; no
    reception time, one ahead or a minute old (a clock changed): the callback's time."""
    from hac_ros.ros.intake import arrival_s

    before = time.monotonic()
    waited = arrival_s({'received_timestamp': time.time_ns() - 200_000_000})
    after = time.monotonic()
    # at least 0.2 s before the call (more only if this thread was held between the two clocks)
    assert before - 0.2 - 30.0 <= waited <= after - 0.2 + 1e-3
    for info in ({}, None, {'received_timestamp': 0},
                 {'received_timestamp': time.time_ns() + 10 * NS},
                 {'received_timestamp': time.time_ns() - 120 * NS}):
        start = time.monotonic()
        assert start <= arrival_s(info) <= time.monotonic()
