"""Progress, as the library reports it and a caller shows it: the replay, the batch runner,
``hac people`` and ``hac video`` advance a :class:`ProgressBar` the caller hands them, and draw
nothing themselves (the ``hac`` command passes a bar on a terminal: hac_ros.cli.terminal).
"""
from __future__ import annotations

import contextlib
from collections.abc import Callable
from contextlib import AbstractContextManager
from typing import Any, Protocol


class ProgressBar(Protocol):
    """What the library advances as it works: ``update(n)``, n more units done."""

    def update(self, n: int, /) -> Any: ...


# A progress display the caller provides: called with the total and a label, it gives a context
# whose value is a ProgressBar.
Progress = Callable[[int, str], AbstractContextManager[ProgressBar]]


def progress_pass(progress: Progress | None, total: int, label: str
                  ) -> AbstractContextManager[ProgressBar | None]:
    """The caller's progress display for one pass of ``total`` units, or nothing (None)."""
    return contextlib.nullcontext() if progress is None else progress(total, label)
