"""A ROS domain for a benchmark that runs nodes: DDS on this machine only, and a domain of
BENCH_DOMAINS that no other benchmark holds (a lock file each, kept until the process exits, as
test/conftest.py locks 10..89 for the tests). A second benchmark or another developer's node in
the same domain answers this one's inputs and publishes into its outputs (seen: another
hac_node's /diagnostics and joints). Call before rclpy is imported."""
from __future__ import annotations

import fcntl
import os
import tempfile
from pathlib import Path
from typing import IO

BENCH_DOMAINS = range(90, 100)  # tests take 10..89 (test/conftest.py)
_held: list[IO[str]] = []  # the lock file, open until the process exits


def claim_domain() -> int:
    """Set ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and ROS_DOMAIN_ID to a domain of
    BENCH_DOMAINS this process now holds; returns it."""
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ.pop('ROS_STATIC_PEERS', None)
    start = os.getpid() % len(BENCH_DOMAINS)
    for k in range(len(BENCH_DOMAINS)):
        domain = BENCH_DOMAINS[(start + k) % len(BENCH_DOMAINS)]
        path = Path(tempfile.gettempdir()) / f'hac_ros_bench_domain_{domain}.lock'
        lock = open(path, 'w')  # noqa: SIM115 - held open until the process exits
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        _held.append(lock)
        os.environ['ROS_DOMAIN_ID'] = str(domain)
        return domain
    raise RuntimeError(f'every ROS domain in {BENCH_DOMAINS} is held by another benchmark')
