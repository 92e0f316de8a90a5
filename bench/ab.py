#!/usr/bin/env python3
"""A/B: does an optimisation pay? Alternated pairs of probes of two revisions, in one run.

    python bench/ab.py BASE CANDIDATE --probe per_frame|replay|node [--mode offline|online]
                       [--pairs 5] [--duration S] [--name TEXT] [--record]
    python bench/ab.py --render

BASE has the optimisation, CANDIDATE is BASE with it removed. Each revision is checked out into a
git worktree under /tmp, and the probe (bench/ab_probe.py of *this* checkout: both sides measured by
the same instrument, with ``PYTHONPATH`` set to the side's worktree) runs in a fresh process per
measurement, alternately: A B, B A, A B, ... Each probe returns one number, lower is better
(bench/ab_probe.py):

- ``per_frame``: our ms per frame at 1M map points (plain ms: bench/ab_probe.py says why);
- ``replay``: replay s / bare rosbags read s of a fixed recording (the room scene, ``--duration``
  seconds, default 120, written once by bench/_scene.py into /tmp/hac_ab_cache), ``--mode``;
- ``node``: hac_node p99 / echo-floor p99 at 100k map points, ``--duration`` s each (default 20).

Rule: readability wins; an optimisation stays only when removing it breaks a speed guard or
worsens its ratio by >= 1.5x: the median pair's B/A >= 1.5 and at least 4 of 5 pairs (80 % of
them) show B/A >= 1.5. Prints each pair, the
verdict and a table row for docs/benchmarks.md; ``--record`` appends the row to
bench/results/ab.json and re-renders the section "Optimisations measured" (``--render`` only
re-renders it).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import REPO, RESULTS, machine, table, write_section

PROBE = Path(__file__).resolve().parent / 'ab_probe.py'
CACHE = Path('/tmp/hac_ab_cache')
AB_JSON = RESULTS / 'ab.json'
WORSE, BETTER = 1.5, 1 / 1.5  # B/A beyond these: removing it worsens / improves the ratio 1.5x
AGREE_SHARE = 0.8  # 4 of 5 pairs
REPLAY_MAP_POINTS = 100_000
PROBE_TIMEOUT_S = 1800


def git(*args: str) -> str:
    return subprocess.run(['git', '-C', str(REPO), *args], check=True, text=True,
                          capture_output=True).stdout.strip()


def add_worktree(rev: str, side: str) -> Path:
    """``rev`` checked out (detached) at /tmp/hac_ab_<side>_<pid>, its modules compiled."""
    path = Path(f'/tmp/hac_ab_{side}_{os.getpid()}')
    git('worktree', 'add', '--detach', str(path), rev)
    subprocess.run([sys.executable, '-m', 'compileall', '-q', str(path / 'hac_ros'),
                    str(path / 'msg_adapters')], check=False, capture_output=True)
    return path


def replay_recording(duration_s: float) -> Path:
    """The replay probe's recording, written once (by bench/_scene.py, the same for both sides)."""
    from _scene import write_recording

    path = CACHE / f'room_{duration_s:g}s_{REPLAY_MAP_POINTS}'
    if not path.exists():
        CACHE.mkdir(parents=True, exist_ok=True)
        partial = CACHE / f'{path.name}.{os.getpid()}'
        write_recording(partial, duration_s, REPLAY_MAP_POINTS)
        partial.rename(path)
    return path


def probe(tree: Path, args: list[str]) -> dict[str, Any]:
    """One probe of the checkout at ``tree`` in a fresh process: its JSON line."""
    env = {**os.environ, 'PYTHONPATH': os.pathsep.join(
        [str(tree), *filter(None, [os.environ.get('PYTHONPATH')])])}
    done = subprocess.run([sys.executable, str(PROBE), *args], cwd=tree, env=env, text=True,
                          capture_output=True, timeout=PROBE_TIMEOUT_S)
    lines = done.stdout.strip().splitlines()
    if done.returncode != 0 or not lines:
        raise RuntimeError(f'probe {args} in {tree} failed ({done.returncode}):\n'
                           f'{done.stderr[-3000:]}')
    result = json.loads(lines[-1])
    if Path(result['tree']) != tree.resolve():
        raise RuntimeError(f"the probe measured {result['tree']}, not {tree}: PYTHONPATH did not "
                           'take precedence over the installed package')
    return result


