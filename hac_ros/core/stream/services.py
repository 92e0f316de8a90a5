"""``~/reset`` and ``~/freeze`` (docs/node.md, "Services") as the calibrator takes them.

A request is queued by the shell and taken at the next accepted SLAM pose, so the same requests at
the same stamps give the same outputs online and replayed. :class:`ServiceRequests` keeps the
queue, the counts (``/diagnostics``: ``service.<name>``) and the held scale of ``~/freeze``; the
calibrator carries out what it returns (a new segment for ``reset``, a fresh estimator window for
``release``). Scales are metres per SLAM unit.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterator

from hac_ros.core.basics.outputs import NoticeOut


class ServiceRequests:
    """The queue of service requests and the ``~/freeze`` state.

    ``held``: the held scale (published while frozen, and after the release until a fresh window
    converges; None when nothing is held); ``holding``: frozen now (samples are counted in
    ``samples``, not used, and nothing expires).
    """

    def __init__(self) -> None:
        self.queue: list[tuple[str, bool]] = []
        self.counts: Counter[str] = Counter()  # requests taken, by name
        self.held: float | None = None
        self.holding = False
        self.samples = 0  # samples taken while frozen

    def request(self, name: str, value: bool = True) -> None:
        """``reset`` or ``freeze`` (value: hold or release), for the next SLAM pose."""
        self.queue.append((name, bool(value)))

    def scale(self, estimate: float | None) -> float | None:
        """The scale in use given the estimator's (None before it converges): the held one while
        frozen, or while a released window converges."""
        return self.held if self.holding or estimate is None else estimate

    def rescale(self, factor: float) -> None:
        """The map changed its scale: a held scale follows it (``factor``: new over old)."""
        if self.held is not None:
            self.held *= factor

    def clear(self) -> None:
        """A new segment: a held scale belongs to the old one."""
        self.held, self.holding = None, False

    def take(self, stamp_ns: int, published: Callable[[], float | None]
             ) -> Iterator[tuple[str, NoticeOut]]:
        """The queued requests in order: (action for the calibrator: ``reset``, ``release`` or
        ``''``, its notice). ``published``: the scale published now, the one a freeze holds."""
        requests, self.queue = self.queue, []
        for name, value in requests:
            self.counts[f'{name}_{str(value).lower()}' if name == 'freeze' else name] += 1
            if name == 'reset':
                yield 'reset', NoticeOut(stamp_ns, 'service_reset', 'new segment requested '
                                         '(~/reset): map and ground normal kept', 'info')
            elif value and not self.holding:
                self.held = published()
                self.holding = self.held is not None
                yield '', NoticeOut(stamp_ns, 'service_freeze', 'scale frozen (~/freeze): held '
                                    f'at {self.held}', 'info')
            elif not value and self.holding:
                self.holding = False
                yield 'release', NoticeOut(stamp_ns, 'service_freeze', 'scale released (~/freeze '
                                           'false): a fresh window converges', 'info')
