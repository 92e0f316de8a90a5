"""A ROS domain for a people benchmark: DDS on this machine only, and a domain that no other run
holds, locked the way the tests lock theirs (test/conftest.py, claim_dds_domain): 10..89. The
benchmarks' 90..99 are chosen without a lock (90 + pid % 10), so two runs can meet there; a
locked domain cannot be shared. Call before rclpy is imported."""
from __future__ import annotations

import fcntl
import os
import tempfile
from pathlib import Path
from typing import IO

DOMAINS = range(10, 90)  # the locked range (test/conftest.py)
_held: list[IO[str]] = []  # the lock file, open until the process exits


def claim_domain() -> int:
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ.pop('ROS_STATIC_PEERS', None)
    start = os.getpid() % len(DOMAINS)
    for k in range(len(DOMAINS)):
        domain = DOMAINS[(start + k) % len(DOMAINS)]
        path = Path(tempfile.gettempdir()) / f'hac_ros_test_domain_{domain}.lock'
        lock = open(path, 'w')  # noqa: SIM115 - held open until the process exits
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        _held.append(lock)
        os.environ['ROS_DOMAIN_ID'] = str(domain)
        return domain
    raise RuntimeError(f'every ROS domain in {DOMAINS} is held by another run')
