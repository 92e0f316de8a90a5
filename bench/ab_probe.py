#!/usr/bin/env python3
"""One A/B measurement for bench/ab.py of the checkout on PYTHONPATH: one number, lower is better.

    PYTHONPATH=CHECKOUT python bench/ab_probe.py per_frame
    PYTHONPATH=CHECKOUT python bench/ab_probe.py replay --recording DIR [--mode offline|online]
    PYTHONPATH=CHECKOUT python bench/ab_probe.py node [--duration 20]

The replay and node probes return a ratio to a reference that does not change with the package,
measured in the same process (a drift of the machine's speed between probes cancels); per_frame
returns plain ms:

- ``per_frame``: our median ms per frame at 1M map points (bench/core_speed.py ``measure``, 1000
  frames after the warm-up; not pinned, so the scheduler may dodge a busy core). Plain ms, not the
  ratio to the literal method: that is the same code on both sides, and its time swings far more
  than ours when another process runs (its 192 MB temporaries per frame; seen here: 304 to 494 ms
  within a minute while ours stayed within 0.34 to 0.36 ms), so dividing by it adds noise; the
  alternated pairs take care of the machine's drift. The literal method's ms (one frame) is
  printed too.
- ``replay``: ``replay()`` seconds of the recording at ``--recording`` / the seconds of a bare read
  of it (rosbags AnyReader + deserialize_cdr), the fastest of each: after one untimed bare read,
  bare read, replay, bare read, replay, bare read (the machine's noise only ever adds time).
- ``node``: hac_node's p99 latency at 100k map points / the echo floor's, one run of each
  (``--duration`` measured seconds, echo first: bench/node_latency.py ``run``).

Prints one JSON line: the probe, its ``value``, the checkout whose ``hac_ros`` was measured
(``tree``) and the raw figures behind the value.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import measured_tree

PER_FRAME_POINTS = 1_000_000
NODE_POINTS = 100_000


def per_frame() -> dict[str, Any]:
    import core_speed
    from _scene import room_scene

    frames = 1000
    r = core_speed.measure(room_scene(core_speed.WARMUP_FRAMES + frames), PER_FRAME_POINTS,
                           frames, literal_frames=1)
    return {'value': r['ours_median_ms'], 'literal_ms': r['literal_median_ms']}


def replay(recording: Path, mode: str, repeats: int = 2) -> dict[str, Any]:
    import replay_throughput as rt

    rt.bare_read_s(recording)  # untimed: page cache and rosbags' generated deserializers
    bare, replays = [rt.bare_read_s(recording)], []
    with tempfile.TemporaryDirectory(prefix='hac_ab_replay_') as work:
        for _ in range(repeats):
            replays.append(rt.replay_s(recording, Path(work) / 'out', mode))
            bare.append(rt.bare_read_s(recording))
    return {'value': min(replays) / min(bare), 'replay_s': replays, 'bare_s': bare, 'mode': mode}


def node(duration_s: float) -> dict[str, Any]:
    import node_latency  # sets the DDS environment before rclpy is imported

    r = node_latency.run(NODE_POINTS, duration_s, rounds=1, extra_rows=False)
    return {'value': r['p99_ratio'], 'node_p99_ms': r['node']['p99_ms'],
            'echo_p99_ms': r['echo']['p99_ms'], 'dropped': r['node']['dropped']}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('probe', choices=('per_frame', 'replay', 'node'))
    parser.add_argument('--recording', type=Path, help='replay: the recording to replay')
    parser.add_argument('--mode', choices=('offline', 'online'), default='offline')
    parser.add_argument('--duration', type=float, default=20.0,
                        help='node: measured seconds per node')
    args = parser.parse_args(argv)
    if args.probe == 'per_frame':
        result = per_frame()
    elif args.probe == 'replay':
        if args.recording is None:
            parser.error('replay needs --recording')
        result = replay(args.recording, args.mode)
    else:
        result = node(args.duration)
    print(json.dumps({'probe': args.probe, 'tree': str(measured_tree()), **result}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
