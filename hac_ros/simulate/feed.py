"""Feed a :class:`Scenario` straight to a Calibrator, in the processing order (no recording).

The order is the recording's: by stamp; at one stamp the map first, then the pose, then the joints
(as ``write_recording`` logs them), so that this and a replay of the recording agree.
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import Any

from hac_ros.core.basics.outputs import Output
from hac_ros.core.calibrator import Calibrator

ORDER = {'map': 0, 'pose': 1, 'joints': 2}


def scenario_events(sc: Any) -> Iterator[tuple[int, str, tuple]]:
    """(stamp_ns, kind, payload) in processing order. Payloads: map (points_slam, frame_id);
    pose (R_wc, c, frame_id); joints (joints_cam (P, K, 3) in the scenario's joint layout, camera
    frame_id)."""
    events: list[tuple[int, str, tuple]] = [(m.stamp_ns, 'map', (m.points_slam, m.frame_id))
                                            for m in sc.maps]
    events += [(int(s), 'pose', (sc.slam_R_wc[i], sc.slam_c[i], sc.slam_frame_ids[i]))
               for i, s in enumerate(sc.pose_stamps_ns)]
    events += [(int(s), 'joints', (sc.joints_cam[k], sc.camera_frame))
               for k, s in enumerate(sc.joints_stamps_ns)]
    events.sort(key=lambda e: (e[0], ORDER[e[1]]))
    return iter(events)


def feed_events(cal: Calibrator, events: Iterable[tuple[int, str, tuple]]) -> list[Output]:
    """Events (stamp_ns, kind, payload), as :func:`scenario_events` gives them, into ``cal``;
    its outputs (not flushed)."""
    outs: list[Output] = []
    for stamp, kind, payload in events:
        if kind == 'map':
            outs += cal.add_map(stamp, *payload)
        elif kind == 'pose':
            outs += cal.add_pose(stamp, *payload)
        else:
            outs += cal.add_joints(stamp, *payload)
    return outs


def feed_scenario(cal: Calibrator, sc: Any, camera_info: bool = True) -> list[Output]:
    """Every input of the scenario into ``cal``; returns all outputs (flushed at the end)."""
    outs: list[Output] = []
    if camera_info:
        outs += cal.add_camera_info(sc.K, sc.width, sc.height)
    return outs + feed_events(cal, scenario_events(sc)) + cal.flush()
