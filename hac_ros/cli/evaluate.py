"""``hac eval OUT --gt IN``: the metrics of a replayed recording against its ground truth."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from hac_ros.cli import add_params, show
from hac_ros.files.params_file import load_params


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('output', metavar='OUT', help='a recording written by hac replay')
    parser.add_argument('--gt', metavar='IN', required=True,
                        help='the recording with ground truth (/gt/camera_pose, /gt/human_joints, '
                        '/gt/scale), normally the replay\'s input')
    parser.add_argument('--json', metavar='F', help='also write the rows as JSON to F')
    parser.add_argument('--md', metavar='F', help='also write the table as Markdown to F')
    add_params(parser, 'the parameters file the replay used (for the reference rows; default: '
               'the defaults in the recording\'s joint layout)')
    parser.add_argument('--no-references', action='store_true',
                        help='skip the "no calibration" and "true scale" rows (they re-run '
                        'the core)')


def run(args: argparse.Namespace) -> int:
    from hac_ros.evaluation.evaluate import evaluate
    from hac_ros.replay.feeder import offline_run

    result = evaluate(args.output, args.gt, load_params(args.params) if args.params else None,
                      None if args.no_references else offline_run)
    show(result.text())
    if args.json:
        Path(args.json).write_text(json.dumps(result.as_dict(), indent=2) + '\n', encoding='utf-8')
    if args.md:
        Path(args.md).write_text(result.markdown() + '\n', encoding='utf-8')
    return 0
