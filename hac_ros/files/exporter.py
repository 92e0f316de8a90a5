"""``hac export OUT -o FILE.npz``: what ``hac replay`` wrote, as numpy arrays.

Rows: T = the header stamps of ``/hac/pose`` (one row per metric camera pose, in stamp order; a
stamp published twice keeps its last message). The arrays (``np.load(FILE)``):

- ``stamps_ns`` (T,) int64: header stamps, nanoseconds (the input recording's clock);
- ``camera_position`` (T, 3) float64: the camera centre (or ``base_frame``'s origin when the replay
  was configured with one), metres, in ``metric_frame`` (default ``map_metric``), from
  ``/hac/pose``;
- ``camera_quat_xyzw`` (T, 4) float64: the rotation of that camera (optical axes) to
  ``metric_frame``, unit quaternion x, y, z, w, from ``/hac/pose``;
- ``joints_world`` (T, P, K, 3) float64: the ``/hac/human_joints`` message of the same header stamp,
  metres, ``metric_frame``; P = the most people in one frame, NaN blocks where a frame has fewer
  people (or no joints message at that stamp); K = the recording's joints per person (rosbag2
  ``custom_data`` written by the replay; ``joint_layout`` when given; SMPL-24's 24 otherwise);
- ``scale`` (T,) float64: metres per SLAM unit, the last ``/hac/scale`` logged at or before each
  stamp (``/hac/scale`` is logged at the stamp of the frame that produced it), NaN before the first.

Joints messages at a stamp without a ``/hac/pose`` are left out (counted in :class:`ExportResult`).
The file appears whole or not at all, and an existing FILE is never overwritten.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hac_ros.core.basics.errors import ArgumentError, HacError
from hac_ros.core.layouts import joints_per_person
from hac_ros.files.tum import rotations_to_quats
from hac_ros.recording.atomic import staged_output
from hac_ros.recording.reader import Recording
from hac_ros.recording.tracks import read_camera, read_scale
from msg_adapters import MessageError, pose_array_to_joints, stamp_to_ns

POSE_TOPIC, JOINTS_TOPIC, SCALE_TOPIC = '/hac/pose', '/hac/human_joints', '/hac/scale'


@dataclass
class ExportResult:
    """What was exported: the file, T, P, K and the joints messages left out (no pose stamp)."""

    path: Path
    frames: int
    people_max: int
    joints_per_person: int
    joints_frames: int
    joints_dropped: int

    def text(self) -> str:
        text = (f'hac export: {self.path}: {self.frames} poses, {self.joints_frames} joints frames '
                f'(up to {self.people_max} people, {self.joints_per_person} joints each)')
        if self.joints_dropped:
            text += (f'; {self.joints_dropped} joints messages at stamps without a /hac/pose left '
                     'out')
        return text


def _joints_per_person(rec: Recording, joint_layout: str | None) -> int:
    k_rec = rec.stated_joints_per_person
    if joint_layout is None:
        return rec.joints_per_person
    k = joints_per_person(joint_layout)
    if k is None:
        if k_rec is None:
            raise ArgumentError(f'{rec.path} does not say its joints per person: {{joint_layout}} '
                                'custom cannot tell K (give the built-in layout, or replay again)',
                                'joint_layout')
        return k_rec
    if k_rec is not None and k_rec != k:
        raise ArgumentError(f'{{joint_layout}} {joint_layout} has {k} joints per person but '
                            f'{rec.path} was replayed with {k_rec}', 'joint_layout')
    return k


def _read_joints(rec: Recording, k: int) -> dict[int, np.ndarray]:
    """Header stamp → people (P, K, 3) metres, metric_frame, of every /hac/human_joints message."""
    out: dict[int, np.ndarray] = {}
    if not rec.has(JOINTS_TOPIC):
        return out
    for log_ns, msg in rec.read(JOINTS_TOPIC):
        try:
            out[stamp_to_ns(msg.header.stamp)] = pose_array_to_joints(msg, k)
        except MessageError as exc:
            raise ArgumentError(f'{rec.path}: the {JOINTS_TOPIC} message logged at {log_ns} ns: '
                                f'{exc} ({{joint_layout}}?)', 'joint_layout') from exc
    return out


def export_arrays(output: str | Path, joint_layout: str | None = None
                  ) -> tuple[dict[str, np.ndarray], int]:
    """The arrays of the module docstring from the replay output ``output``, and the number of
    joints messages left out."""
    with Recording(output) as rec:
        if not rec.has(POSE_TOPIC):
            raise HacError(f'{output} has no {POSE_TOPIC} messages: not written by hac replay, or '
                           f'the estimate never converged; it contains: {rec.describe()}')
        k = _joints_per_person(rec, joint_layout)
        camera = read_camera(rec, POSE_TOPIC)
        scale = read_scale(rec, SCALE_TOPIC) if rec.has(SCALE_TOPIC) else None
        joints = _read_joints(rec, k)
    stamps = camera.stamps_ns
    # one row per stamp (the last message of a stamp), in stamp order
    last = len(stamps) - 1 - np.unique(stamps[::-1], return_index=True)[1]
    stamps, positions, rotations = stamps[last], camera.positions[last], camera.rotations[last]
    row = {int(s): i for i, s in enumerate(stamps.tolist())}
    kept = {s: people for s, people in joints.items() if s in row}
    people_max = max((len(p) for p in kept.values()), default=0)
    joints_world = np.full((len(stamps), people_max, k, 3), np.nan)
    for s, people in kept.items():
        joints_world[row[s], :len(people)] = people
    values = np.full(len(stamps), np.nan)
    if scale is not None and len(scale):
        idx = np.searchsorted(scale.stamps_ns, stamps, side='right') - 1
        values = np.where(idx >= 0, scale.values[np.clip(idx, 0, None)], np.nan)
    arrays = {'stamps_ns': stamps.astype(np.int64), 'camera_position': positions.astype(float),
              'camera_quat_xyzw': rotations_to_quats(rotations),
              'joints_world': joints_world, 'scale': values.astype(float)}
    return arrays, len(joints) - len(kept)


def export(output: str | Path, npz_path: str | Path, joint_layout: str | None = None
           ) -> ExportResult:
    """Write ``npz_path`` from the replay output ``output`` (refused if it exists)."""
    target = Path(npz_path)
    if target.exists() or target.is_symlink():
        raise HacError(f'{target} already exists: not overwritten (remove it or choose another '
                       'name)')
    if not Path(output).exists():
        raise HacError(f'replay output {output} does not exist')
    arrays, dropped = export_arrays(output, joint_layout)
    with staged_output(target) as staged, open(staged, 'wb') as handle:
        np.savez(handle, **arrays)  # type: ignore[arg-type]  # numpy's stub: allow_pickle
    joints = arrays['joints_world']
    return ExportResult(target, len(arrays['stamps_ns']), joints.shape[1], joints.shape[2],
                        int((~np.isnan(joints).all(axis=(2, 3))).any(axis=1).sum()), dropped)
