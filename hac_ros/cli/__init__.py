"""The ``hac`` command: ``simulate | replay | batch | eval | plot | demo | import | export | play |
lifecycle | people | video``.

Thin: each sub-command is a module of this package with ``add_arguments(parser)`` and
``run(args) -> int``, and only argument parsing in it; the work is done by the library modules
(:mod:`hac_ros.replay.replayer`, :mod:`hac_ros.evaluation.evaluate`, ...). Errors the user can fix
(:class:`~hac_ros.core.basics.errors.HacError`, :class:`~msg_adapters.MessageError`, and a file that
cannot be written: a read-only path, a full disk) print one line and exit 2, leaving nothing
partial. SIGINT (Ctrl-C), SIGTERM and SIGHUP (``timeout``, systemd, Slurm, a closed terminal) all
end a command the same way: what it was writing is removed, one line, exit 128 + the signal's
number (130, 143, 129). What the library logs is shown on stderr (:mod:`hac_ros.cli.terminal`).

The library knows nothing of flags: its errors name function arguments and parameters
(:class:`~hac_ros.core.basics.errors.ArgumentError`), and this package says them as the
sub-command's options (``pose_type`` -> ``--pose-type``, :func:`option_names`) where the command has
one.
"""
from __future__ import annotations

import os
import signal
import sys

# A signal while the command is still starting (importing numpy and the sub-command's modules: a
# second or more on a busy machine) is held until main() ends the command with its one line. Only
# when this is the program (the ``hac`` script, ``python -m hac_ros.cli``), never when another
# program imports this package.
EARLY_SIGNALS: list[int] = []
if sys.argv and (sys.argv[0] == '-m' or os.path.basename(sys.argv[0]) == 'hac'):
    for _signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(_signum, lambda signum, frame: EARLY_SIGNALS.append(signum))

import argparse  # noqa: E402
import contextlib  # noqa: E402
import errno  # noqa: E402
import importlib  # noqa: E402
import threading  # noqa: E402
from collections.abc import Iterator, Sequence  # noqa: E402
from types import FrameType  # noqa: E402
from typing import TextIO  # noqa: E402

from hac_ros import __version__  # noqa: E402
from hac_ros.cli.terminal import terminal_logging  # noqa: E402
from hac_ros.core.basics.errors import ArgumentError, ArgumentText, HacError  # noqa: E402
from hac_ros.core.basics.printable import printable_lines  # noqa: E402
from hac_ros.recording.atomic import STOP_SIGNALS, Interrupted  # noqa: E402

# sub-command -> (module in this package, one-line help)
COMMANDS = {
    'simulate': ('simulate', 'make a recording with ground truth'),
    'replay': ('replay', 'calibrate a recording (same core and parameters as the node)'),
    'batch': ('batch', 'calibrate many recordings in parallel (a process pool, or Ray)'),
    'eval': ('evaluate', 'metrics of a replayed recording against ground truth'),
    'plot': ('plot', 'figures of a replayed recording'),
    'demo': ('demo', 'replay, evaluate and plot the bundled sample recording'),
    'import': ('import_files', 'make a recording from SLAM and HMR files (TUM, PLY, npz)'),
    'export': ('export', 'a replayed recording as numpy arrays (.npz)'),
    'recover': ('recover', 'the complete part of a recording cut off while it was written'),
    'play': ('play', 'publish a recording\'s input topics over DDS (drives hac_node)'),
    'lifecycle': ('lifecycle', 'take a lifecycle transition of a managed node (configure, ...)'),
    'people': ('people', 'metric people from a video or images (the [people] extra), for hac '
               'import'),
    'video': ('video', 'a metric trajectory, map and people from a video alone (the [video] '
              'extra)'),
}


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser; with ``only``, just that sub-command's module is imported (a fast start)."""
    parser = argparse.ArgumentParser(prog='hac', description='metric scale for monocular SLAM '
                                     'from the people in view: one sub-command per job')
    parser.add_argument('--version', action='version', version=f'hac_ros {__version__}')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for name, (module_name, help_text) in COMMANDS.items():
        sub_parser = sub.add_parser(name, help=help_text, description=help_text)
        if only is None or name == only:
            module = importlib.import_module(f'{__name__}.{module_name}')
            module.add_arguments(sub_parser)
            sub_parser.set_defaults(_run=module.run, _options=option_names(sub_parser))
    return parser


def option_names(parser: argparse.ArgumentParser) -> dict[str, str]:
    """Argument or parameter name -> the option that sets it (``pose_type`` -> ``--pose-type``):
    each optional argument's destination and its longest option string."""
    return {action.dest: max(action.option_strings, key=len)
            for action in parser._actions if action.option_strings and action.dest != 'help'}


