"""``hac batch``'s summary: DIR/summary.csv and DIR/summary.md."""
from __future__ import annotations

import csv
import io
import statistics
from collections.abc import Iterable
from pathlib import Path

from hac_ros.batch.jobs import COLUMNS, LOGS, SUMMARY_CSV, SUMMARY_MD, Row, _finite, write_text
from hac_ros.core.basics.printable import printable


# ============================================================================ the summary
def write_summary(out_dir: Path, rows: list[Row], mode: str) -> None:
    """DIR/summary.csv (docs/batch.md's columns) and DIR/summary.md (the same table and the
    medians)."""
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(COLUMNS), lineterminator='\n')
    writer.writeheader()
    writer.writerows(row.cells() for row in rows)
    write_text(out_dir / SUMMARY_CSV, text.getvalue())
    ok = sum(row.ok for row in rows)
    lines = [f'# hac batch: {printable(out_dir)}', '',
             f'{len(rows)} recordings ({mode} mode): {ok} ok, {len(rows) - ok} failed. Logs in '
             f'`{LOGS}/`; metrics where a recording has ground truth.', '',
             '| ' + ' | '.join(header for _, _, header in COLUMNS.values()) + ' |',
             '|' + '|'.join(' --- ' if fmt == 's' else ' ---: ' for _, fmt, _ in COLUMNS.values())
             + '|']
    for row in rows:
        cells = {column: _md_escape(text) for column, text in row.cells().items()}
        cells['input'] = f'`{cells["input"]}`'
        lines.append('| ' + ' | '.join(text or ('' if column == 'error' else '–')
                                       for column, text in cells.items()) + ' |')
    medians = medians_line(rows)
    if medians:
        lines += ['', medians]
    write_text(out_dir / SUMMARY_MD, '\n'.join(lines) + '\n')


def medians_line(rows: Iterable[Row]) -> str:
    """One line of medians across the successful recordings with ground truth ('' when none)."""
    with_truth = [row for row in rows if row.ok and row.has_ground_truth]
    if not with_truth:
        return ''

    def median(attr: str, fmt: str, unit: str) -> str:
        values = [getattr(r, attr) for r in with_truth if _finite(getattr(r, attr))]
        return format(statistics.median(values), fmt) + unit if values else '–'
    return (f'Medians over {len(with_truth)} recordings with ground truth: scale error '
            f'{median("scale_err_pct", ".2f", " %")}, ATE-S {median("ate_s_m", ".4f", " m")}, '
            f'W-MPJPE {median("w_mpjpe_mm", ".1f", " mm")}.')


def _md_escape(text: str) -> str:
    """A cell of summary.md: one line, its pipes escaped, nothing a terminal would obey (an input's
    name can hold anything: hac_ros.core.basics.printable)."""
    return printable(text.replace('\n', ' ')).replace('|', '\\|')
