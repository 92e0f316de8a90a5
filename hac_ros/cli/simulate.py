"""``hac simulate SCENARIO -o OUT``: make a recording with ground truth."""
from __future__ import annotations

import argparse
from pathlib import Path

from hac_ros.cli import add_output_recording, escape_help, show
from hac_ros.core.basics.errors import HacError
from hac_ros.core.layouts import DEFAULT
from hac_ros.core.rules.params import POSE_TYPES
from hac_ros.simulate.scenarios import SCENARIOS
from hac_ros.simulate.skeletons import simulated_layouts
from hac_ros.simulate.writer import POSE_FRAMES, POSE_SOURCES


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('scenario', choices=sorted(SCENARIOS), metavar='SCENARIO',
                        help=escape_help('; '.join(f'{k}: {v[1]}' for k, v in SCENARIOS.items())))
    add_output_recording(parser)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--duration', type=float, default=None,
                        help='seconds (default: the scenario\'s own)')
    parser.add_argument('--rate', type=float, default=30.0, help='camera rate, Hz')
    parser.add_argument('--pose-type', choices=POSE_TYPES, default='PoseStamped')
    parser.add_argument('--pose-frame', choices=POSE_FRAMES, default='optical',
                        help='base: the SLAM pose of a robot base (x forward, z up) 1.2 below and '
                        '0.3 behind the camera, as a wrapper reporting base_link writes it; '
                        'replay with pose_to_optical [0.3, 0, 1.2, -0.5, 0.5, -0.5, 0.5]')
    parser.add_argument('--pose-source', choices=POSE_SOURCES, default='topic',
                        help='tf: the SLAM pose only on /tf (map -> camera_optical, or -> '
                        'base_link with /tf_static base_link -> camera_optical); replay with '
                        'pose_source tf')
    parser.add_argument('--hmr-bias', type=float, default=None,
                        help=escape_help('HMR depth bias (0.03 = 3 % too far); default: random '
                                         'few %; 0: none'))
    parser.add_argument('--joint-layout', choices=simulated_layouts(), default=DEFAULT,
                        help='the HMR model\'s joints (replay with the same joint_layout)')
    parser.add_argument('--motion', type=Path, default=None,
                        help='real motion instead of the gait: a .npz with joints (T, 24, 3) '
                        'SMPL-24 metres, y up, floor at y = 0, and fps (CMU motion capture '
                        're-floored to SMPL\'s foot height)')


def run(args: argparse.Namespace) -> int:
    from hac_ros.simulate import make_scenario, write_recording

    output = Path(args.output)
    if output.exists():
        raise HacError(f'{args.output} exists: refusing to overwrite it')
    if args.motion is not None and not args.motion.is_file():
        raise HacError(f'motion file {args.motion} not found')
    sc = make_scenario(args.scenario, seed=args.seed, duration=args.duration, rate=args.rate,
                       hmr_bias=args.hmr_bias,
                       motion=str(args.motion) if args.motion is not None else None,
                       joint_layout=args.joint_layout)
    write_recording(sc, output, storage=args.storage, pose_type=args.pose_type,
                    pose_frame=args.pose_frame, pose_source=args.pose_source)
    show(f'{args.output}: {args.scenario}, {sc.duration_s:.1f} s, {len(sc.pose_stamps_ns)} poses, '
          f'{len(sc.joints_stamps_ns)} joints frames, {len(sc.maps)} maps, true scale '
          f'{sc.true_scale[0]:.4g} m/unit, HMR bias {sc.hmr_bias:+.3f}')
    return 0
