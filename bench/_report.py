"""Shared by the benchmarks: the machine line, JSON results, their section of docs/benchmarks.md
(speed) or docs/accuracy.md (accuracy).

Each benchmark owns one section of its page between ``<!-- NAME:start -->`` and
``<!-- NAME:end -->`` and leaves the others alone. A speed benchmark also lists its ratios as
``checks`` in its JSON; :func:`write_summary` renders every result's checks into the ``summary``
section, so the page opens with the current verdicts.
"""
from __future__ import annotations

import json
import os
import platform
import re
import subprocess
import sys
from importlib import metadata
from importlib.util import find_spec
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / 'bench' / 'results'
DOC = REPO / 'docs' / 'benchmarks.md'
ACCURACY_DOC = REPO / 'docs' / 'accuracy.md'
VERSIONED = ('numpy', 'scipy', 'rosbags', 'rclpy')
SPEED_RESULTS = ('core_speed', 'replay_throughput', 'node_latency', 'node_memory', 'people_speed')


def machine() -> dict[str, Any]:
    """What the figures were measured on: CPU, cores, Python, the measured commit and the versions
    of the libraries the figures depend on."""
    cpu = platform.processor() or '?'
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                cpu = line.split(':', 1)[1].strip()
                break
    except OSError:
        pass
    return {'cpu': cpu, 'cores': os.cpu_count(), 'python': platform.python_version(),
            'commit': _commit(), 'versions': _versions()}


def measured_tree() -> Path:
    """The checkout whose ``hac_ros`` this process imports (PYTHONPATH may point at another
    than this one's: bench/ab.py)."""
    spec = find_spec('hac_ros')
    return Path(spec.origin).resolve().parents[1] if spec and spec.origin else REPO


def _commit() -> str:
    """The measured checkout's commit, ``+modified`` when its package files differ from it."""
    def git(*args: str) -> str:
        return subprocess.run(['git', *args], cwd=measured_tree(), text=True,
                              capture_output=True, check=False).stdout.strip()
    try:
        commit = git('rev-parse', '--short', 'HEAD')
        modified = git('status', '--porcelain', '--', 'hac_ros', 'msg_adapters', 'config')
    except OSError:
        return ''
    return commit + ('+modified' if modified else '')


def _versions() -> dict[str, str]:
    found = {}
    for name in VERSIONED:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = ''
    return found


def machine_line(info: dict[str, Any]) -> str:
    """One line naming the machine, the commit and the library versions."""
    line = (f"Machine: {info['cpu']}, {info['cores']} cores, Python {info['python']}, "
            f"commit {info.get('commit') or '?'}.")
    if info.get('versions'):
        line += ' ' + ', '.join(f'{k} {v}' for k, v in info['versions'].items() if v) + '.'
    return line


def check(what: str, measured: str, target: str, met: bool) -> dict[str, Any]:
    """One ratio as measured (text, e.g. ``'1067x'``), its target (e.g. ``'>= 100x'``) and whether
    it is met: a row of the summary."""
    return {'what': what, 'measured': measured, 'target': target, 'met': bool(met)}


def command_line(script: str, argv: list[str] | None = None) -> str:
    """How this run was started, for its section: ``python bench/NAME.py ARGS``."""
    args = sys.argv[1:] if argv is None else argv
    return ' '.join(['python', f'bench/{Path(script).name}', *args])


def write_json(name: str, data: dict[str, Any]) -> Path:
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f'{name}.json'
    path.write_text(json.dumps(data, indent=2, default=float) + '\n')
    return path


def write_section(name: str, markdown: str, doc: Path = DOC) -> None:
    """Replace (or append) the section ``name`` of ``doc`` (docs/benchmarks.md by default)."""
    text = doc.read_text() if doc.exists() else f'# {doc.stem.capitalize()}\n'
    start, end = f'<!-- {name}:start -->', f'<!-- {name}:end -->'
    block = f'{start}\n{markdown.rstrip()}\n{end}'
    pattern = re.compile(re.escape(start) + '.*?' + re.escape(end), re.S)
    if pattern.search(text):
        text = pattern.sub(lambda _: block, text)
    else:
        text = text.rstrip() + '\n\n' + block + '\n'
    doc.parent.mkdir(parents=True, exist_ok=True)
    doc.write_text(text)


def publish(name: str, data: dict[str, Any], markdown: str) -> None:
    """A speed benchmark's outputs: its JSON, its section and the summary at the top."""
    write_json(name, data)
    write_section(name, markdown)
    write_summary()


def write_summary() -> None:
    """The ``summary`` section: every speed result's checks, from bench/results/*.json."""
    rows = []
    for name in SPEED_RESULTS:
        path = RESULTS / f'{name}.json'
        if not path.exists():
            continue
        data = json.loads(path.read_text())
        for c in data.get('checks', []):
            rows.append([c['what'], c['measured'], c['target'], 'yes' if c['met'] else '**no**',
                         f'`bench/{name}.py`', data['machine'].get('commit', '?')])
    write_section('summary', '\n'.join([
        '## The ratios at a glance', '',
        table(['ratio', 'measured', 'target', 'met', 'by', 'commit'], rows)]))


def section(title: str, command: str, what: str, body: str, info: dict[str, Any]) -> str:
    """A benchmark's section: title, command, one paragraph of what is measured, its table and the
    machine line."""
    return '\n'.join([f'## {title}', '', f'`{command}`', '', what, '', body, '',
                      machine_line(info)])


def table(headers: list[str], rows: list[list[Any]]) -> str:
    """A markdown table; floats with 3 significant digits."""
    lines = ['| ' + ' | '.join(headers) + ' |', '|' + '---|' * len(headers)]
    lines += ['| ' + ' | '.join(_fmt(v) for v in row) + ' |' for row in rows]
    return '\n'.join(lines)


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f'{v:.3g}' if abs(v) < 1000 else f'{v:.0f}'
    return str(v)
