"""``hac batch``'s jobs on a pool of worker processes (spawned, not forked).

Each worker is a process of its own that runs one job at a time
(:func:`hac_ros.batch.jobs.run_job`) and asks for the next; a worker that dies fails only its own
recording, and a new one takes its place. The pool stops on a signal the way the command does
(:class:`~hac_ros.recording.atomic.Interrupted`, or Ctrl-C, in the caller): no new recording starts,
every running worker gets SIGTERM (its replay removes what it was writing) and is waited for
STOP_WAIT_S at most (then killed, and its half-written output removed here), so that no process
is left behind; what finished is kept. Workers ignore SIGINT and SIGHUP themselves (a terminal
sends them to the whole process group): the caller decides. A worker whose caller died stops too
(:func:`_watch_parent`).
"""
from __future__ import annotations

import contextlib
import os
import shutil
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from multiprocessing.context import SpawnContext
from multiprocessing.process import BaseProcess
from pathlib import Path
from types import FrameType

from hac_ros.batch.jobs import Job, Row, completed_row, one_line, run_job
from hac_ros.recording.atomic import Interrupted

STOP_WAIT_S = 10.0  # a stopped worker has this long to clean up before it is killed
PARENT_POLL_S = 1.0  # a worker checks this often that its caller is alive
# A signal may be delivered to any thread of the process (numpy's BLAS threads too), and then the
# main thread blocked in wait() is not interrupted: it looks up this often to run the handler.
SIGNAL_POLL_S = 0.2


def default_workers() -> int:
    """The cores this process may use (its CPU affinity), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


# ============================================================================ running
OnRow = Callable[[Job, Row], None]


@dataclass
class _Worker:
    process: BaseProcess
    conn: Connection  # the caller's end of the worker's pipe
    job: Job | None = None  # the job it runs, None when idle


def run_pool(jobs: list[Job], workers: int, on_row: OnRow) -> None:
    """Each job in one of ``workers`` processes; ``on_row`` as each finishes (in this process).
    On any exception here (a signal: Interrupted, KeyboardInterrupt) the pool stops (module
    docstring) and the exception goes on."""
    import multiprocessing

    context = multiprocessing.get_context('spawn')
    queue = list(jobs)
    pool: list[_Worker] = []
    try:
        while queue or any(w.job is not None for w in pool):
            while queue and len([w for w in pool if w.job is not None]) < workers:
                worker = next((w for w in pool if w.job is None), None)
                if worker is None:
                    worker = _start(context)
                    pool.append(worker)
                worker.job = queue.pop(0)
                worker.conn.send(worker.job)
            busy = [w for w in pool if w.job is not None]
            ready = wait([w.conn for w in busy] + [w.process.sentinel for w in busy],
                         timeout=SIGNAL_POLL_S)
            for worker in busy:
                job = worker.job
                assert job is not None
                if worker.conn in ready and worker.conn.poll():
                    try:
                        row = worker.conn.recv()
                    except (EOFError, OSError):
                        row = None
                    if isinstance(row, Row):
                        worker.job = None
                        on_row(job, row)
                        continue
                if worker.process.sentinel in ready or not worker.process.is_alive():
                    worker.job = None
                    pool.remove(worker)
                    clean_up(job)
                    on_row(job, Row(job.input, 'failed', 'a worker process died (killed, or out '
                                    'of memory?) before this recording finished: resuming the '
                                    'batch redoes it'))
    except BaseException:
        _stop(pool)
        raise
    finally:
        for worker in pool:  # idle workers: asked to leave
            if worker.process.is_alive():
                with contextlib.suppress(OSError, ValueError):
                    worker.conn.send(None)
        for worker in pool:
            worker.process.join(STOP_WAIT_S)
            if worker.process.is_alive():
                worker.process.kill()
                worker.process.join()
            worker.conn.close()


def _start(context: SpawnContext) -> _Worker:
    ours, theirs = context.Pipe()
    process = context.Process(target=_work, args=(theirs, os.getpid()), name='hac_batch_worker')
    process.start()
    theirs.close()
    return _Worker(process, ours)


def _stop(pool: list[_Worker]) -> None:
    """Stop every worker now: SIGTERM to the busy ones (their replay cleans up), wait, kill the
    ones still there and remove what they were writing."""
    for worker in pool:
        if worker.process.is_alive() and worker.process.pid is not None:
            os.kill(worker.process.pid, signal.SIGTERM)
    deadline = time.monotonic() + STOP_WAIT_S
    for worker in pool:
        worker.process.join(max(0.0, deadline - time.monotonic()))
        if worker.process.is_alive():
            worker.process.kill()
            worker.process.join()
        if worker.job is not None:
            clean_up(worker.job)
            worker.job = None


def clean_up(job: Job) -> None:
    """What an attempt at ``job`` that did not finish may have left: its staging directory and
    an output without a completion marker (run_job removes them itself unless it was killed)."""
    output = Path(job.output_path)
    for staging in output.parent.glob(f'.{output.name}.*.partial'):
        shutil.rmtree(staging, ignore_errors=True)
    if completed_row(job) is None and output.exists():
        shutil.rmtree(output, ignore_errors=True)


# ============================================================================ a worker
def _work(conn: Connection, parent_pid: int) -> None:
    """A worker process: jobs from ``conn`` until None (or EOF), each row sent back. SIGTERM
    interrupts the job (its output removed: run_job), SIGINT and SIGHUP are the caller's."""
    def stop(signum: int, frame: FrameType | None) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise Interrupted(signum)

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, stop)
    threading.Thread(target=_watch_parent, args=(parent_pid,), name='hac_batch_parent',
                     daemon=True).start()
    try:
        while True:
            try:
                job = conn.recv()
            except EOFError:
                return
            if job is None:
                return
            try:
                row = run_job(job)
            except Exception as exc:  # run_job returns failed rows itself; this is a bug
                row = Row(job.input, 'failed', one_line(exc))
            conn.send(row)
    except Interrupted:
        return


def _watch_parent(parent_pid: int) -> None:
    """Stop this worker (SIGTERM to itself) once its caller is gone: never an orphan."""
    while os.getppid() == parent_pid:
        time.sleep(PARENT_POLL_S)
    os.kill(os.getpid(), signal.SIGTERM)