def verdict(ratios: list[float]) -> dict[str, Any]:
    """The issue's rule over the pairs' B/A."""
    median = float(np.median(ratios))
    worse = sum(r >= WORSE for r in ratios)
    better = sum(r <= BETTER for r in ratios)
    need = math.ceil(AGREE_SHARE * len(ratios))
    keep = median >= WORSE and worse >= need
    if keep:
        text = (f'removing it worsens the ratio by >= {WORSE:g}x (median {median:.2f}, {worse} of '
                f'{len(ratios)} pairs agree): keep')
    else:
        text = (f'does not pay: remove (median {median:.2f}, {worse} of {len(ratios)} pairs '
                f'>= {WORSE:.2f}' + (f', {better} <= {BETTER:.2f}' if better else '') + ')')
    return {'median': median, 'worse': WORSE, 'agree': worse, 'better': better, 'keep': keep,
            'verdict': text}


def measure(base: str, candidate: str, probe_args: list[str], pairs: int) -> dict[str, Any]:
    """``pairs`` alternated pairs of probes of ``base`` (A) and ``candidate`` (B)."""
    trees: dict[str, Path] = {}
    values: list[dict[str, float]] = []
    raws: list[dict[str, Any]] = []  # each probe's raw figures
    try:
        trees['A'] = add_worktree(base, 'A')
        trees['B'] = add_worktree(candidate, 'B')
        for i in range(pairs):
            pair: dict[str, float] = {}
            raws.append({})
            for side in ('A', 'B') if i % 2 == 0 else ('B', 'A'):
                start = time.perf_counter()
                result = probe(trees[side], probe_args)
                pair[side] = result['value']
                raws[-1][side] = {k: v for k, v in result.items() if k not in ('probe', 'tree')}
                raw = ', '.join(f'{k} {_short(v)}' for k, v in result.items()
                                if k not in ('probe', 'tree', 'value'))
                print(f'  pair {i + 1} {side}: {pair[side]:.4g} ({raw}; '
                      f'{time.perf_counter() - start:.0f} s)', flush=True)
            values.append(pair)
            print(f"pair {i + 1}: A {pair['A']:.4g}, B {pair['B']:.4g}, "
                  f"B/A {pair['B'] / pair['A']:.3f}", flush=True)
    finally:
        for tree in trees.values():
            subprocess.run(['git', '-C', str(REPO), 'worktree', 'remove', '--force', str(tree)],
                           check=False, capture_output=True)
    return {'pairs': [{'A': p['A'], 'B': p['B'], 'B/A': p['B'] / p['A'], 'raw': raw}
                      for p, raw in zip(values, raws)]}


def _short(value: Any) -> str:
    if isinstance(value, float):
        return f'{value:.4g}'
    if isinstance(value, list):
        return '[' + ', '.join(_short(v) for v in value) + ']'
    return str(value)


def row(entry: dict[str, Any]) -> list[Any]:
    return [entry['name'], entry['probe'], f"`{entry['base']}` → `{entry['candidate']}`",
            len(entry['pairs']), f"{entry['median']:.2f}", f"{entry['worse']:.2f}",
            f"{entry['agree']} of {len(entry['pairs'])}",
            (f"keep: without it {entry['guard']}" if entry.get('guard') else 'keep')
            if entry['keep'] else 'remove',
            entry['machine'].get('cpu', '?'), entry['date']]


# 'keep at B/A >=': the rule the row was judged by (its own WORSE; issue 18's rows: 1.10)
HEADERS = ['optimisation removed', 'probe', 'base → candidate', 'pairs', 'median B/A',
           'keep at B/A >=', 'pairs at or above', 'verdict', 'machine', 'date']


