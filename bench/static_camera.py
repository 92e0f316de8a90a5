#!/usr/bin/env python3
"""A fixed camera from a video alone: vtest.avi (768 x 576, a static camera over a paved square)
through the people front end and hac_node's core with ``static_camera: true``, no SLAM, no map.

    python bench/static_camera.py [--step 4]

Every ``--step``-th frame goes through :class:`~hac_ros.people.frontend.PeopleFromImages` (the
default model: person_min_height_px 60) with an assumed camera (fx = fy = 700 px, principal point
at the centre, no distortion: the video's own is unknown), stamped i / 10 s, and into a
:class:`~hac_ros.core.calibrator.Calibrator` (``joint_layout: blazepose33``,
``static_camera: true``). Reported: the camera's height above the floor (the scale: the floor is
one SLAM unit below a fixed camera), its ± and the estimator's own σ, pitch and roll, the samples
and rejections; and each person's implied height (the median of their samples, people followed
across frames by :class:`~hac_ros.core.bodies.human_filter.PersonTracker` on their hips) and the spread
between people. The height scales with the assumed focal length.

Writes bench/results/static_camera.json.
"""
from __future__ import annotations

import argparse
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _people_scenes import video_frames
from _report import command_line, machine, write_json

from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.outputs import DiagnosticsOut, SampleOut
from hac_ros.core.bodies.human_filter import PersonTracker
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.layouts.blazepose33 import LAYOUT
from hac_ros.core.rules.params import HacParams

NAME = 'static_camera'
FOCAL_PX = 700.0
FPS = 10.0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--step', type=int, default=4, help='every STEP-th frame (default 4)')
    parser.add_argument('--no-write', action='store_true')
    args = parser.parse_args(argv)
    from hac_ros.people.frontend import PeopleFromImages
    from hac_ros.people.lifting import Camera
    from hac_ros.people.model import PoseModel

    people = PeopleFromImages(PoseModel())
    calibrator = Calibrator(HacParams(joint_layout='blazepose33', static_camera=True))
    camera = None
    tracker = PersonTracker()
    heights: dict[int, list[float]] = defaultdict(list)
    outs = []
    frames = 0
    try:
        for index, rgb in video_frames(args.step):
            if camera is None:
                height, width = rgb.shape[:2]
                K = np.array([[FOCAL_PX, 0, width / 2], [0, FOCAL_PX, height / 2], [0, 0, 1.0]])
                camera = Camera(K=K, width=width, height=height)
                calibrator.add_camera_info(K, width, height)
            stamp = int(index / FPS * NS)
            joints = people.process(rgb, camera).joints_cam
            frames += 1
            out = calibrator.add_joints(stamp, joints, 'camera')
            outs += out
            roots = LAYOUT.root_of(joints) if len(joints) else np.zeros((0, 3))
            ids = tracker.follow(stamp, roots)  # people followed by their hips
            for o in out:
                if isinstance(o, SampleOut) and o.accepted and 0 <= o.person < len(ids):
                    heights[ids[o.person]].append(o.scale)
        outs += calibrator.flush()
    finally:
        people.model.close()
    status = [o for o in outs if isinstance(o, DiagnosticsOut)][-1].status
    per_person = [float(np.median(h)) for h in heights.values() if len(h) >= 5]
    result = {
        'command': command_line('bench/static_camera.py', argv), 'machine': machine(),
        'frames': frames, 'step': args.step, 'focal_px': FOCAL_PX,
        'camera_height_m': status.camera_height_m, 'spread_m': status.spread,
        'spread_stat_m': status.spread_stat, 'pitch_deg': status.camera_pitch_deg,
        'roll_deg': status.camera_roll_deg, 'samples': status.samples,
        'converged': status.converged,
        'rejected': {k: v for k, v in status.rejected.items() if v},
        'people_with_5_samples': len(per_person),
        'person_heights_m': sorted(round(h, 3) for h in per_person),
        'person_spread_rel': float(np.std(per_person) / np.median(per_person))
        if per_person else float('nan'),
    }
    print(f"frames {frames} (every {args.step}th), samples {status.samples}, converged "
          f"{status.converged}: camera height {status.camera_height_m:.3f} m +- "
          f"{status.spread:.3f} (own {status.spread_stat:.3f}), pitch "
          f"{status.camera_pitch_deg:.1f} deg, roll {status.camera_roll_deg:.1f} deg")
    print(f"{len(per_person)} people with >= 5 samples: median "
          f"{np.median(per_person):.2f} m, std {np.std(per_person):.2f} m "
          f"({100 * result['person_spread_rel']:.1f} %), from {min(per_person):.2f} to "
          f"{max(per_person):.2f} m; rejected {result['rejected']}")
    if not args.no_write:
        write_json(NAME, result)
    return 0


if __name__ == '__main__':
    sys.exit(main())
