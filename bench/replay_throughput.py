#!/usr/bin/env python3
"""Replay throughput: ``hac replay`` against a bare read of the same recording, as a ratio.

    python bench/replay_throughput.py [--duration 600] [--map-points 100000] [--rounds 3]
                                      [--keep DIR]

The recording (bench/_scene.py ``write_recording``, not timed): ``--duration`` seconds of the room
scene at 30 Hz, a SLAM pose and the HMR joints per frame and a ``--map-points`` map republished
every second; mcap, in a temporary directory. Timed, in rounds of three side by side in this
process: the bare read (rosbags' AnyReader over the recording, every message deserialized with the
ROS 2 Jazzy typestore: bench/_scene.py ``read_recording``) and ``hac_ros.replay.replayer.replay``
in ``offline`` mode (the default), then in ``online`` mode, each from opening the recording to the
written OUT. One untimed bare read comes first; then a block of READS_PER_BLOCK bare reads before
and after every replay. Ratio per round and mode = replay seconds / the median of the bare reads
in the two blocks around it; the median over the rounds is the figure. Guard: <= 30x offline, <= 35x
online (a regression guard on today's features, not a goal).
Prints, writes bench/results/replay_throughput.json and its section of docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import check, command_line, machine, publish, section, table
from _scene import read_recording, write_recording

from hac_ros.replay.replayer import replay

NAME = 'replay_throughput'
MODES = ('offline', 'online')
TARGET_RATIO = {'offline': 30.0, 'online': 35.0}  # guards, per mode
READS_PER_BLOCK = 3  # bare reads between two replays


def bare_read_s(recording: Path) -> float:
    """Seconds to read and deserialize every message of ``recording`` (bench/_scene.py)."""
    start = time.perf_counter()
    read_recording(recording)
    return time.perf_counter() - start


def replay_s(recording: Path, out: Path, mode: str) -> float:
    """Seconds of ``replay(recording, out, mode=mode)``; ``out`` is removed afterwards."""
    if out.exists():
        shutil.rmtree(out)
    start = time.perf_counter()
    replay(recording, out, mode=mode)
    seconds = time.perf_counter() - start
    shutil.rmtree(out)
    return seconds


def run(work: Path, duration_s: float, map_points: int, rounds: int) -> dict[str, Any]:
    recording = work / 'recording'
    if recording.exists():
        shutil.rmtree(recording)
    start = time.perf_counter()
    info = write_recording(recording, duration_s, map_points)
    print(f"recording: {info['frames']} frames, {info['maps']} maps of {map_points:,} points, "
          f"{info['bytes'] / 1e6:.0f} MB (written in {time.perf_counter() - start:.0f} s)",
          flush=True)
    bare_read_s(recording)  # untimed: the page cache and rosbags' generated deserializers
    # bare reads in blocks between the replays: each replay is divided by the median of the
    # blocks on either side of it (one 2-3 s read alone swings by up to 40 % here)
    blocks = [[bare_read_s(recording) for _ in range(READS_PER_BLOCK)]]
    seconds: dict[str, list[float]] = {mode: [] for mode in MODES}
    bare: dict[str, list[float]] = {mode: [] for mode in MODES}
    for k in range(rounds):
        for mode in MODES:
            seconds[mode].append(replay_s(recording, work / 'out', mode))
            blocks.append([bare_read_s(recording) for _ in range(READS_PER_BLOCK)])
            bare[mode].append(float(np.median(blocks[-2] + blocks[-1])))
        print(f'round {k + 1}: ' + ', '.join(
            f'{mode} {seconds[mode][-1]:.2f} s / bare read {bare[mode][-1]:.2f} s '
            f'({seconds[mode][-1] / bare[mode][-1]:.2f}x)' for mode in MODES), flush=True)
    ratios = {mode: [s / b for s, b in zip(seconds[mode], bare[mode])] for mode in MODES}
    return {'recording': info, 'seconds': seconds, 'bare_s': bare, 'bare_blocks': blocks,
            'ratios': ratios,
            'median_ratio': {mode: float(np.median(r)) for mode, r in ratios.items()}}


def report(data: dict[str, Any]) -> str:
    rec, seconds, bare = data['recording'], data['seconds'], data['bare_s']
    rows = [[mode, f"{data['median_ratio'][mode]:.2f}x",
             ', '.join(f'{r:.2f}' for r in data['ratios'][mode]),
             float(np.median(seconds[mode])), float(np.median(bare[mode]))]
            for mode in MODES]
    return section(
        'Replay throughput', data['command'],
        f"`hac replay` (`hac_ros.replay.replayer.replay`, markers on, mcap out) of the room scene's "
        f"{rec['duration_s'] / 60:.0f}-minute 30 Hz recording ({rec['frames']} frames, a "
        f"{rec['map_points']:,}-point map every second, {rec['bytes'] / 1e6:.0f} MB mcap) "
        'against the bare read of the same recording (rosbags AnyReader, every message '
        'deserialized with the ROS 2 Jazzy typestore), in one process: rounds of offline / '
        f'online, with a block of {READS_PER_BLOCK} bare reads before and after each replay. '
        'Ratio: replay s / the median of the bare reads in the blocks on either side of it, '
        f'median over {len(seconds["offline"])} rounds. Guard: <= {TARGET_RATIO["offline"]:g}x offline, '
        f'<= {TARGET_RATIO["online"]:g}x online. The seconds are this host\'s raw data.',
        table(['mode', 'median ratio', 'ratio per round', 'replay median s',
               'bare read median s'], rows),
        data['machine'])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, default=600.0, help='recording length, s')
    parser.add_argument('--map-points', type=int, default=100_000, help='points per map message')
    parser.add_argument('--rounds', type=int, default=3)
    parser.add_argument('--keep', metavar='DIR', help='write (and keep) the recording in DIR')
    args = parser.parse_args(argv)
    info = machine()
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix='hac_bench_replay_'))
    work.mkdir(parents=True, exist_ok=True)
    try:
        data = run(work, args.duration, args.map_points, args.rounds)
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    data.update(machine=info, command=command_line(__file__, argv), checks=[
        check(f'replay {mode} vs bare rosbags read', f'{ratio:.2f}x',
              f'<= {TARGET_RATIO[mode]:g}x', ratio <= TARGET_RATIO[mode])
        for mode, ratio in data['median_ratio'].items()])
    markdown = report(data)
    publish(NAME, data, markdown)
    print(markdown)
    return 0


if __name__ == '__main__':
    sys.exit(main())
