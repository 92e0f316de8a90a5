"""Shared test fixtures.

DDS stays on this machine and each test process gets its own ROS domain, so that concurrent runs
(two developers, CI, a benchmark) never hear each other. This runs before any test imports rclpy.
"""
from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.pop('ROS_STATIC_PEERS', None)
# 0..101 are safe domain ids on Linux; 10..99 leaves room for the Makefile's and users' own.
os.environ['ROS_DOMAIN_ID'] = str(10 + os.getpid() % 90)

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / 'shared' / 'data'


@pytest.fixture(scope='session')
def shared_data() -> Path:
    """``../shared/data`` beside the repository (present in CI; absent in a user's fresh clone)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f'real data not found at {SHARED_DATA} (../shared/data is only beside the '
                    'repository in CI and on developer machines)')
    return SHARED_DATA