def say(text: str, args: argparse.Namespace) -> str:
    """A library message for this command's user: arguments named as its options."""
    return text.naming(args._options) if isinstance(text, ArgumentText) else text


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    only = argv[0] if argv and argv[0] in COMMANDS else None
    command = f'hac {only}' if only else 'hac'
    with stop_on_signals():  # from the start: an early Ctrl-C is one line too
        try:
            if EARLY_SIGNALS:  # it came while the command was starting
                raise Interrupted(EARLY_SIGNALS[0])
            args = build_parser(only).parse_args(argv)
            with terminal_logging(args.command):
                return int(args._run(args) or 0)
        except KeyboardInterrupt as exc:  # Interrupted: SIGINT, SIGTERM or SIGHUP
            return interrupted(command, exc.signum if isinstance(exc, Interrupted)
                               else signal.SIGINT)
        except Exception as exc:
            signum = interruption(exc)
            if signum is not None:  # a signal, wrapped by the library it interrupted
                return interrupted(command, signum)
            reason = user_error(exc, args if 'args' in locals() else None)
            if reason is None:
                raise
            show(f'{command}: error: {reason}', sys.stderr)
            return 2


def show(text: object, file: TextIO | None = None) -> None:
    """Print ``text`` for the user (stdout, or ``file``): every character a terminal would obey
    rather than show escaped, line by line (:func:`~hac_ros.core.basics.printable.printable_lines`):
    what a command prints holds names and paths from recordings and files."""
    print(printable_lines(text), file=file if file is not None else sys.stdout, flush=True)


def interrupted(command: str, signum: int) -> int:
    """The one line of a command ended by ``signum``, and its exit code (128 + the signal)."""
    print(f'{command}: interrupted ({signal.Signals(signum).name}): nothing partial left behind',
          file=sys.stderr)
    return 128 + signum


def interruption(exc: BaseException) -> int | None:
    """The signal behind ``exc`` when a KeyboardInterrupt is in its chain (``__cause__`` or
    ``__context__``), else None: a signal that lands while a library runs its own code (a module
    being imported, a C extension initialising) can come back as that library's error, such as
    ``SystemError: initialization of ... raised unreported exception``."""
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        seen.add(id(cause))
        if isinstance(cause, KeyboardInterrupt):
            return cause.signum if isinstance(cause, Interrupted) else int(signal.SIGINT)
        cause = cause.__cause__ or cause.__context__
    return None


def user_error(exc: BaseException, args: argparse.Namespace | None) -> str | None:
    """One line for an error the user can fix: hac_ros's own (arguments named as this
    command's options) and msg_adapters', or a file that cannot be written or read (an OSError
    anywhere in the chain: a read-only path, a full disk, a missing permission). None for
    anything else (a bug: its traceback is shown)."""
    from msg_adapters import MessageError

    if isinstance(exc, ArgumentError) and args is not None:
        return say(exc.text, args)
    if isinstance(exc, (HacError, MessageError)):
        return str(exc)
    cause: BaseException | None = exc
    while cause is not None and not isinstance(cause, OSError):
        cause = cause.__cause__ or cause.__context__
    if cause is None:
        return None
    assert isinstance(cause, OSError)
    what = errno.errorcode.get(cause.errno or 0, '') if cause.errno else ''
    where = f': {cause.filename}' if cause.filename else ''
    text = cause.strerror or str(cause) or type(cause).__name__
    return f'{text}{where}' + (f' ({what})' if what else '')


@contextlib.contextmanager
def stop_on_signals() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP raise :class:`~hac_ros.recording.atomic.Interrupted` in the main
    thread: the first one only (the command is cleaning up after it; later ones are ignored).
    The previous handlers come back afterwards. Nothing changes off the main thread."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, frame: FrameType | None) -> None:
        for each in STOP_SIGNALS:
            signal.signal(each, signal.SIG_IGN)
        raise Interrupted(signum)

    previous = {each: signal.signal(each, stop) for each in STOP_SIGNALS}
    try:
        yield
    finally:
        for each, handler in previous.items():
            signal.signal(each, handler)


# ---------------------------------------------------------------- arguments several commands share
def add_output_recording(parser: argparse.ArgumentParser) -> None:
    """``-o OUT``: the recording a command creates, and ``--storage`` of it."""
    from hac_ros.recording.reader import STORAGES

    parser.add_argument('-o', '--output', metavar='OUT', required=True,
                        help='output recording to create (must not exist)')
    parser.add_argument('--storage', choices=STORAGES, default='mcap',
                        help='storage plugin of OUT (default mcap)')


def add_mode_and_params(parser: argparse.ArgumentParser, mode_help: str, params_help: str) -> None:
    """``--mode`` of the replay and ``--params FILE``, the node's parameters file."""
    from hac_ros.replay.replayer import MODES

    parser.add_argument('--mode', choices=MODES, default='offline', help=mode_help)
    add_params(parser, params_help)


def add_params(parser: argparse.ArgumentParser, params_help: str) -> None:
    """``--params FILE``: a parameters file as hac_node reads it."""
    parser.add_argument('--params', metavar='FILE', help=params_help)


def escape_help(text: str) -> str:
    """``text`` for an argparse help string, which %-formats it (a literal % must be %%)."""
    return text.replace('%', '%%')


if __name__ == '__main__':
    sys.exit(main())
