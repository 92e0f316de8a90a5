"""``hac export OUT -o FILE.npz``: a replay's camera, world joints and scale as numpy arrays."""
from __future__ import annotations

import argparse

from hac_ros.cli import show
from hac_ros.core.layouts import LAYOUTS


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        'Write what hac replay wrote as a .npz: stamps_ns (T,) int ns; camera_position (T, 3) m '
        'and camera_quat_xyzw (T, 4) (camera to metric_frame) from /hac/pose; joints_world '
        '(T, P, K, 3) m in metric_frame, the /hac/human_joints message of the same stamp, '
        'NaN-padded to the most people in a frame; scale (T,) m per SLAM unit, the last /hac/scale '
        'at or before each stamp (NaN before the first). T = the stamps of /hac/pose; joints at '
        'other stamps are left out.')
    parser.add_argument('output', metavar='OUT', help='a recording written by hac replay')
    parser.add_argument('-o', '--npz', metavar='FILE.npz', required=True,
                        help='the file to write (must not exist)')
    parser.add_argument('--joint-layout', choices=LAYOUTS,
                        help='the layout the replay used (default: what OUT records, else smpl24)')


def run(args: argparse.Namespace) -> int:
    from hac_ros.files.exporter import export

    show(export(args.output, args.npz, args.joint_layout).text())
    return 0
