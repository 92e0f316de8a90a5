"""Shared test fixtures.

DDS stays on this machine and each test process gets its own ROS domain, so that concurrent runs
(two developers, CI, a benchmark) never hear each other. This runs before any test imports rclpy.
"""
from __future__ import annotations

import fcntl
import os
import tempfile
from pathlib import Path

import pytest

# 0..101 are safe domain ids on Linux; 10..99 leaves room for the Makefile's and users' own.
DOMAINS = range(10, 100)
_domain_lock = None  # the open lock file of this process's domain, held until it exits


def claim_dds_domain() -> int:
    """A ROS domain no other test process on this machine holds: each domain has a lock file,
    and this process keeps the first one it can lock (starting from its pid, so that concurrent
    runs spread out) until it exits. Two suites in one domain hear each other's nodes."""
    global _domain_lock
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
        _domain_lock = lock
        return domain
    raise RuntimeError(f'every ROS domain in {DOMAINS} is held by another test process')


os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('ROS_STATIC_PEERS', None)
os.environ['ROS_DOMAIN_ID'] = str(claim_dds_domain())

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / 'shared' / 'data'


@pytest.fixture(scope='session')
def shared_data() -> Path:
    """``../shared/data`` beside the repository (present in CI; absent in a user's fresh clone)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f'real data not found at {SHARED_DATA} (../shared/data is only beside the '
                    'repository in CI and on developer machines)')
    return SHARED_DATA
