"""``hac replay IN -o OUT``: calibrate a recording with the node's core and parameters."""
from __future__ import annotations

import argparse
import sys

from hac_ros.cli import add_mode_and_params, add_output_recording, show
from hac_ros.core.rules.params import POSE_MSGTYPES
from hac_ros.files.params_file import load_params

NOT_CALIBRATED = 3  # exit code: the replay ran but wrote no scale


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('input', metavar='IN', help='input recording (rosbag2 directory, .mcap, '
                        '.db3, or ROS 1 .bag); only read')
    add_output_recording(parser)
    add_mode_and_params(parser, 'offline (default): the best estimate using the whole recording; '
                        'online: exactly what hac_node publishes, frame by frame',
                        'the node\'s parameters file (hac_node: ros__parameters:)')
    parser.add_argument('--pose-topic', help='overrides pose_topic')
    parser.add_argument('--cloud-topic', help='overrides cloud_topic')
    parser.add_argument('--joints-topic', help='overrides joints_topic')
    parser.add_argument('--camera-info-topic', help='overrides camera_info_topic ("" = off)')
    parser.add_argument('--pose-type', choices=tuple(POSE_MSGTYPES),
                        help='the SLAM pose topic\'s type (default: read from the recording)')
    parser.add_argument('--copy-inputs', action='store_true',
                        help='also copy every topic of IN into OUT (so OUT alone can be evaluated)')
    parser.add_argument('--export-tum', metavar='DIR',
                        help='write camera_metric.tum, camera_slam.tum and camera_gt.tum (when the '
                        'recording has ground truth) into DIR, for evo')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')


def run(args: argparse.Namespace) -> int:
    from hac_ros.cli.terminal import progress_bar
    from hac_ros.replay.replayer import replay

    params = load_params(args.params, {
        'pose_topic': args.pose_topic, 'cloud_topic': args.cloud_topic,
        'joints_topic': args.joints_topic, 'camera_info_topic': args.camera_info_topic})
    summary = replay(args.input, args.output, params, mode=args.mode, storage=args.storage,
                     pose_type=args.pose_type,
                     copy_inputs=args.copy_inputs, export_tum=args.export_tum,
                     progress=None if args.no_progress else progress_bar('msg'))
    show(summary.text())
    if not summary.calibrated:  # a replay that calibrated nothing is not a success
        show(f'hac replay: {summary.why_not_calibrated()}', sys.stderr)
        return NOT_CALIBRATED
    return 0
