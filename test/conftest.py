"""Shared test fixtures.

DDS stays on this machine and each test process gets its own ROS domain, so that concurrent runs
(two developers, CI, a benchmark) never hear each other. This runs before any test imports rclpy.
"""
from __future__ import annotations

import contextlib
import fcntl
import os
import signal
import tempfile
from pathlib import Path

import pytest

# 0..101 are safe domain ids on Linux; tests take 10..89, the Makefile's runs (demo) and the
# benchmarks 90..99: a benchmark or a demo never shares a test's domain.
DOMAINS = range(10, 90)
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

# CI: .ci/run exports CI=1 (most CI services set CI=true). There, a test whose inputs are missing
# fails, naming them: CI installs them all, and a test that skipped there would prove nothing.
# Elsewhere (a user's fresh clone) it skips, naming what to install.
IN_CI = os.environ.get('CI', '').strip().lower() in ('1', 'true', 'yes')


def missing(what: str, remedy: str) -> None:
    """A test's input is missing: fail in CI, skip elsewhere; both say ``remedy``."""
    text = f'{what} (to run this test: {remedy})'
    if IN_CI:
        pytest.fail(f'CI is set and {text}', pytrace=False)
    pytest.skip(text)


@pytest.fixture(scope='session')
def shared_data() -> Path:
    """``../shared/data`` beside the repository (present in CI; absent in a user's fresh clone)."""
    if not SHARED_DATA.is_dir():
        missing(f'real data not found at {SHARED_DATA}', '../shared/data is only beside the '
                'repository in CI and on developer machines')
    return SHARED_DATA


# ---------------------------------------------------------------- people from pixels (docs/people.md)
OPENCV_DATA = Path('/usr/share/doc/opencv-doc/examples/data')  # Debian's opencv-doc samples
OPENCV_IMAGES = ('basketball1.png', 'basketball2.png', 'messi5.jpg')


@pytest.fixture(scope='session')
def people_extra() -> None:
    """The [people] extra (MediaPipe with its shipped models, OpenCV)."""
    from hac_ros.people import extra

    try:
        extra.require()
    except extra.ExtraMissing as exc:
        missing(str(exc), f"{extra.INSTALL}, or make install (it installs .[ros,dev,people])")


@pytest.fixture(scope='session')
def opencv_images(people_extra) -> dict[str, object]:
    """The opencv-doc sample images with people, as (H, W, 3) uint8 RGB by file name."""
    import cv2

    found = {}
    for name in OPENCV_IMAGES:
        bgr = cv2.imread(str(OPENCV_DATA / name))
        if bgr is None:
            missing(f'{OPENCV_DATA / name} not found', 'apt-get install opencv-doc (Debian, '
                    'Ubuntu)')
        found[name] = bgr[:, :, ::-1].copy()
    if not (OPENCV_DATA / 'vtest.avi').is_file():
        missing(f'{OPENCV_DATA / "vtest.avi"} not found', 'apt-get install opencv-doc')
    return found


# ================================================================ no node outlives its test
NODE_COMMANDS = ('hac_node', 'hac_lifecycle_node', 'hac_ros.ros.node', 'hac_ros.ros.lifecycle_node',
                 'hac_ros.cli play', 'hac_ros.cli demo', 'hac_people_node', 'hac_ros.ros.people_node')


def _live_children() -> dict[int, str]:
    """pid -> command line of this process's children that run a node or a player."""
    found = {}
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / 'stat').read_text()
            cmdline = (entry / 'cmdline').read_bytes().replace(b'\0', b' ').decode(errors='replace')
        except OSError:
            continue
        fields = stat.rsplit(')', 1)[-1].split()  # after "pid (comm)": state, ppid, ...
        if fields[0] != 'Z' and int(fields[1]) == os.getpid() and any(
                command in cmdline for command in NODE_COMMANDS):
            found[int(entry.name)] = cmdline.strip()
    return found


@pytest.fixture(autouse=True)
def no_node_left_running():
    """A test that leaves a node or a player process running fails (and the process is killed):
    left in the test domain, it would answer every later test's inputs too."""
    yield
    left = _live_children()
    for pid in left:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    assert not left, f'processes left running by the test (killed now): {left}'
