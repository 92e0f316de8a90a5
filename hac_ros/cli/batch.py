"""``hac batch IN... -o DIR``: calibrate many recordings in parallel (a process pool, or Ray)."""
from __future__ import annotations

import argparse

from hac_ros.cli import add_mode_and_params, show
from hac_ros.files.params_file import load_params


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('inputs', metavar='IN', nargs='+',
                        help='input recordings (rosbag2 directories, .mcap, .db3 or ROS 1 .bag); '
                        'each is replayed into DIR/<its name without .mcap/.db3/.bag>')
    parser.add_argument('-o', '--output', metavar='DIR', required=True,
                        help='output directory: one recording per input, logs/, summary.csv, '
                        'summary.md')
    parser.add_argument('--workers', metavar='N', type=int,
                        help='recordings calibrated at once (default: the cores this process may '
                        'use; with --ray ADDRESS the cluster\'s CPUs decide)')
    parser.add_argument('--ray', metavar='ADDRESS',
                        help='each recording a Ray task: "local" starts a Ray on this machine, '
                        'HOST:PORT (or ray://HOST:PORT, auto) joins a cluster; needs '
                        'pip install hac_ros[cluster]')
    parser.add_argument('--resume', action='store_true',
                        help='skip inputs whose output is complete for the same input, parameters '
                        'and mode; redo the others')
    add_mode_and_params(parser, 'offline (default) or online, as hac replay',
                        'the node\'s parameters file (hac_node: ros__parameters:), for every '
                        'recording; the SLAM pose type is read from each recording')


def run(args: argparse.Namespace) -> int:
    from hac_ros.batch.runner import batch
    from hac_ros.cli.terminal import progress_bar

    result = batch(args.inputs, args.output, load_params(args.params), mode=args.mode,
                   workers=args.workers, ray=args.ray, resume=args.resume,
                   progress=progress_bar('rec', leave=True))
    show(result.text())
    if any(row.error for row in result.rows):
        show('  (--resume redoes what failed and keeps what is complete)')
    return result.exit_code
