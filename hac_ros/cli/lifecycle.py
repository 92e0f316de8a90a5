"""``hac lifecycle NODE TRANSITION``: drive a managed node without the ``ros2`` CLI.

The work is :mod:`hac_ros.ros.lifecycle_client`'s. Exit 0 when the node took the transition, 1
when it refused it (its own callback failed, e.g. an invalid parameter at configure), 2 when it
cannot be asked (no such managed node in this domain, a transition not available from its
state).
"""
from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from hac_ros.ros.lifecycle_client import TRANSITIONS, WAIT_S

    parser.description = (
        'Take one lifecycle transition of a managed node (hac_lifecycle_node or any other) over '
        'its lifecycle services, as `ros2 lifecycle set` does; shutdown is the shutdown '
        'transition of the node\'s current state.')
    parser.add_argument('node', metavar='NODE', help='the managed node, e.g. /hac_node')
    parser.add_argument('transition', metavar='TRANSITION', choices=TRANSITIONS,
                        help=', '.join(TRANSITIONS))
    parser.add_argument('--wait', type=float, default=WAIT_S, metavar='S',
                        help=f'wait up to S seconds for the node (default {WAIT_S:g})')


def run(args: argparse.Namespace) -> int:
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    from hac_ros.core.basics.errors import HacError
    from hac_ros.ros.lifecycle_client import change_state

    if not args.wait > 0:
        raise HacError(f'--wait {args.wait}: must be > 0')
    context = Context()
    rclpy.init(args=[], context=context, signal_handler_options=SignalHandlerOptions.NO)
    try:
        outcome = change_state(args.node, args.transition, context, args.wait)
    finally:
        rclpy.try_shutdown(context=context)
    print(f'hac lifecycle: {outcome.text()}')
    return 0 if outcome.success else 1
