"""What the statuses of a run said, in shares: the summaries' line of ``/diagnostics``.

A replay writes one ``/diagnostics`` status per second of stamp time and ``hac_node`` publishes
one per second of stamp time too, so the share of the statuses at a level is the share of the
run's time it held. :class:`StatusShares` counts them, from the replay's assessed statuses
(:class:`~hac_ros.core.rules.health.Health`) or from what came back over DDS (``hac demo --live``),
and says them the same way for ``hac replay``'s summary, ``hac demo --live``'s and ``hac batch``'s
``warn_pct`` and ``reasons`` columns: ``OK 62 %, WARN 38 % (floor_unknown 30 %, relocking 8 %)``,
never a bare "converged" over a run that was mostly WARN.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field

from hac_ros.core.rules.health import LEVEL_NAMES, OK


@dataclass
class StatusShares:
    """The statuses of a run: how many at each level (``diagnostic_msgs`` levels, OK 0 to STALE
    3) and how many gave each reason; the last one's level and reasons."""

    levels: Counter[int] = field(default_factory=Counter)
    reasons: Counter[str] = field(default_factory=Counter)
    last_level: int | None = None
    last_reasons: tuple[str, ...] = ()

    def add(self, level: int, reasons: Iterable[str]) -> None:
        """One status: its level and the reasons it gave (each counted once per status)."""
        given = tuple(dict.fromkeys(r for r in reasons if r))
        self.levels[int(level)] += 1
        self.reasons.update(given)
        self.last_level, self.last_reasons = int(level), given

    @property
    def total(self) -> int:
        return sum(self.levels.values())

    def percent(self, count: int) -> float:
        """``count`` statuses as a percentage of all of them (NaN when there were none)."""
        return 100.0 * count / self.total if self.total else float('nan')

    @property
    def warn_pct(self) -> float:
        """The share of the statuses that were not OK (WARN, ERROR or STALE), %."""
        return self.percent(self.total - self.levels[OK])

    def reasons_text(self) -> str:
        """``floor_unknown 30 %, relocking 8 %``: each reason with the share of the statuses that
        gave it, the largest first ('' when none did)."""
        ranked = sorted(self.reasons.items(), key=lambda item: (-item[1], item[0]))
        return ', '.join(f'{reason} {_percent(self.percent(n))}' for reason, n in ranked)

    def text(self) -> str:
        """``OK 62 %, WARN 38 % (floor_unknown 30 %, relocking 8 %)``, or ``no status`` ."""
        if not self.total:
            return 'no status'
        levels = ', '.join(f'{LEVEL_NAMES.get(level, str(level))} {_percent(self.percent(n))}'
                           for level, n in sorted(self.levels.items()))
        reasons = self.reasons_text()
        return levels + (f' ({reasons})' if reasons else '')

    def last_text(self) -> str:
        """The last status: ``OK``, or ``WARN (floor_unknown)``."""
        if self.last_level is None:
            return 'no status'
        name = LEVEL_NAMES.get(self.last_level, str(self.last_level))
        return name + (f' ({", ".join(self.last_reasons)})' if self.last_reasons else '')


def _percent(value: float) -> str:
    """A share for people: whole percent, but never 0 % or 100 % for a share that is neither."""
    if 0.0 < value < 1.0:
        return '<1 %'
    if 99.0 < value < 100.0:
        return '>99 %'
    return f'{value:.0f} %'