def render(entries: list[dict[str, Any]]) -> str:
    """The section "Optimisations measured" of docs/benchmarks.md, from bench/results/ab.json."""
    body = table(HEADERS, [row(e) for e in entries]) if entries else '(none measured yet)'
    return '\n'.join([
        '## Optimisations measured', '',
        '`python bench/ab.py BASE CANDIDATE --probe per_frame|replay|node [--mode online] '
        '--pairs 5 --record`: BASE has the optimisation, CANDIDATE is BASE without it. Each '
        'probe (bench/ab_probe.py, lower is better: `per_frame` our ms per frame at 1M map '
        'points, `replay` replay s / bare rosbags read s, `node` hac_node p99 / echo p99 at 100k '
        'points) runs in a fresh process, alternated A B, B A, ...; B/A per pair. Kept when the '
        f'median B/A >= {WORSE:.2f} and at least 4 of 5 pairs agree, or when removing it breaks a '
        'speed guard (issue 28: readability wins). Rows measured under the earlier rule (keep at '
        '1.10, issue 18) say so in their column "keep at B/A >=". A revision that '
        'is not on main was a throwaway commit made for the measurement: it restores (or, for '
        'the CDR writers, removes) only what its row names.', '', body])


def load() -> list[dict[str, Any]]:
    return json.loads(AB_JSON.read_text()) if AB_JSON.exists() else []


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('base', nargs='?', help='the revision with the optimisation')
    parser.add_argument('candidate', nargs='?', help='the revision without it')
    parser.add_argument('--probe', choices=('per_frame', 'replay', 'node'))
    parser.add_argument('--mode', choices=('offline', 'online'), default='offline',
                        help='replay probe: the replay mode')
    parser.add_argument('--pairs', type=int, default=5)
    parser.add_argument('--duration', type=float,
                        help='replay: recording seconds (120); node: measured seconds (20)')
    parser.add_argument('--name', help="what the candidate removes (default: its commit subject)")
    parser.add_argument('--guard-broken', metavar='TEXT',
                        help='the speed guard the candidate breaks, measured by its bench (e.g. '
                             '"replay offline 30.40x > 30x at 2e057cd"): kept whatever the ratio')
    parser.add_argument('--record', action='store_true',
                        help='append to bench/results/ab.json and re-render its section')
    parser.add_argument('--render', action='store_true',
                        help='only re-render the section from bench/results/ab.json')
    args = parser.parse_args(argv)
    if args.render:
        write_section('ab', render(load()))
        return 0
    if not (args.base and args.candidate and args.probe):
        parser.error('BASE, CANDIDATE and --probe are needed (or --render)')
    base, candidate = (git('rev-parse', '--short', rev) for rev in (args.base, args.candidate))
    probe_args = [args.probe]
    if args.probe == 'replay':
        recording = replay_recording(args.duration or 120.0)
        probe_args += ['--recording', str(recording), '--mode', args.mode]
    elif args.probe == 'node':
        probe_args += ['--duration', str(args.duration or 20.0)]
    name = args.probe + (f':{args.mode}' if args.probe == 'replay' else '')
    print(f'{name}: A = {base}, B = {candidate}, {args.pairs} pairs', flush=True)
    result = measure(base, candidate, probe_args, args.pairs)
    result.update(verdict([p['B/A'] for p in result['pairs']]))
    if args.guard_broken:  # the rule's other half: removing it breaks a speed guard
        result.update(keep=True, guard=args.guard_broken,
                      verdict=f"{result['verdict'].split(':')[0]}, but removing it breaks a speed "
                              f'guard ({args.guard_broken}): keep')
    entry = {'name': args.name or git('log', '-1', '--format=%s', candidate)[:60],
             'base': base, 'candidate': candidate, 'probe': name, **result,
             'machine': {k: v for k, v in machine().items() if k != 'commit'},
             'date': time.strftime('%Y-%m-%d')}
    print(result['verdict'])
    print('| ' + ' | '.join(str(v) for v in row(entry)) + ' |')
    if args.record:
        AB_JSON.parent.mkdir(parents=True, exist_ok=True)
        AB_JSON.write_text(json.dumps(load() + [entry], indent=2) + '\n')
        write_section('ab', render(load()))
    return 0


if __name__ == '__main__':
    sys.exit(main())
