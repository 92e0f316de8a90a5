"""The fault suite (test_faults.py): signals to the ``hac`` commands. SIGINT, SIGTERM and SIGHUP in
the middle of a command's work (held there with SIGSTOP, however loaded the machine), or while it
is still starting, end it with one line and exit 128 + the signal: no process left, nothing partial
written, the input untouched; hac batch stops its workers and keeps what finished."""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from faultkit import wait_until
from test_faults import REPO, SIGNALS, _import_args, walk  # noqa: F401 (walk: a fixture)

from hac_ros.batch.runner import batch
from hac_ros.replay.replayer import replay

pytest.importorskip('rclpy')


# ============================================================================ signals
def interrupted_midway(args: list[str], inside: Callable[[int], bool], signum: int,
                       tmp_path: Path) -> tuple[int, str]:
    """Run ``hac ARGS``, wait until ``inside(pid)`` says it is in the middle of its work, stop it
    there (SIGSTOP: it cannot finish meanwhile, however loaded the machine), send ``signum``, let
    it go on; its exit code and stderr. Its session must be empty afterwards (no process left)."""
    stderr_path = tmp_path / 'stderr.txt'
    with open(stderr_path, 'w') as stderr:
        proc = subprocess.Popen([sys.executable, '-m', 'hac_ros.cli', *args], cwd=REPO,
                                stdout=subprocess.DEVNULL, stderr=stderr, start_new_session=True)
        try:
            deadline = time.monotonic() + 600.0
            while not inside(proc.pid):
                assert proc.poll() is None, f'hac {args[0]} finished before it could be interrupted'
                assert time.monotonic() < deadline
                time.sleep(0.005)
            os.kill(proc.pid, signal.SIGSTOP)
            assert inside(proc.pid), 'left its work before it was stopped'
            os.kill(proc.pid, signum)
            os.kill(proc.pid, signal.SIGCONT)
            code = proc.wait(timeout=120.0)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    assert wait_until(lambda: not session_members(proc.pid), 30.0), session_members(proc.pid)
    return code, stderr_path.read_text()


def session_members(sid: int) -> list[str]:
    """The live processes of session ``sid`` (zombies waiting to be reaped left out)."""
    members = []
    for entry in os.listdir('/proc'):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f'/proc/{entry}/stat').read_text()
            if os.getsid(int(entry)) == sid and stat.rsplit(')', 1)[1].split()[0] != 'Z':
                members.append(Path(f'/proc/{entry}/cmdline').read_text().replace('\0', ' '))
        except OSError:
            continue
    return members


def staging(directory: Path) -> Callable[[int], bool]:
    """In the middle: a staging directory or file (``.*partial``) exists in ``directory``."""
    return lambda pid: directory.is_dir() and any(directory.glob('.*partial'))


def reading(path: Path) -> Callable[[int], bool]:
    """In the middle: the process has a file under ``path`` open."""
    target = str(path.resolve())

    def check(pid: int) -> bool:
        try:
            return any(os.readlink(f'/proc/{pid}/fd/{fd}').startswith(target)
                       for fd in os.listdir(f'/proc/{pid}/fd'))
        except OSError:
            return False
    return check


def assert_clean_interruption(code: int, stderr: str, signum: int) -> None:
    assert code == 128 + signum, stderr
    assert 'Traceback' not in stderr
    lines = [line for line in stderr.splitlines() if 'interrupted' in line]
    assert len(lines) == 1 and signal.Signals(signum).name in lines[0], stderr


