"""Outputs that appear whole or not at all: the one way hac_ros writes a result.

``with staged_output(target) as path:`` gives a path inside a temporary directory beside
``target`` (``.<name>.<random>.partial``); the caller writes a file or a directory (a rosbag2
recording) there, and at the end it is renamed to ``target``, on the same file system, in one
step. Missing parent directories of ``target`` are created. On an error or KeyboardInterrupt the
temporary directory (and the parents it created) is removed and ``target`` is left as it was.
SIGINT, SIGTERM and SIGHUP are held back while the temporary directory is made and while it is
renamed, so a signal never leaves one unknown to the clean-up. A read-only path or a full disk is a
HacError naming ``target`` (one line for the command line).

Recordings (replay, import, simulate), exported arrays, ``hac batch``'s summary and its completion
markers are all written this way.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from types import FrameType, TracebackType
from typing import Any

from hac_ros.core.basics.errors import HacError

# the signals that end a command (hac_ros.cli) and that signals_held holds back
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
PARTIAL_SUFFIX = '.partial'  # of the temporary directory; `hac batch` removes a killed attempt's


class staged_output:
    """The context manager of the module docstring.

    replace: an existing ``target`` file is replaced (atomically, ``os.replace``); otherwise
    ``target`` must not exist when the output is complete (HacError, and nothing is written).
    """

    def __init__(self, target: str | Path, replace: bool = False) -> None:
        self.target = Path(target)
        self.replace = replace
        self.tmp: Path | None = None
        self.created: list[Path] = []  # parent directories made here, innermost first

    def __enter__(self) -> Path:
        try:
            with signals_held():  # the directory made and its name kept, or neither
                parent = self.target.parent
                while not parent.exists():
                    self.created.append(parent)
                    parent = parent.parent
                self.target.parent.mkdir(parents=True, exist_ok=True)
                self.tmp = Path(tempfile.mkdtemp(prefix=f'.{self.target.name}.',
                                                 suffix=PARTIAL_SUFFIX, dir=self.target.parent))
            return self.tmp / self.target.name
        except OSError as exc:  # a read-only path, a full disk
            self._remove(done=False)
            raise HacError(f'cannot write {self.target}: {exc.strerror or exc}') from exc
        except BaseException:  # a signal held back until now
            self._remove(done=False)
            raise

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        assert self.tmp is not None
        done = False
        try:
            if exc_type is None:
                if not self.replace and (self.target.exists() or self.target.is_symlink()):
                    raise HacError(f'output {self.target} appeared while writing it: not '
                                   'overwritten')
                with signals_held():  # renamed and known to be: a signal now is too late
                    os.replace(self.tmp / self.target.name, self.target)
                    done = True
        finally:
            self._remove(done)
        if isinstance(exc, OSError):  # a full disk, a read-only path: one line naming it
            raise HacError(f'cannot write {self.target}: {exc.strerror or exc}') from exc

    def _remove(self, done: bool) -> None:
        """The temporary directory, and unless ``target`` appeared the parents made for it."""
        if self.tmp is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
        if not done:
            for directory in self.created:  # innermost first
                try:
                    directory.rmdir()
                except OSError:
                    break


class Interrupted(KeyboardInterrupt):
    """A signal that ends a command (SIGINT, SIGTERM, SIGHUP), raised where the command is so that
    everything it was writing is removed on the way out, as for Ctrl-C (every writer of hac_ros
    cleans up on KeyboardInterrupt). ``signum``: the signal's number."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP back for a few statements that must not be cut in two
    (a temporary file created and its name kept for the clean-up): the first one that came is
    handed to the handler that was in place when the block ends, where the caller's clean-up sees
    it.

    The signals are held in Python, not masked: ``pthread_sigmask`` masks the calling thread
    only, and the kernel then hands the signal to another thread (numpy's OpenBLAS workers), after
    which Python runs its handler in the main thread inside the block all the same. Python runs
    signal handlers in the main thread only, so off it there is nothing to hold."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    came: list[int] = []
    previous = {each: signal.signal(each, lambda signum, _frame: came.append(signum))
                for each in STOP_SIGNALS}
    try:
        yield
    finally:
        for each, handler in previous.items():
            signal.signal(each, handler if handler is not None else signal.SIG_DFL)
        if came:
            first = signal.Signals(came[0])
            _deliver(first, previous[first])


def _deliver(signum: int, handler: signal.Handlers | Callable[[int, FrameType | None], Any] | int
             | None) -> None:
    """Signal ``signum``, held back, to ``handler`` (the one in place before the block): called
    now when it is Python's, else sent to this process again (its default action, or nothing)."""
    if callable(handler):
        handler(signum, None)
    elif handler != signal.SIG_IGN:
        os.kill(os.getpid(), signum)
