"""The ``hac`` command line: every sub-command's ``--help`` works (the first thing a user types)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from hac_ros.cli import COMMANDS, main

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize('command', [None, *COMMANDS])
def test_every_help_prints_usage_and_exits_0(command, capsys):
    argv = ['--help'] if command is None else [command, '--help']
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith('usage: hac') and (command is None or command in out.splitlines()[0])


def test_help_of_the_installed_entry_point():
    """Through ``python -m hac_ros.cli`` (what the ``hac`` script runs): every command listed."""
    result = subprocess.run([sys.executable, '-m', 'hac_ros.cli', '--help'], cwd=REPO, text=True,
                            capture_output=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert all(command in result.stdout for command in COMMANDS)
