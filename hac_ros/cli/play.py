"""``hac play IN``: publish a recording's input topics over DDS, to drive ``hac_node``; or a video's
or a folder of images' frames as a camera (``camera/image_raw``, ``camera/camera_info``), to drive
``hac_people_node``.

The work is :class:`hac_ros.ros.player.Player`'s; this module parses the arguments and starts
rclpy without its signal handlers: SIGINT, SIGTERM and SIGHUP end ``hac play`` as every command
(:func:`hac_ros.cli.main`: one line, exit 128 + the signal's number). A signal cannot cut a
message in two: rclpy publishes it in one call, and the signal is seen between two.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from hac_ros.cli import show
from hac_ros.core.basics.errors import HacError

DEFAULT_FRAME_ID = 'camera_optical'  # hac_ros.ros.player's (not imported here: a fast --help)


def parse_remap(items: Sequence[str] | None) -> dict[str, str]:
    """``OLD:=NEW`` pairs (ROS's remapping syntax) -> {'/OLD': '/NEW'}; HacError naming --remap."""
    remap: dict[str, str] = {}
    for item in items or []:
        old, sep, new = item.partition(':=')
        if not sep or not old.strip() or not new.strip():
            raise HacError(f'--remap {item!r}: expected OLD:=NEW (e.g. /orb/pose:=/slam/pose)')
        old, new = old.strip(), new.strip()
        remap[old if old.startswith('/') else '/' + old] = new if new.startswith('/') else '/' + new
    return remap


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        'Publish a recording\'s input topics over DDS in log-time order, at real time or --rate, '
        'with the QoS hac_node expects (reliable; maps and /tf_static transient local): the way '
        'to drive hac_node without a ROS install. Default topics: /slam/pose, /slam/cloud, '
        '/hmr/joints, /camera/camera_info, /tf, /tf_static (those the recording holds). '
        'A video or a folder of images (with --camera) is played as a camera, as image_publisher '
        'does: /camera/image_raw (rgb8 Image; JPEG CompressedImage on '
        '/camera/image_raw/compressed with --compressed) and /camera/camera_info, reliable, frame '
        'i stamped --start + i / fps (needs OpenCV, the [people] extra).')
    parser.add_argument('input', metavar='IN', help='recording (rosbag2 directory, .mcap, .db3, '
                        'or ROS 1 .bag), a video (a file OpenCV reads) or a folder of images '
                        '(without metadata.yaml; sorted by name); only read')
    parser.add_argument('--rate', type=float, default=1.0,
                        help='playback speed, a factor of real time (default 1)')
    parser.add_argument('--loop', action='store_true',
                        help='play again from the start at the end, until interrupted (a video\'s '
                        'stamps run on: the recording\'s start again)')
    parser.add_argument('--clock', type=float, nargs='?', const=40.0, default=0.0, metavar='HZ',
                        help='publish /clock with the playback time (at HZ between messages, '
                        'default 40), for nodes run with use_sim_time')
    parser.add_argument('--topics', nargs='+', metavar='TOPIC',
                        help='play these topics of IN instead of the input topics')
    parser.add_argument('--remap', nargs='+', metavar='OLD:=NEW', default=[],
                        help='publish topic OLD of IN as NEW (e.g. /orb/pose:=/slam/pose)')
    parser.add_argument('--wait', type=float, default=0.0, metavar='S',
                        help='wait up to S seconds for a subscriber on every topic before playing '
                        '(default 0: start at once)')
    camera = parser.add_argument_group('a video or a folder of images')
    camera.add_argument('--camera', metavar='fx,fy,cx,cy[,k1,k2,p1,p2]',
                        help='the intrinsics in pixels of the frames as they are (and plumb_bob '
                        'distortion); hac import\'s fx,fy,cx,cy,width,height too (the size must '
                        'be the frames\'). Needed for a video or a folder')
    camera.add_argument('--fps', type=float, default=None, metavar='HZ',
                        help='frames per second (default: the video\'s; a folder needs it)')
    camera.add_argument('--start', type=float, default=None, metavar='S',
                        help='the first frame\'s stamp in seconds (frame i at S + i / fps; '
                        'default 1: a ROS stamp of 0 means "not set"; hac people --start 1 '
                        'stamps alike)')
    camera.add_argument('--frame-id', default=None, metavar='FRAME',
                        help=f'the header frame_id (default {DEFAULT_FRAME_ID})')
    camera.add_argument('--compressed', action='store_true',
                        help='publish JPEG CompressedImage on /camera/image_raw/compressed '
                        'instead of Image on /camera/image_raw')


def run(args: argparse.Namespace) -> int:
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from hac_ros.ros.player import Player

    if not args.rate > 0:
        raise HacError(f'--rate {args.rate}: must be > 0')
    if not args.clock >= 0:
        raise HacError(f'--clock {args.clock}: must be >= 0')
    if not args.wait >= 0:
        raise HacError(f'--wait {args.wait}: must be >= 0')
    remap = parse_remap(args.remap)
    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
    try:
        with Player(args.input, rate=args.rate, loop=args.loop, clock_hz=args.clock,
                    topics=args.topics, remap=remap, wait_s=args.wait, camera=args.camera,
                    fps=args.fps, start=args.start, frame_id=args.frame_id,
                    compressed=args.compressed) as player:
            for reason in player.skipped:
                show(f'hac play: warning: not played: {reason}', sys.stderr)
            names = ', '.join(f'{t.name} -> {t.published_as}' if t.name != t.published_as
                              else t.name for t in player.plan)
            what = f' ({player.frames.describe()})' if player.frames is not None else ''
            show(f'hac play: {args.input}{what}: {names} at {args.rate:g}x'
                 + (' (loop)' if args.loop else ''))
            stats = player.run()
    finally:
        rclpy.try_shutdown()
    show(f'hac play: {stats.text()}')
    return 0
