"""``hac batch``: plan, run on a pool or as Ray tasks, write the summary."""
from __future__ import annotations

import contextlib
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from hac_ros.batch.jobs import LOGS, SUMMARY_CSV, SUMMARY_MD, Job, Row, plan, recording_name
from hac_ros.batch.pool import default_workers, run_pool
from hac_ros.batch.summary import medians_line, write_summary
from hac_ros.core.basics.errors import ArgumentError
from hac_ros.core.basics.printable import printable
from hac_ros.core.rules.params import HacParams
from hac_ros.progress import Progress, progress_pass

MOSTLY_WARN_PCT = 50.0  # a recording WARN for more of its statuses is named in the summary


# ============================================================================ the batch
@dataclass
class BatchResult:
    """The rows of one batch, in input order, and where the summary went."""

    out_dir: Path
    mode: str
    rows: list[Row]

    @property
    def exit_code(self) -> int:
        """0 when every input succeeded, 1 when any failed."""
        return 0 if all(row.ok for row in self.rows) else 1

    def text(self) -> str:
        ok = sum(row.ok for row in self.rows)
        skipped = sum(row.skipped for row in self.rows)
        lines = [f'hac batch ({self.mode}): {len(self.rows)} recordings, {ok} ok'
                 + (f' ({skipped} already complete)' if skipped else '')
                 + f', {len(self.rows) - ok} failed -> {self.out_dir / SUMMARY_CSV}, '
                 f'{self.out_dir / SUMMARY_MD}']
        lines += [f'  failed: {row.input}: {row.error}' for row in self.rows if not row.ok]
        lines += [f'  mostly WARN: {row.input}: WARN {row.warn_pct:.0f} % of its statuses '
                  f'({row.reasons})' for row in self.rows
                  if row.ok and row.warn_pct is not None and row.warn_pct > MOSTLY_WARN_PCT]
        medians = medians_line(self.rows)
        if medians:
            lines.append('  ' + medians)
        return '\n'.join(lines)


def batch(inputs: Sequence[str | Path], out_dir: str | Path, params: HacParams | None = None,
          mode: str = 'offline', workers: int | None = None, ray: str | None = None,
          resume: bool = False, progress: Progress | None = None) -> BatchResult:
    """Calibrate every recording of ``inputs`` into ``out_dir`` (module docstring).

    workers: parallel recordings (default: the cores this process may use; with Ray on a
    cluster, the cluster's CPUs decide); ray: None (a process pool), ``local`` or a cluster's
    address; progress: a display advanced per recording (default none: the library draws
    nothing; ``hac batch`` passes a bar on a terminal).
    Raises HacError on usage errors; a failed recording is a row, not an exception.
    """
    params = params or HacParams()
    workers = default_workers() if workers is None else workers
    if workers < 1:
        raise ArgumentError(f'{{workers}} must be at least 1, not {workers}', 'workers')
    out_dir = Path(out_dir)
    jobs, done = plan(inputs, out_dir, params, mode, resume)
    rows: dict[str, Row] = dict(done)
    with contextlib.ExitStack() as stack:
        ray_module = None
        if ray is not None:  # joined before anything is written: its errors are usage errors
            from hac_ros.batch.ray_tasks import import_ray, ray_session, run_ray
            import_ray()
            if jobs:
                ray_module = stack.enter_context(ray_session(ray, min(workers, len(jobs))))
        (out_dir / LOGS).mkdir(parents=True, exist_ok=True)
        for name in done:
            with open(out_dir / LOGS / f'{name}.log', 'a', encoding='utf-8') as log:
                print(f'hac batch: {time.strftime("%Y-%m-%d %H:%M:%S")}: skipped (resumed): '
                      f'{printable(out_dir / name)} is complete for the same input, parameters '
                      'and mode', file=log)
        total = len(jobs) + len(done)
        bar = stack.enter_context(progress_pass(progress, total, 'hac batch'))
        if bar is not None and done:
            bar.update(len(done))

        def on_row(job: Job, row: Row) -> None:
            rows[job.name] = row
            if bar is not None:
                bar.update(1)
        if jobs and ray_module is not None:
            run_ray(ray_module, jobs, on_row)
        elif jobs:
            run_pool(jobs, min(workers, len(jobs)), on_row)
    ordered = [rows[recording_name(p)] for p in inputs]
    write_summary(out_dir, ordered, mode)
    return BatchResult(out_dir, mode, ordered)
