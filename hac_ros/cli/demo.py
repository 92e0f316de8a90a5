"""``hac demo`` (``make demo``): replay, evaluate and plot the bundled sample recording."""
from __future__ import annotations

import argparse
from pathlib import Path

from hac_ros.demo import DEMO_RECORDING


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--recording', metavar='IN',
                        help=f'recording to use instead of {DEMO_RECORDING}')
    parser.add_argument('-o', '--out-dir', metavar='DIR', default='out',
                        help='where the results go (default out/; earlier demo results replaced)')


def run(args: argparse.Namespace) -> int:
    from hac_ros.demo import demo

    return demo(Path(args.out_dir), args.recording)
