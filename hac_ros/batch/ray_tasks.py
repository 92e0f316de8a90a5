"""``hac batch`` on Ray: each recording a Ray task, on a local Ray or a cluster (docs/batch.md).

The task is :func:`hac_ros.batch.jobs.run_job`, the function the process pool runs, with the same
:class:`~hac_ros.batch.jobs.Job`: the outputs are the pool's. Joining a cluster is bounded in time
(:func:`probe_ray_address`); a missing Ray or an address where no cluster answers is a usage
error (:class:`~hac_ros.core.basics.errors.HacError`).
"""
from __future__ import annotations

import contextlib
import logging
import os
import socket
from collections.abc import Iterator
from typing import Any

from hac_ros.batch.jobs import Job, Row, one_line, run_job
from hac_ros.batch.pool import SIGNAL_POLL_S, STOP_WAIT_S, OnRow, clean_up
from hac_ros.core.basics.errors import ArgumentError, HacError

# Ray: a task whose worker process (or node) dies is run again this many times; staging and the
# marker make a rerun start clean (docs/batch.md, "When a worker dies")
RAY_MAX_RETRIES = 2
RAY_CONNECT_TIMEOUT_S = 5.0  # TCP connect and the gRPC greeting of a cluster's address
# The HTTP/2 client preface and an empty SETTINGS frame: a Ray head's GCS (gRPC) answers with a
# SETTINGS frame (type 4) at once; ray.init itself would retry an address for minutes.
HTTP2_PREFACE = b'PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n' + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
HTTP2_SETTINGS = 4


@contextlib.contextmanager
def ray_session(address: str, workers: int) -> Iterator[Any]:
    """The ``ray`` module, joined to a local Ray (``local``: started here with ``workers`` CPUs)
    or the cluster at ``address``, and shut down afterwards if it was started here. A Ray already
    initialised by the caller is used as it is (and left running)."""
    ray = import_ray()
    started = connect_ray(ray, address, workers)
    try:
        yield ray
    finally:
        if started:
            ray.shutdown()


def run_ray(ray: Any, jobs: list[Job], on_row: OnRow) -> None:
    """Each job as a Ray task of one CPU (:func:`hac_ros.batch.jobs.run_job`), retried up to
    :data:`RAY_MAX_RETRIES` times when its worker dies; ``on_row`` as each finishes."""
    refs: dict[Any, Job] = {}
    try:
        task = ray.remote(num_cpus=1, max_retries=RAY_MAX_RETRIES)(run_job)
        refs = {task.remote(job): job for job in jobs}
        pending = list(refs)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1, timeout=SIGNAL_POLL_S)
            for ref in ready:
                job = refs[ref]
                try:
                    row = ray.get(ref)
                except Exception as exc:
                    row = Row(job.input, 'failed', f'Ray task failed after {RAY_MAX_RETRIES} '
                              f'retries: {one_line(exc)}')
                on_row(job, row)
    except BaseException:  # a signal (Interrupted, Ctrl-C): no new task, the running ones stop
        done = set()
        for ref in refs:
            ray.cancel(ref)  # KeyboardInterrupt in the task: its replay removes its staging
        with contextlib.suppress(Exception):
            finished, _ = ray.wait(list(refs), num_returns=len(refs), timeout=STOP_WAIT_S)
            done = set(finished)
        for ref, job in refs.items():
            if ref not in done:
                ray.cancel(ref, force=True)
            clean_up(job)  # what a task killed half-way left (a finished one is kept)
        raise


def import_ray() -> Any:
    try:
        import ray
    except ImportError as exc:
        raise HacError('Ray is not installed: pip install "hac_ros[cluster]" (or pip install '
                       '"ray[default]")') from exc
    return ray


def connect_ray(ray: Any, address: str, workers: int) -> bool:
    """Start (``local``) or join (an address) Ray; True when this call initialised it."""
    if ray.is_initialized():
        return False
    options: dict[str, Any] = {'logging_level': logging.ERROR, 'log_to_driver': False}
    if address == 'local':
        options.update(address='local', num_cpus=workers, include_dashboard=False)
    else:
        probe_ray_address(address)
        options.update(address=address)
    try:
        ray.init(**options)
    except Exception as exc:
        raise HacError(f'Ray at {address}: {one_line(exc)}') from exc
    return True


def probe_ray_address(address: str, timeout_s: float = RAY_CONNECT_TIMEOUT_S) -> None:
    """HacError unless a gRPC server (a Ray head's GCS, or a Ray Client server for ``ray://``)
    answers at ``address`` within ``timeout_s`` seconds: ray.init would retry for minutes.
    ``auto`` (the cluster this machine belongs to) is left to ray.init."""
    if address == 'auto':
        return
    host, sep, port = address.split('://', 1)[-1].rpartition(':')
    host = host.strip('[]')
    if not sep or not host or not port.isdigit():
        raise ArgumentError(f'{{ray}} {address!r}: expected local, auto, HOST:PORT or '
                            'ray://HOST:PORT', 'ray')
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s) as conn:
            if os.environ.get('RAY_USE_TLS', '0') not in ('1', 'true', 'True'):
                conn.settimeout(timeout_s)
                conn.sendall(HTTP2_PREFACE)
                frame = conn.recv(9)
                if len(frame) < 9 or frame[3] != HTTP2_SETTINGS:
                    raise HacError(f'Ray at {address}: what answers there is not a Ray cluster '
                                   '(no gRPC greeting)')
    except OSError as exc:
        raise ArgumentError(f'Ray at {address}: no Ray cluster reachable there within '
                            f'{timeout_s:g} s ({exc.strerror or type(exc).__name__}); start one '
                            'with "ray start --head", or use {ray} local', 'ray') from exc
