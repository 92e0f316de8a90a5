"""Scenes edited as a hostile user edits a recording (issue 43): a SLAM whose scale changes, people
out of sight, a joints gap, bursts of repeated frames. Each takes a bench/_accuracy_runs.Scene and
returns a new one whose truth still matches its inputs.

- :func:`rescaled`: the SLAM's scale follows a profile in time: its positions integrate each step
  at the scale of the moment and each map is the whole map placed about the camera of its
  moment at that moment's scale (a SLAM's tracking keeps its map consistent with its poses);
  :data:`PROFILES` has the fast change (30 % in 8 s) and the breathing one;
- :func:`blank_joints`: the joints frames of a span carry nobody (a people front end that keeps
  publishing empty PoseArrays while nobody is in view);
- :func:`drop_joints`: no joints message at all during a span (the HMR stopped);
- :func:`bursts`: every ``every_s`` one joints frame is resent ``copies`` times within
  ``within_s`` (a driver that repeats an image), each copy with its SLAM pose, the frame placed
  ``error`` too far (an HMR glitch): counted by samples the copies would outvote the others.

Stamps are int ns; spans are seconds from the scene's first pose.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

NS = 1_000_000_000
RESCALE_FACTOR, RESCALE_AT_S, RESCALE_S = 1.3, 40.0, 8.0  # the SLAM unit shrinks 1.3x in 8 s
BREATHING = ((0.05, 20.0), (0.05, 60.0))  # (amplitude of the log scale, period s): +-10 % at most


def _fast_change(t_s: np.ndarray) -> np.ndarray:
    done = np.clip((t_s - RESCALE_AT_S) / RESCALE_S, 0.0, 1.0)
    return RESCALE_FACTOR ** -done


def _breathing(t_s: np.ndarray) -> np.ndarray:
    return np.exp(sum(a * np.sin(2.0 * math.pi * t_s / period) for a, period in BREATHING))


# name -> the scale's factor (against its first value) at seconds from the first pose
PROFILES: dict[str, Callable[[np.ndarray], np.ndarray]] = {'fast': _fast_change,
                                                            'breathing': _breathing}


def rescaled(scene: Any, profile: str) -> Any:
    """``scene`` (a constant-scale one) seen by a SLAM whose scale (metres per SLAM unit) is the
    ``profile`` of :data:`PROFILES` times its own (module docstring); the truth rewritten."""
    first = int(scene.pose_stamps_ns[0])
    factor = PROFILES[profile]

    def at(stamp: int) -> float:
        return float(factor(np.array([(stamp - first) / NS]))[0])
    events, last, moved = [], None, None
    camera: tuple[np.ndarray, np.ndarray] | None = None  # (original, moved) camera centre
    for stamp, kind, payload in scene.events:
        if kind == 'pose':
            c = np.asarray(payload[1], dtype=float)
            moved = c.copy() if last is None else moved + (c - last) / at(stamp)
            last, camera = c, (c, moved)
            payload = (payload[0], moved.copy(), *payload[2:])
        elif kind == 'map' and camera is not None:
            points = camera[1] + (np.asarray(payload[0], dtype=float) - camera[0]) / at(stamp)
            payload = (points, *payload[1:])
        events.append((stamp, kind, payload))
    truth = scene.true_scale * factor((scene.pose_stamps_ns - first) / NS)
    return replace(scene, events=events, true_scale=truth)


def _span(scene: Any, start_s: float, end_s: float) -> tuple[int, int]:
    first = int(scene.pose_stamps_ns[0])
    return first + int(start_s * NS), first + int(end_s * NS)


def blank_joints(scene: Any, start_s: float, end_s: float) -> Any:
    """``scene`` with the joints frames in [start_s, end_s) emptied (no person; the frame stays)."""
    return _edit_joints(scene, start_s, end_s, drop=False)


def drop_joints(scene: Any, start_s: float, end_s: float) -> Any:
    """``scene`` without its joints frames in [start_s, end_s)."""
    return _edit_joints(scene, start_s, end_s, drop=True)


def _edit_joints(scene: Any, start_s: float, end_s: float, drop: bool) -> Any:
    """``scene`` with its joints frames in [start_s, end_s) dropped, or emptied (the frame kept
    without its people), their truth alike."""
    lo, hi = _span(scene, start_s, end_s)
    events, joints_world, person_ids = [], [], []
    k = -1
    for stamp, kind, payload in scene.events:
        if kind == 'joints':
            k += 1
            world, ids = scene.joints_world[k], scene.person_ids[k]
            if lo <= stamp < hi:
                if drop:
                    continue
                payload = (np.asarray(payload[0])[:0], *payload[1:])
                world, ids = np.asarray(world)[:0], np.asarray(ids)[:0]
            joints_world.append(world)
            person_ids.append(ids)
        events.append((stamp, kind, payload))
    return replace(scene, events=events, joints_world=joints_world, person_ids=person_ids)


def bursts(scene: Any, every_s: float = 15.0, copies: int = 100, within_s: float = 0.1,
           error: float = 0.12) -> Any:
    """``scene`` with a burst every ``every_s`` (the first after one period): the first joints
    frame with someone in it at or after the burst's time is placed ``error`` farther (every
    joint about the camera) and resent ``copies`` times, evenly within ``within_s`` after it,
    each copy with the SLAM pose of that frame at its own stamp."""
    first = int(scene.pose_stamps_ns[0])
    last = int(scene.pose_stamps_ns[-1])
    times = [first + int(k * every_s * NS) for k in range(1, int((last - first) / (every_s * NS)) + 1)]
    poses = {stamp: payload for stamp, kind, payload in scene.events if kind == 'pose'}
    events: list[tuple[int, str, tuple]] = []
    joints_world, person_ids = [], []
    k = 0
    for stamp, kind, payload in scene.events:
        if kind != 'joints':
            events.append((stamp, kind, payload))
            continue
        world, ids = scene.joints_world[k], scene.person_ids[k]
        k += 1
        due = bool(times) and stamp >= times[0] and len(payload[0]) and stamp in poses
        if due:
            times.pop(0)
            payload = (np.asarray(payload[0]) * (1.0 + error), *payload[1:])
        events.append((stamp, kind, payload))
        joints_world.append(world)
        person_ids.append(ids)
        if due:
            step = int(within_s * NS / copies)
            for j in range(1, copies + 1):
                events.append((stamp + j * step, 'pose', poses[stamp]))
                events.append((stamp + j * step, 'joints', payload))
                joints_world.append(world)
                person_ids.append(ids)
    order = sorted(range(len(events)), key=lambda i: (events[i][0], _RANK[events[i][1]], i))
    joint_index = {}
    n = 0
    for i, (_, kind, _) in enumerate(events):
        if kind == 'joints':
            joint_index[i] = n
            n += 1
    sorted_events = [events[i] for i in order]
    world_sorted = [joints_world[joint_index[i]] for i in order if events[i][1] == 'joints']
    ids_sorted = [person_ids[joint_index[i]] for i in order if events[i][1] == 'joints']
    stamps = np.array(sorted({s for s, kind, _ in sorted_events if kind == 'pose'}), dtype=np.int64)
    index = np.clip(np.searchsorted(scene.pose_stamps_ns, stamps, side='right') - 1, 0, None)
    return replace(scene, events=sorted_events, joints_world=world_sorted, person_ids=ids_sorted,
                   pose_stamps_ns=stamps, true_scale=scene.true_scale[index],
                   gt_R_wc=scene.gt_R_wc[index], gt_c=scene.gt_c[index])


_RANK = {'map': 0, 'pose': 1, 'joints': 2}
