"""A node's log as a user reads it: its stderr, captured by pytest's capfd (in-process nodes)."""
from __future__ import annotations

import os
import time
from collections.abc import Callable

import pytest


class NodeLog:
    """The node's stderr so far, read through capfd without consuming it: capfd.readouterr()
    reads the capture file and then truncates it, so a line another thread writes in between
    is lost (seen: a node's warning missing from the log, once in four runs of this module).
    The capture file is read from its start instead (os.pread: the writers' offset stays)."""

    def __init__(self, capfd: pytest.CaptureFixture[str]) -> None:
        self.capfd = capfd
        self.text = ''
        capture = getattr(capfd, '_capture', None)  # pytest's FDCapture of stderr
        tmpfile = getattr(getattr(capture, 'err', None), 'tmpfile', None)
        self._fd = tmpfile.fileno() if tmpfile is not None else None

    def read(self) -> str:
        if self._fd is None:  # another pytest: the racy way
            self.text += self.capfd.readouterr().err
        else:
            size = os.fstat(self._fd).st_size
            self.text = os.pread(self._fd, size, 0).decode('utf-8', 'replace')
        return self.text

    def wait_for(self, predicate: Callable[[str], bool], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate(self.read()):
                return True
            time.sleep(0.02)
        return predicate(self.read())
