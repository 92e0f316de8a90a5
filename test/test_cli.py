"""The ``hac`` command line: every sub-command's ``--help`` works (the first thing a user types)."""
from __future__ import annotations

import ast
import re
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


# ============================================================================ flags live in cli/
# Another program's own flags that a library message may quote
OTHER_PROGRAMS_FLAGS = {'--head',  # "ray start --head"
                        '--ros-args', '--params-file'}  # hac_node's own ROS arguments
FLAG = re.compile(r'(?<![\w-])--[a-z][a-z0-9-]*')


# Command lines besides cli/: hac_node's and hac_people_node's own (--help, and the ROS
# arguments they read)
COMMAND_LINES = {Path('hac_ros/ros/arguments.py'), Path('hac_ros/people/arguments.py')}


def _library_strings() -> list[tuple[str, int, str]]:
    """(file, line, text) of every string literal of hac_ros and msg_adapters outside the command
    lines that is not a docstring: what the library can say to a user."""
    found = []
    for package in ('hac_ros', 'msg_adapters'):
        for path in sorted((REPO / package).rglob('*.py')):
            relative = path.relative_to(REPO)
            if 'cli' in relative.parts or relative in COMMAND_LINES:
                continue
            tree = ast.parse(path.read_text(encoding='utf-8'))
            docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                          if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                                               ast.AsyncFunctionDef))
                          and node.body and isinstance(node.body[0], ast.Expr)}
            found += [(str(path.relative_to(REPO)), node.lineno, node.value)
                      for node in ast.walk(tree) if isinstance(node, ast.Constant)
                      and isinstance(node.value, str) and id(node) not in docstrings]
    return found


def test_the_library_names_no_command_line_flag():
    """Library errors and messages name arguments and parameters; only cli/ says them as flags."""
    flags = [(path, line, flag) for path, line, text in _library_strings()
             for flag in FLAG.findall(text) if flag not in OTHER_PROGRAMS_FLAGS]
    assert flags == []


def test_argument_errors_are_said_with_the_commands_own_options(tmp_path):
    """One error, two audiences: the library names ``workers``, ``hac batch`` says ``--workers``;
    an argument the command has no option for keeps its name."""
    from hac_ros.batch.runner import batch
    from hac_ros.core.basics.errors import ArgumentError, ArgumentText

    with pytest.raises(ArgumentError, match=r'^workers must be at least 1, not 0$'):
        batch([str(tmp_path)], tmp_path / 'out', workers=0)
    result = subprocess.run([sys.executable, '-m', 'hac_ros.cli', 'batch', str(tmp_path), '-o',
                             str(tmp_path / 'out'), '--workers', '0'], cwd=REPO, text=True,
                            capture_output=True, timeout=60)
    assert result.returncode == 2
    assert result.stderr == 'hac batch: error: --workers must be at least 1, not 0\n'
    text = ArgumentText('use {pose_type} or {joints_topic}; {other} stays', 'pose_type',
                        'joints_topic')
    assert text == 'use pose_type or joints_topic; {other} stays'
    assert text.naming({'pose_type': '--pose-type'}) == \
        'use --pose-type or joints_topic; {other} stays'


def test_a_signal_wrapped_by_the_library_it_interrupted_is_still_an_interruption():
    """A SIGTERM that lands while a module initialises can come back as that library's error
    (seen under load: exit 1 where 143 was due); the command still says "interrupted"."""
    import signal

    from hac_ros.cli import interruption
    from hac_ros.recording.atomic import Interrupted

    try:
        try:
            raise Interrupted(signal.SIGTERM)
        except KeyboardInterrupt as inner:
            raise SystemError('initialization of _x raised unreported exception') from inner
    except SystemError as wrapped:
        assert interruption(wrapped) == signal.SIGTERM
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise ImportError('cannot import name x') from None  # chained as context only
    except ImportError as wrapped:
        assert interruption(wrapped) == signal.SIGINT
    assert interruption(ValueError('a bug')) is None