@pytest.mark.slow
@pytest.mark.parametrize('signum', SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_a_signal_to_hac_replay_leaves_nothing_and_exits_128_plus_it(walk, tmp_path, signum):
    """SIGTERM and SIGHUP (timeout, systemd, Slurm, a closed terminal) end hac replay as Ctrl-C
    does: no OUT, no staging directory, the input untouched, one line, exit 128 + the signal."""
    results = tmp_path / 'results'
    out = results / 'out'
    code, stderr = interrupted_midway(['replay', str(walk), '-o', str(out), '--mode', 'online'],
                                      staging(results), signum, tmp_path)
    assert_clean_interruption(code, stderr, signum)
    assert not results.exists()  # nor OUT, nor its staging, nor the parent it made


def loading(library: str) -> Callable[[int], bool]:
    """In the middle: the process has mapped a file of ``library`` (it is importing it)."""
    def check(pid: int) -> bool:
        try:
            return f'/{library}/' in Path(f'/proc/{pid}/maps').read_text()
        except OSError:
            return False
    return check


@pytest.mark.slow
@pytest.mark.parametrize('library', ['numpy', 'scipy'])
def test_a_signal_while_hac_replay_starts_is_one_line_too(walk, tmp_path, library):
    """Ctrl-C while the command is still starting (importing numpy for the package, scipy for
    the replay): one line, exit 130, no traceback, nothing written."""
    out = tmp_path / 'results' / 'out'
    code, stderr = interrupted_midway(['replay', str(walk), '-o', str(out)], loading(library),
                                      signal.SIGINT, tmp_path)
    assert_clean_interruption(code, stderr, signal.SIGINT)
    assert not (tmp_path / 'results').exists()


@pytest.mark.slow
def test_a_signal_to_hac_batch_stops_its_workers_and_keeps_what_finished(walk, tmp_path):
    """SIGTERM to hac batch alone (not its workers): it stops them within seconds, starts no
    new recording, leaves no process and no partial output, keeps what finished; --resume
    completes the rest."""
    inputs = []
    for name in ('one', 'two', 'three'):
        inputs.append(tmp_path / name)
        shutil.copytree(walk, inputs[-1])
    out = tmp_path / 'out'
    start = time.monotonic()
    code, stderr = interrupted_midway(
        ['batch', *map(str, inputs), '-o', str(out), '--workers', '1'],
        lambda pid: bool(list(out.glob('*.done.json'))) and any(out.glob('.*partial')),
        signal.SIGTERM, tmp_path)
    assert_clean_interruption(code, stderr, signal.SIGTERM)
    assert time.monotonic() - start < 300.0  # a hang, not a busy machine
    finished = {p.name[:-len('.done.json')] for p in out.glob('*.done.json')}
    assert len(finished) == 1  # the recording in progress was stopped, not let finish
    assert not list(out.glob('.*partial')) and not (out / 'summary.csv').exists()
    assert {p.name for p in out.iterdir() if p.is_dir()} == finished | {'logs'}
    result = batch(inputs, out, workers=1, resume=True)
    assert [r.skipped for r in result.rows].count(True) == 1 and all(r.ok for r in result.rows)


@pytest.mark.slow
@pytest.mark.parametrize('command', ['simulate', 'import', 'export', 'eval', 'plot', 'demo'])
def test_every_command_stops_cleanly_on_sigterm(walk, tmp_path, command):
    """SIGTERM in the middle of each other command: exit 143, one line, nothing partial."""
    work = tmp_path / 'work'
    work.mkdir()
    if command == 'simulate':
        args, inside = ['simulate', 'walk', '-o', str(work / 'sim')], staging(work)
    elif command == 'import':
        args, inside = _import_args(walk, tmp_path, work / 'imported'), staging(work)
    elif command in ('export', 'eval', 'plot'):
        replayed = tmp_path / 'replayed'
        replay(walk, replayed)
        args = {'export': ['export', str(replayed), '-o', str(work / 'out.npz')],
                'eval': ['eval', str(replayed), '--gt', str(walk), '--json',
                         str(work / 'eval.json')],
                'plot': ['plot', str(replayed), '--gt', str(walk), '-o', str(work / 'figures')]
                }[command]
        inside = staging(work / 'figures') if command == 'plot' else reading(replayed)
    else:
        args = ['demo', '--recording', str(walk), '-o', str(work / 'demo')]
        inside = staging(work / 'demo')  # its replay is being written
    code, stderr = interrupted_midway(args, inside, signal.SIGTERM, tmp_path)
    assert_clean_interruption(code, stderr, signal.SIGTERM)
    left = [p for p in work.rglob('*')]
    assert left == [], left  # hac demo -o NEWDIR: not even the directory it made
