"""``hac import -o OUT --trajectory T --map M --joints J ...``: a recording from SLAM and HMR files.

(The module is not called ``import``: that is a Python keyword.)
"""
from __future__ import annotations

import argparse
import sys

from hac_ros.cli import add_output_recording, say, show
from hac_ros.core.layouts import LAYOUTS


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        'Write a rosbag2 recording with the input topics (/slam/pose, /slam/cloud, /hmr/joints, '
        'optionally /camera/camera_info and ground truth /gt/*) from the files a SLAM and an HMR '
        'pipeline write, for hac replay. Every stamp becomes integer nanoseconds by '
        'round(t x 1e9). Nothing is written unless every file is good (exit 2 with one line '
        'saying what is wrong); a warning when the trajectory is too sparse for the joints.')
    add_output_recording(parser)
    parser.add_argument('--trajectory', metavar='T', required=True,
                        help='TUM file: stamp tx ty tz qx qy qz qw, camera-to-map, SLAM units, '
                        'optical axes (x right, y down, z forward); # comments. Or a '
                        'DROID-SLAM-style .npz: traj (N, 7) camera-to-world tx ty tz qx qy qz qw '
                        'and tstamp (N,) seconds, or frame indices with --fps')
    parser.add_argument('--fps', type=float, metavar='HZ',
                        help='frame rate of a .npz trajectory\'s tstamp frame indices (seconds = '
                        'index / HZ; without tstamp, frame i at i / HZ)')
    parser.add_argument('--map', metavar='M', required=True,
                        help='map points in SLAM units, map frame: .ply (ASCII or binary, vertex '
                        'x y z), .npy (N, 3) or text (x y z per line); published once at the '
                        'first stamp')
    parser.add_argument('--joints', metavar='J', required=True,
                        help='.npz with stamps (T,) float seconds and joints (T, P, K, 3) metres '
                        'in the camera optical frame; an all-NaN (K, 3) block = that person is '
                        'absent (left out of the message; a frame with nobody is not written)')
    parser.add_argument('--camera', metavar='fx,fy,cx,cy,width,height',
                        help='pinhole intrinsics in pixels: /camera/camera_info at every pose '
                        'stamp')
    parser.add_argument('--gt-trajectory', metavar='G',
                        help='metric ground-truth TUM file (any fixed world frame): '
                        '/gt/camera_pose at the trajectory\'s stamps (interpolated within '
                        'interp_max_gap_s) and /gt/scale = the Sim(3) fit of T to G')
    parser.add_argument('--gt-joints', metavar='GJ',
                        help='.npz like J, metres in G\'s world frame: /gt/human_joints')
    parser.add_argument('--joint-layout', choices=LAYOUTS,
                        help='check K against the layout (not for custom) and write '
                        'OUT/params.yaml with joint_layout, for hac replay --params')
    parser.add_argument('--map-frame', default='map',
                        help='frame_id of /slam/pose and /slam/cloud (default map)')
    parser.add_argument('--camera-frame', default='camera_optical',
                        help='frame_id of /hmr/joints and /camera/camera_info (default '
                        'camera_optical)')
    parser.add_argument('--world-frame', default='world',
                        help='frame_id of the ground truth (default world)')


def run(args: argparse.Namespace) -> int:
    from hac_ros.files.importer import import_files

    result = import_files(args.output, args.trajectory, args.map, args.joints, camera=args.camera,
                          gt_trajectory=args.gt_trajectory, gt_joints=args.gt_joints,
                          joint_layout=args.joint_layout, storage=args.storage,
                          map_frame=args.map_frame, camera_frame=args.camera_frame,
                          world_frame=args.world_frame, fps=args.fps)
    show(result.text())
    if result.params_file is not None:
        show(f'  parameters: {result.params_file} (for hac replay --params)')
    for warning in result.warnings:
        show(f'hac import: warning: {say(warning, args)}', sys.stderr)
    return 0
