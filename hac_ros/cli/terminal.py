"""What the ``hac`` command shows on the terminal of what the library logs.

The library logs (module loggers under ``hac_ros``); a command shows those records at INFO and
above on stderr, one line each, ``hac COMMAND: LEVEL: message`` (``hac replay: warning: t+3.200 s
...``), written between the lines of a progress bar rather than through it. Nothing else of the
process is changed: other libraries' loggers and the streams are left as they are.

The progress bars are the command's too (:func:`progress_bar`): the library only advances the
display it is given (:data:`hac_ros.progress.Progress`) and draws none itself.
"""
from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from hac_ros.core.basics.printable import printable_lines

if TYPE_CHECKING:  # the command starts without importing the library
    from hac_ros.progress import Progress

PACKAGE_LOGGER = 'hac_ros'
LEVEL = logging.INFO


class TerminalHandler(logging.Handler):
    """A record as one line on stderr, written so that an active tqdm bar stays whole."""

    def emit(self, record: logging.LogRecord) -> None:
        from tqdm import tqdm

        try:
            tqdm.write(self.format(record), file=sys.stderr)
        except Exception:
            self.handleError(record)


class CommandFormatter(logging.Formatter):
    """``hac COMMAND: level: message`` (and the traceback, when a record carries one); the
    message's characters that a terminal would obey escaped
    (:mod:`hac_ros.core.basics.printable`)."""

    def __init__(self, command: str) -> None:
        super().__init__()
        self.command = command

    def formatMessage(self, record: logging.LogRecord) -> str:
        return (f'hac {self.command}: {record.levelname.lower()}: '
                f'{printable_lines(record.message)}')


@contextlib.contextmanager
def terminal_logging(command: str) -> Iterator[None]:
    """While the command runs, hac_ros' records at INFO and above on stderr; the package logger's
    handlers and level are restored afterwards (a command may run another: the demo simulates)."""
    package = logging.getLogger(PACKAGE_LOGGER)
    handlers, level = list(package.handlers), package.level
    handler = TerminalHandler()
    handler.setFormatter(CommandFormatter(command))
    for old in handlers:
        package.removeHandler(old)
    package.addHandler(handler)
    package.setLevel(LEVEL)
    try:
        yield
    finally:
        package.removeHandler(handler)
        for old in handlers:
            package.addHandler(old)
        package.setLevel(level)


def progress_bar(unit: str, leave: bool = False) -> Progress | None:
    """A tqdm bar on stderr per pass of the library (counting ``unit``), when stderr is a terminal;
    None otherwise (a pipe, a log file: no bar)."""
    if not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    def bar(total: int, label: str) -> Any:
        return tqdm(total=total, desc=label, unit=unit, file=sys.stderr, dynamic_ncols=True,
                    leave=leave, mininterval=0.2)
    return bar
