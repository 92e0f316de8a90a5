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
import time
from importlib import metadata
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
            'platform': platform.platform(), 'commit': commit, 'versions': versions(),
            'speed_reference_ms': speed_reference()}


VERSIONED = ('numpy', 'scipy', 'rosbags', 'rclpy')


def versions() -> dict[str, str]:
    """The installed versions of the libraries the figures depend on ('' when not installed)."""
    found = {}
    for name in VERSIONED:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = ''
    return found


def speed_reference(repeats: int = 7) -> dict[str, float]:
    """This machine's speed now, to compare runs made on different hosts or days: the median ms of
    a fixed pure-Python loop (1M additions) and of the literal cone median over 1M fixed points
    (one ray; numpy). The issue's targets were set where the literal method cost ~180 ms per
    frame at 1M points (bench/core_speed.py measures that per frame). Written out here, not
    hac_ros.core.reference.literal_cone_median: a reference must not change when the package does."""
    import numpy as np

    rng = np.random.default_rng(0)
    points = rng.random((1_000_000, 3)) - 0.5
    direction = np.array([0.0, 0.0, 1.0])
    python_ms, numpy_ms = [], []
    for _ in range(repeats):
        start = time.perf_counter()
        total = 0
        for i in range(1_000_000):
            total += i
        python_ms.append((time.perf_counter() - start) * 1e3)
        start = time.perf_counter()
        dist = np.sqrt(np.einsum('ij,ij->i', points, points))
        cos = (points @ direction) / dist
        np.median(dist[cos > 0.99])
        numpy_ms.append((time.perf_counter() - start) * 1e3)
    return {'python_loop_1m_ms': float(np.median(python_ms)),
            'numpy_cone_1m_ms': float(np.median(numpy_ms))}


def run_machine(info: dict[str, Any]) -> str:
    """A short name of the machine and commit of one run, for a table column."""
    cpu = str(info.get('cpu', '?')).replace('(R)', '').replace(' Processor', '').replace('  ', ' ')
    ref = info.get('speed_reference_ms')
    speed = f", ref {ref['numpy_cone_1m_ms']:.0f} ms" if ref else ''
    return f"{cpu.strip()}{speed}, {info.get('commit') or '?'}"


def machine_line(info: dict[str, Any]) -> str:
    line = (f"Machine: {info['cpu']}, {info['cores']} cores, Python {info['python']}, "
            f"commit {info['commit'] or 'uncommitted'}.")
    if info.get('versions'):
        line += ' ' + ', '.join(f'{k} {v}' for k, v in info['versions'].items() if v) + '.'
    ref = info.get('speed_reference_ms')
    if ref:
        line += (f" Speed reference (median ms, `bench/_report.py` speed_reference): Python loop "
                 f"{ref['python_loop_1m_ms']:.0f}, numpy cone over 1M points "
                 f"{ref['numpy_cone_1m_ms']:.1f}.")
    return line


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
