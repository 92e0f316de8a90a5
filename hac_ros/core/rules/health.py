"""What ``/diagnostics`` says: the level of a status and the reasons for it.

A status is OK only when none of these holds (each a :class:`Finding` with its reason):

- the estimate has not converged (``not_converged``);
- the core reports a condition while it lasts (``Status.conditions``, reason -> text: for example
  ``slam_frozen``);
- a convention is suspect (``Status.suspects``, :mod:`hac_ros.core.bodies.convention_check`);
- the gravity-aligned metric frame fell back to the SLAM's axes (``alignment_slam``);
- since the previous status, inputs or outputs were refused, or time jumped, for a reason of
  :data:`WARN_WHEN_COUNTED` (``Status.rejected`` and ``Status.events``: frames dropped under
  overload, an implausible map, joints not in metres, a suppressed output, a jump in time, ...).

The node and the replay assess the same statuses the same way (one :class:`HealthMonitor` per
output stream, :class:`hac_ros.bridge.messages.OutputMessages`), so both write the same
``/diagnostics``. The node adds findings only it can make (its latency and backlog, no input on
its wall-clock timer) through ``extra``.

Every reason is an entry of :data:`hac_ros.core.rules.reasons.REASONS` (its kind, text, whether it
warns, its remedy): a condition is set as ``conditions[reason]`` while it holds; a counted reason
with ``warns`` makes the status WARN when it grew.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from hac_ros.core.basics.outputs import Status
from hac_ros.core.rules.params import FrameAlignment
from hac_ros.core.rules.reasons import warn_when_counted

# diagnostic_msgs/DiagnosticStatus levels
OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}

# Counted reasons (Status.rejected, Status.events) that make the status WARN when they grew since
# the previous status: reason -> what it means (hac_ros.core.rules.reasons)
WARN_WHEN_COUNTED = warn_when_counted()


@dataclass(frozen=True)
class Finding:
    """One reason why a status is not OK: ``reason`` (a key, as counted), ``text`` for a human,
    ``level`` (:data:`WARN`, :data:`ERROR` or :data:`STALE`)."""

    reason: str
    text: str
    level: int = WARN


@dataclass(frozen=True)
class Health:
    """The assessed status: its level, one-line message and findings (empty when OK)."""

    level: int
    message: str
    findings: tuple[Finding, ...]

    @property
    def reasons(self) -> list[str]:
        return [f.reason for f in self.findings]


def headline(status: Status) -> str:
    """The estimate in a few words: the scale and its ``±``, whether it converged and whether it
    is published, or how far convergence is."""
    if status.converged:
        text = f'converged: scale {status.scale:.6g} +- {status.spread:.2g}'
    elif status.publishing:
        text = f'published, not converged: scale {status.scale:.6g} +- {status.spread:.2g}'
    else:
        text = f'not converged: {status.samples} samples'
        if status.scale > 0.0 and math.isfinite(status.spread_stat):  # its own, relative
            text += (f', scale {status.scale:.6g} +- '
                     f'{100.0 * status.spread_stat / status.scale:.2g} %')
    return text + (' (frozen)' if status.frozen else '')


def findings(status: Status, counted_since: dict[str, int], gravity_wanted: bool
             ) -> list[Finding]:
    """The findings of one status (module docstring); ``counted_since``: reason -> how many were
    counted since the previous status; ``gravity_wanted``: metric_frame_alignment is gravity."""
    out: list[Finding] = []
    if not status.converged:
        out.append(Finding('not_converged', f'not converged ({status.samples} samples)'))
    out += [Finding(reason, text) for reason, text in sorted(status.conditions.items())]
    if status.suspects:
        out.append(Finding('inputs_suspect',
                           'inputs suspect: ' + ', '.join(sorted(status.suspects))))
    if status.alignment == FrameAlignment.SLAM and gravity_wanted:
        out.append(Finding('alignment_slam', 'metric frame: SLAM axes (no usable ground normal)'))
    for reason, text in WARN_WHEN_COUNTED.items():
        if counted_since.get(reason, 0) > 0:
            out.append(Finding(reason, f'{text} ({counted_since[reason]})'))
    return out


def assess(status: Status, counted_since: dict[str, int], gravity_wanted: bool,
           extra: Iterable[Finding] = ()) -> Health:
    """The level and message of ``status`` (see :func:`findings`), with the shell's ``extra``."""
    found = findings(status, counted_since, gravity_wanted) + list(extra)
    level = max((f.level for f in found), default=OK)
    texts = [f.text for f in found if f.reason != 'not_converged']
    message = headline(status) + ''.join(f'; {t}' for t in texts)
    return Health(level, message, tuple(found))


class HealthMonitor:
    """Assesses a stream of statuses in order: the counted reasons are judged by what was
    counted since the previous status (a counter that restarted counts from zero)."""

    def __init__(self, gravity_wanted: bool = True) -> None:
        self.gravity_wanted = gravity_wanted
        self._counted: dict[str, int] = {}

    def assess(self, status: Status, extra: Iterable[Finding] = ()) -> Health:
        health = self.peek(status, extra)
        self._counted = {**status.rejected, **status.events}
        return health

    def peek(self, status: Status, extra: Iterable[Finding] = ()) -> Health:
        """As :meth:`assess`, without taking the counts as seen (the node's timer status)."""
        counts = {**status.rejected, **status.events}
        since = {reason: count - min(self._counted.get(reason, 0), count)
                 for reason, count in counts.items()}
        return assess(status, since, self.gravity_wanted, extra)
