"""``hac batch``'s jobs on a process pool (spawned workers)."""
from __future__ import annotations

import os
from collections.abc import Callable

from hac_ros.batch.jobs import Job, Row, one_line, run_job


def default_workers() -> int:
    """The cores this process may use (its CPU affinity), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


# ============================================================================ running
OnRow = Callable[[Job, Row], None]


def run_pool(jobs: list[Job], workers: int, on_row: OnRow) -> None:
    """Each job in a process of a pool of ``workers`` (spawned, not forked)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    context = multiprocessing.get_context('spawn')
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=context)
    try:
        futures = {pool.submit(run_job, job): job for job in jobs}
        for future in as_completed(futures):
            job = futures[future]
            try:
                row = future.result()
            except BrokenProcessPool:
                row = Row(job.input, 'failed', 'a worker process died (killed, or out of memory?) '
                          'before this recording finished: resuming the batch redoes it')
            except Exception as exc:
                row = Row(job.input, 'failed', one_line(exc))
            on_row(job, row)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
