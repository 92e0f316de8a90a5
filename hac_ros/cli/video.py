"""``hac video VIDEO|IMAGE_DIR -o OUT``: a metric camera trajectory, a metric map and the people in
the world from a video alone, on a CPU (the ``[video]`` extra: pycolmap, with ``[people]``)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hac_ros.cli import add_params, show
from hac_ros.people.params import PERSON_DETECTORS, PeopleParams
from hac_ros.video.keyframes import DEFAULT_MOTION

NOT_CALIBRATED = 3  # exit code, as hac replay's: OUT written, but no scale


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        'Keyframes of the video, the people in them (masked out of the features), pycolmap\'s '
        'structure from motion on the CPU, then hac import and hac replay in this process. OUT '
        'gets the recording made (recording/), the replay (replay/), camera_metric.tum and '
        'camera_slam.tum, people.npz (hac export), map_metric.ply, summary.txt, figures/ and '
        'the files hac import took (inputs/). '
        'The stages before the calibration are cached (an interrupted run resumes); OUT appears '
        'whole or not at all. Needs the [video] extra (docs/video.md).')
    parser.add_argument('source', metavar='VIDEO|IMAGE_DIR', help='a video file or a folder of '
                        'images (sorted by name) of one moving camera')
    parser.add_argument('-o', '--output', required=True, metavar='OUT',
                        help='the directory to write (must not exist)')
    parser.add_argument('--camera', metavar='fx,fy,cx,cy[,k1,k2,p1,p2]', default=None,
                        help='the intrinsics in pixels of the frames as they are (and plumb_bob '
                        'distortion), kept as given; without them the camera is self-calibrated '
                        'and a reconstruction that fails its gates is refused')
    parser.add_argument('--fps', type=float, default=None, metavar='HZ',
                        help='frames per second (default: the video\'s; a folder needs it)')
    parser.add_argument('--start', type=float, default=0.0, metavar='S',
                        help='the first frame\'s stamp in seconds (frame i at S + i / fps; '
                        'default 0), as hac people stamps it')
    parser.add_argument('--keyframe-rate', type=float, default=None, metavar='HZ',
                        help='keyframes per second, at least 1 (default: chosen by motion, and '
                        'never more than 1 s apart)')
    parser.add_argument('--keyframe-motion', type=float, default=DEFAULT_MOTION, metavar='SHARE',
                        help='the median image motion, a share of the width, that makes a '
                        f'keyframe (default {DEFAULT_MOTION:g})')
    parser.add_argument('--threads', type=int, default=0, metavar='N',
                        help='threads for the reconstruction (default 0: every core this '
                        'process may use)')
    parser.add_argument('--cache', metavar='DIR', default=None,
                        help='the cache of the stages (default $XDG_CACHE_HOME/hac_ros/video)')
    default = PeopleParams()
    parser.add_argument('--person-detector', choices=PERSON_DETECTORS,
                        default=default.person_detector,
                        help=f'as hac people\'s (default {default.person_detector})')
    add_params(parser, 'the replay\'s parameters file (hac_node: ros__parameters:; default: '
               'reference_mode floor_plane, docs/video.md); joint_layout is blazepose33')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')


def run(args: argparse.Namespace) -> int:
    from hac_ros.people import extra as people_extra
    from hac_ros.video import extra

    for missing, package, install in (
            (not people_extra.available(), people_extra.PACKAGE, people_extra.INSTALL),
            (not extra.available(), extra.PACKAGE, extra.INSTALL)):
        if missing:
            show(f'hac video: needs the [video] extra ({package}): {install}', sys.stderr)
            return 2
    from hac_ros.cli.terminal import progress_bar
    from hac_ros.files.params_file import load_params
    from hac_ros.video.pipeline import VideoOptions, video

    options = VideoOptions(camera=args.camera, fps=args.fps, start=args.start,
                           keyframe_rate=args.keyframe_rate,
                           keyframe_motion=args.keyframe_motion, threads=args.threads,
                           cache=Path(args.cache) if args.cache else None)
    result = video(args.source, args.output, options,
                   load_params(args.params) if args.params else None,
                   PeopleParams().replace(person_detector=args.person_detector),
                   progress=None if args.no_progress else progress_bar('step'))
    show(result.text())
    if result.replay is None or not result.replay.calibrated:
        why = result.replay.why_not_calibrated() if result.replay else 'nothing calibrated'
        show(f'hac video: {why}', sys.stderr)
        return NOT_CALIBRATED
    return 0
