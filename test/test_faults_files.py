"""The fault suite (test_faults.py): files. ``hac`` commands writing onto a full or a read-only
filesystem (a real tmpfs in a private mount namespace, no mock) give one line naming the problem
and leave nothing (hac batch fails the recording's row); hac import refuses joints the calibrator
would refuse, in one line, writing nothing."""
from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from test_faults import REPO, _import_args, hac, walk  # noqa: F401 (walk: a fixture)

from hac_ros.replay.replayer import replay

pytest.importorskip('rclpy')


# ============================================================================ files
@pytest.fixture(scope='module')
def unshare() -> list[str]:
    """A private mount namespace, where an unprivileged user may mount a tiny tmpfs: a real full
    or read-only filesystem, no mock."""
    command = ['unshare', '--user', '--map-root-user', '--mount']
    try:
        probe = subprocess.run([*command, 'sh', '-c', 'mount -t tmpfs -o size=16k tmpfs /mnt'],
                               capture_output=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as exc:
        pytest.skip(f'unshare not available: {exc}')
    if probe.returncode != 0:
        pytest.skip(f'cannot mount a tmpfs in a user namespace here: {probe.stderr!r}')
    return command


def on_small_filesystem(unshare: list[str], tmp_path: Path, args: list[str], size: str,
                        read_only: bool = False) -> tuple[int, str, list[str]]:
    """``hac ARGS`` with ``{fs}`` in them standing for a fresh tmpfs of ``size`` (read-only if
    asked): its exit code, stderr, and what is left on the filesystem afterwards."""
    mount = tmp_path / 'fs'
    mount.mkdir()
    left, err = tmp_path / 'left.txt', tmp_path / 'stderr.txt'
    command = ' '.join(shlex.quote(a.replace('{fs}', str(mount)))
                       for a in [sys.executable, '-m', 'hac_ros.cli', *args])
    options = f'size={size}' + (',ro' if read_only else '')
    script = (f'mount -t tmpfs -o {options} tmpfs {mount} || exit 99; cd {REPO}; '
              f'{command} >/dev/null 2>{err}; code=$?; ls -A {mount} > {left}; exit $code')
    code = subprocess.run([*unshare, 'sh', '-c', script], timeout=600).returncode
    assert code != 99, 'the tmpfs could not be mounted'
    return code, err.read_text(), left.read_text().split()


def assert_one_line_error(code: int, stderr: str, *needles: str) -> None:
    assert code == 2, stderr
    assert 'Traceback' not in stderr, stderr
    lines = [line for line in stderr.splitlines() if ': error: ' in line]
    assert len(lines) == 1, stderr  # (notices printed before it are the replay's own)
    for needle in needles:
        assert needle in lines[0], stderr


@pytest.mark.slow
def test_a_full_disk_gives_one_line_and_leaves_nothing(unshare, walk, tmp_path):
    """hac replay onto a 1 MB filesystem (its output needs about 5 MB): one line naming the
    problem, exit 2, no OUT and no staging left."""
    code, stderr, left = on_small_filesystem(
        unshare, tmp_path, ['replay', str(walk), '-o', '{fs}/out', '--no-progress'], '1m')
    assert_one_line_error(code, stderr, 'No space left on device')
    assert left == []


@pytest.mark.slow
def test_a_read_only_output_gives_one_line(unshare, walk, tmp_path):
    code, stderr, left = on_small_filesystem(
        unshare, tmp_path, ['replay', str(walk), '-o', '{fs}/out', '--no-progress'], '1m',
        read_only=True)
    assert_one_line_error(code, stderr, 'Read-only file system')
    assert left == []


@pytest.mark.slow
@pytest.mark.parametrize('command', ['simulate', 'export', 'batch'])
def test_other_commands_on_a_full_disk_give_one_line_and_leave_nothing(unshare, walk, tmp_path,
                                                                       command):
    if command == 'simulate':
        args, size = ['simulate', 'walk', '-o', '{fs}/sim'], '1m'
    elif command == 'export':
        replayed = tmp_path / 'replayed'
        replay(walk, replayed)
        args, size = ['export', str(replayed), '-o', '{fs}/out.npz'], '64k'
    else:
        args, size = ['batch', str(walk), '-o', '{fs}/batch', '--workers', '1'], '1m'
    code, stderr, left = on_small_filesystem(unshare, tmp_path, args, size)
    if command == 'batch':  # the recording's own failure is its row; the summary is written
        assert code in (1, 2), stderr
        assert 'Traceback' not in stderr
    else:
        assert_one_line_error(code, stderr, 'No space left on device')
        assert left == []


@pytest.mark.parametrize('factor, shift_s, needle', [
    (1000.0, 0.0, 'millimetres'), (0.01, 0.0, 'centimetres converted to metres twice'),
    (1.0, 3600.0, 'share no time')], ids=['mm', 'cm_twice', 'outside_in_time'])
def test_hac_import_refuses_joints_the_calibrator_would_refuse(walk, tmp_path, factor, shift_s,
                                                              needle):
    """hac import judges the joints as the calibrator does (a body's size in metres, naming the
    likely unit) and checks they overlap the trajectory in time: exit 2, one line, nothing
    written."""
    out = tmp_path / 'imported'
    result = hac(*_import_args(walk, tmp_path, out, factor, shift_s))
    assert result.returncode == 2, result.stderr
    assert 'Traceback' not in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert needle in result.stderr
    assert not out.exists()
