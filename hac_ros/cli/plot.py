"""``hac plot OUT [--gt IN] -o DIR``: figures of a replayed recording."""
from __future__ import annotations

import argparse

from hac_ros.cli import show


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('output', metavar='OUT', help='a recording written by hac replay')
    parser.add_argument('--gt', metavar='IN', help='the recording with ground truth (the replay\'s '
                        'input): adds the truth and the raw SLAM trajectory')
    parser.add_argument('-o', '--out-dir', metavar='DIR', required=True,
                        help='directory for the PNG figures (created; figures are replaced)')


def run(args: argparse.Namespace) -> int:
    from hac_ros.evaluation.plots import make_plots

    for name, path in make_plots(args.output, args.out_dir, args.gt).items():
        show(f'{name}: {path}')
    return 0
