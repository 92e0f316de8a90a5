"""``hac recover IN -o OUT.mcap``: the complete part of a recording cut off while it was
written."""
from __future__ import annotations

import argparse

from hac_ros.cli import show


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        'Keep the complete part of an MCAP recording that was cut off while it was written '
        '(power lost, the recorder killed, a full disk: no footer): every whole record before '
        'the cut, closed as a readable MCAP file that hac replay, hac play and the mcap tools '
        'read. The record the cut went through (at most one chunk of messages) is lost. IN is '
        'only read.')
    parser.add_argument('input', metavar='IN',
                        help='the cut-off .mcap file, or the rosbag2 directory holding it')
    parser.add_argument('-o', '--output', metavar='OUT.mcap', required=True,
                        help='the MCAP file to write (must not exist)')


def run(args: argparse.Namespace) -> int:
    from hac_ros.recording.recover import recover

    show(recover(args.input, args.output).text())
    return 0
