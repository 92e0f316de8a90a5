"""The ``hac`` command: ``simulate | replay | eval | plot | demo``.

Thin: each sub-command is a module with ``add_arguments(parser)`` and ``run(args) -> int``; this
file only parses and dispatches. Errors the user can fix (:class:`~hac_ros.core.errors.HacError`)
print one line and exit 2; Ctrl-C exits 130.
"""
from __future__ import annotations

import argparse
import importlib
import sys
from typing import Sequence

from hac_ros import __version__
from hac_ros.core.errors import HacError

# sub-command -> (module, one-line help)
COMMANDS = {
    'simulate': ('hac_ros.simulate.command', 'make a recording with ground truth'),
    'replay': ('hac_ros.replay', 'calibrate a recording (same core and parameters as the node)'),
    'eval': ('hac_ros.evaluate', 'metrics of a replayed recording against ground truth'),
    'plot': ('hac_ros.plots', 'figures of a replayed recording'),
    'demo': ('hac_ros.demo', 'replay, evaluate and plot the bundled sample recording'),
}


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser; with ``only``, just that sub-command's module is imported (a fast start)."""
    parser = argparse.ArgumentParser(prog='hac', description=__doc__.splitlines()[0])
    parser.add_argument('--version', action='version', version=f'hac_ros {__version__}')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for name, (module_name, help_text) in COMMANDS.items():
        sub_parser = sub.add_parser(name, help=help_text, description=help_text)
        if only is None or name == only:
            module = importlib.import_module(module_name)
            module.add_arguments(sub_parser)
            sub_parser.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    only = argv[0] if argv and argv[0] in COMMANDS else None
    parser = build_parser(only)
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print('hac: interrupted', file=sys.stderr)
        return 130
    except HacError as exc:
        print(f'hac {args.command}: error: {exc}', file=sys.stderr)
        return 2


if __name__ == '__main__':
    sys.exit(main())
