"""``hac demo`` (``make demo``): replay, evaluate and plot the bundled sample recording.

``hac demo --live``: the node instead of the replay. ``hac_node`` runs as a process of its own,
``hac play`` feeds it the same recording over DDS, and the summary ``hac replay --mode online``
prints is made from what comes back (:mod:`hac_ros.ros.live`).

The recording ``bags/demo_walk`` is only read. Its results go to ``out/`` (``out/replay`` the
calibrated recording, ``out/eval.md`` and ``out/eval.json`` the metrics, ``out/*.png`` the
figures, ``out/tum/`` the trajectories for evo); results of an earlier demo there are replaced,
nothing else in ``out/`` is touched. Without the bundled recording (an installed package, or a
checkout before it was added) a 20-second ``walk`` recording is simulated into a temporary
directory.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import shutil
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

from hac_ros.cli import show
from hac_ros.core.basics.errors import HacError
from hac_ros.recording.atomic import signals_held

REPO = Path(__file__).resolve().parents[2]

DEMO_RECORDING = Path('bags') / 'demo_walk'

SIMULATED = {'scenario': 'walk', 'seed': 0, 'duration_s': 20.0}  # when the recording is absent

RESULTS = ('replay', 'tum', 'eval.md', 'eval.json', 'trajectories.png', 'scale.png',
           'fallback.png', 'heights.png')

def find_recording(explicit: str | None) -> Path | None:
    """The demo recording: the one given, else ./bags/demo_walk, else the repository's."""
    if explicit:
        path = Path(explicit)
        if not path.exists():
            raise HacError(f'demo recording {path} does not exist')
        return path
    for candidate in (Path.cwd() / DEMO_RECORDING, REPO / DEMO_RECORDING):
        if candidate.exists():
            return candidate
    return None

def simulate_into(directory: Path) -> Path:
    """``hac simulate walk`` into ``directory``; returns the recording's path."""
    from hac_ros.cli import main

    path = directory / 'demo_walk'
    code = main(['simulate', str(SIMULATED['scenario']), '-o', str(path), '--seed',
                 str(SIMULATED['seed']), '--duration', str(SIMULATED['duration_s'])])
    if code != 0 or not path.exists():
        raise HacError(f'could not simulate a demo recording (hac simulate exited with {code})')
    return path

def recording_or_simulated(recording: str | None, tmp: Path) -> Path:
    """The demo recording (:func:`find_recording`), else one simulated into ``tmp``."""
    source = find_recording(recording)
    if source is None:
        show(f'{DEMO_RECORDING} not found: simulating a {SIMULATED["duration_s"]:.0f} s '
              f'"{SIMULATED["scenario"]}" recording instead')
        source = simulate_into(tmp)
    return source


def clear_results(out_dir: Path) -> None:
    """Remove the results of an earlier demo (only the names the demo writes)."""
    for name in RESULTS:
        path = out_dir / name
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()

@contextlib.contextmanager
def results_dir(out_dir: Path) -> Iterator[None]:
    """``out_dir`` for the demo's results: made if missing (with its parents), an earlier demo's
    results cleared. On an error or an interruption the results written so far are removed and so
    are the directories made here: nothing partial, no empty ``-o NEWDIR`` left behind."""
    made = [p for p in (out_dir, *out_dir.parents) if not p.exists()]  # the deepest first
    with signals_held():  # a signal cannot land between the mkdir and the clean-up's reach
        out_dir.mkdir(parents=True, exist_ok=True)
    try:
        clear_results(out_dir)
        yield
    except BaseException:
        with signals_held():
            clear_results(out_dir)
            for path in made:
                with contextlib.suppress(OSError):  # not empty: something else is in it
                    path.rmdir()
        raise


def demo(out_dir: Path, recording: str | None = None) -> int:
    from hac_ros.cli.terminal import progress_bar
    from hac_ros.evaluation.evaluate import evaluate
    from hac_ros.evaluation.plots import make_plots
    from hac_ros.replay.feeder import offline_run
    from hac_ros.replay.replayer import replay

    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix='hac_demo_') as tmp:
        source = recording_or_simulated(recording, Path(tmp))
        with results_dir(out_dir):
            summary = replay(source, out_dir / 'replay', mode='offline',
                             export_tum=out_dir / 'tum', progress=progress_bar('msg'))
            show(summary.text())
            show('')
            result = evaluate(out_dir / 'replay', source, offline_run=offline_run)
            show(result.text())
            (out_dir / 'eval.json').write_text(json.dumps(result.as_dict(), indent=2) + '\n',
                                               encoding='utf-8')
            (out_dir / 'eval.md').write_text(result.markdown() + '\n', encoding='utf-8')
            show('')
            for name, path in make_plots(out_dir / 'replay', out_dir, source).items():
                show(f'figure {name}: {path}')
    show(f'\ndemo done in {time.perf_counter() - start:.1f} s; results in {out_dir}/')
    return 0


def live_demo(recording: str | None, rate: float, params_file: str | None) -> int:
    """``hac demo --live``: the recording played into hac_node, its summary from DDS."""
    from hac_ros.ros.live import live_run

    with tempfile.TemporaryDirectory(prefix='hac_demo_') as tmp:
        source = recording_or_simulated(recording, Path(tmp))
        show(f'starting hac_node and playing {source} into it at {rate:g}x real time '
              '(hac play) ...')
        summary = live_run(source, rate, params_file)
    show(summary.text())
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--recording', metavar='IN',
                        help=f'recording to use instead of {DEMO_RECORDING}')
    parser.add_argument('--live', action='store_true',
                        help='run hac_node and feed it the recording with hac play over DDS '
                        '(localhost); print the summary from what comes back')
    parser.add_argument('--rate', type=float, default=1.0,
                        help='--live: playback speed, a factor of real time (default 1)')
    parser.add_argument('--params', metavar='FILE',
                        help='--live: the node\'s parameters file (default: its defaults)')
    parser.add_argument('-o', '--out-dir', metavar='DIR', default='out',
                        help='where the results go (default out/; earlier demo results replaced)')


def run(args: argparse.Namespace) -> int:
    if args.live:
        if not args.rate > 0:
            raise HacError(f'--rate {args.rate}: must be > 0')
        return live_demo(args.recording, args.rate, args.params)
    return demo(Path(args.out_dir), args.recording)
