"""Shared by the benchmarks: machine description, JSON results, and their section of docs/benchmarks.md.

Each benchmark owns one section of ``docs/benchmarks.md`` between ``<!-- NAME:start -->`` and
``<!-- NAME:end -->`` and leaves the others alone.
"""
from __future__ import annotations

import json
import os
import platform
import re
import subprocess
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / 'bench' / 'results'
DOC = REPO / 'docs' / 'benchmarks.md'
DOC_HEADER = ('# Benchmarks\n\nEvery figure here was written by the script named in its section, '
              'on the machine it names. Re-run a section with its command.\n')


def machine() -> dict[str, Any]:
    """What the figures were measured on."""
    cpu = platform.processor() or ''
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                cpu = line.split(':', 1)[1].strip()
                break
    except OSError:
        pass
    try:
        commit = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], cwd=REPO, text=True,
                                capture_output=True, check=False).stdout.strip()
    except OSError:
        commit = ''
    return {'cpu': cpu, 'cores': os.cpu_count(), 'python': platform.python_version(),
            'platform': platform.platform(), 'commit': commit}


def machine_line(info: dict[str, Any]) -> str:
    return (f"Machine: {info['cpu']}, {info['cores']} cores, Python {info['python']}, "
            f"commit {info['commit'] or 'uncommitted'}.")


def write_json(name: str, data: dict[str, Any]) -> Path:
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f'{name}.json'
    path.write_text(json.dumps(data, indent=2, default=float) + '\n')
    return path


def write_section(name: str, markdown: str) -> None:
    """Replace (or append) this benchmark's section of docs/benchmarks.md."""
    DOC.parent.mkdir(parents=True, exist_ok=True)
    text = DOC.read_text() if DOC.exists() else DOC_HEADER
    start, end = f'<!-- {name}:start -->', f'<!-- {name}:end -->'
    block = f'{start}\n{markdown.rstrip()}\n{end}'
    pattern = re.compile(re.escape(start) + '.*?' + re.escape(end), re.S)
    text = pattern.sub(lambda _: block, text) if pattern.search(text) else text.rstrip() + '\n\n' + block + '\n'
    DOC.write_text(text)


def table(headers: list[str], rows: list[list[Any]]) -> str:
    """A markdown table; floats with 3 significant decimals."""
    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return f'{v:.3g}' if abs(v) < 1000 else f'{v:.0f}'
        return str(v)
    lines = ['| ' + ' | '.join(headers) + ' |', '|' + '---|' * len(headers)]
    lines += ['| ' + ' | '.join(fmt(v) for v in row) + ' |' for row in rows]
    return '\n'.join(lines)
