"""Topics of a recording as numpy tracks: cameras, joints, scales, ground truth, outputs."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hac_ros.bridge.messages import (
    DIAGNOSTICS,
    HUMAN_JOINTS,
    ODOMETRY,
    POSE,
    SAMPLE_FIELDS,
    SAMPLES,
    SCALE,
)
from hac_ros.bridge.topics import in_root
from hac_ros.core.basics.errors import HacError
from hac_ros.core.layouts import SMPL24, JointLayout
from hac_ros.recording.reader import GT_CAMERA, GT_JOINTS, GT_SCALE, Recording
from msg_adapters import MessageError, pose_array_to_joints, pose_msg_to_rt, stamp_to_ns


# ============================================================================ tracks
def _no_stamps() -> np.ndarray:
    return np.zeros(0, dtype=np.int64)


@dataclass
class _Track:
    """Values at header stamps: stamps_ns (N,) int nanoseconds (empty by default)."""

    stamps_ns: np.ndarray = field(default_factory=_no_stamps)

    def __len__(self) -> int:
        return len(self.stamps_ns)


@dataclass
class CameraTrack(_Track):
    """positions (T, 3) camera centres, metres (SLAM units for a SLAM track), in the track's
    world/metric frame; rotations (T, 3, 3) camera to that frame."""

    positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    rotations: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))


@dataclass
class JointsTrack(_Track):
    """joints[f]: (P_f, K, 3) metres, the track's frame (P_f people in frame f, K joints each:
    the recording's joint layout)."""

    joints: list[np.ndarray] = field(default_factory=list)


@dataclass
class ScaleTrack(_Track):
    """values (S,) metres per SLAM unit."""

    values: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def at(self, stamps_ns: np.ndarray) -> np.ndarray:
        """As a step function (the latest value at or before each stamp; the first before it)."""
        if not len(self.stamps_ns):
            return np.full(len(stamps_ns), np.nan)
        at = np.asarray(stamps_ns, dtype=np.int64)
        idx = np.searchsorted(self.stamps_ns, at, side='right') - 1
        return self.values[np.clip(idx, 0, len(self.values) - 1)]


@dataclass
class Truth:
    """Ground truth of a recording (any part may be missing): docs/interface.md, "Recordings"."""

    camera: CameraTrack | None
    joints: JointsTrack | None
    scale: ScaleTrack | None


def read_camera(recording: Recording, topic: str) -> CameraTrack:
    """PoseStamped or Odometry messages of ``topic`` as a camera track (header stamps)."""
    stamps, positions, rotations = [], [], []
    for _, msg in recording.read(topic):
        R, c = pose_msg_to_rt(msg)
        stamps.append(stamp_to_ns(msg.header.stamp))
        rotations.append(R)
        positions.append(c)
    if not stamps:
        return CameraTrack()
    return CameraTrack(np.asarray(stamps, dtype=np.int64), np.asarray(positions, dtype=float),
                       np.asarray(rotations, dtype=float))


def read_joints(recording: Recording, topic: str) -> JointsTrack:
    """PoseArray messages of ``topic``: (P, K, 3) joints per header stamp, K the recording's
    (:attr:`Recording.joints_per_person`); malformed ones skipped."""
    stamps, joints = [], []
    k = recording.joints_per_person
    for _, msg in recording.read(topic):
        try:
            people = pose_array_to_joints(msg, k)
        except MessageError:
            continue
        stamps.append(stamp_to_ns(msg.header.stamp))
        joints.append(people)
    return JointsTrack(np.asarray(stamps, dtype=np.int64), joints)


def read_scale(recording: Recording, topic: str) -> ScaleTrack:
    """std_msgs/Float64 messages of ``topic`` at their log times."""
    items = recording.read(topic)
    return ScaleTrack(np.asarray([t for t, _ in items], dtype=np.int64),
                      np.asarray([float(m.data) for _, m in items], dtype=float))


def read_truth(path: str | Path) -> Truth:
    """/gt/camera_pose, /gt/human_joints and /gt/scale of a recording (whichever it has)."""
    with Recording(path) as rec:
        camera = read_camera(rec, GT_CAMERA[0]) if rec.has(*GT_CAMERA) else None
        joints = read_joints(rec, GT_JOINTS[0]) if rec.has(*GT_JOINTS) else None
        scale = read_scale(rec, GT_SCALE[0]) if rec.has(*GT_SCALE) else None
        if camera is None and joints is None and scale is None:
            raise HacError(f'{path} has no ground truth ({GT_CAMERA[0]}, {GT_JOINTS[0]}, '
                           f'{GT_SCALE[0]}); it contains: {rec.describe()}')
    return Truth(camera, joints, scale)


@dataclass
class Samples:
    """Per-person scale samples of each frame (/hac/samples): stamps_ns, person, scale (metres per
    SLAM unit, NaN when rejected), source (0 map, 1 ground, 2 rejected), accepted (bool)."""

    stamps_ns: np.ndarray
    person: np.ndarray
    scale: np.ndarray
    source: np.ndarray
    accepted: np.ndarray


@dataclass
class Replayed:
    """What a replay wrote: the metric camera (/hac/pose: metres, metric frame), world joints,
    scale, diagnostics [(log time ns, {key: value})], the per-frame samples and the continuous
    odometry (/hac/odometry: metres, odom frame)."""

    camera: CameraTrack
    joints: JointsTrack
    scale: ScaleTrack
    diagnostics: list[tuple[int, dict[str, str]]]
    samples: Samples | None
    odometry: CameraTrack = field(default_factory=CameraTrack)
    layout: JointLayout = SMPL24  # of the joints (the recording's custom_data)


def read_output(path: str | Path) -> Replayed:
    """Read a recording written by ``hac replay`` (the output topics and /hac/samples)."""
    pose, odom, diag = in_root(POSE[0]), in_root(ODOMETRY[0]), DIAGNOSTICS[0]
    joints_topic, scale_topic, samples_topic = (in_root(HUMAN_JOINTS[0]), in_root(SCALE[0]),
                                                in_root(SAMPLES[0]))
    with Recording(path) as rec:
        if not rec.has(diag) and not rec.has(pose):
            raise HacError(f'{path} is not a recording written by hac replay (no {pose} or '
                           f'{diag}); it contains: {rec.describe()}')
        camera = read_camera(rec, pose) if rec.has(pose) else CameraTrack()
        odometry = read_camera(rec, odom) if rec.has(odom) else CameraTrack()
        joints = read_joints(rec, joints_topic) if rec.has(joints_topic) else JointsTrack()
        scale = read_scale(rec, scale_topic) if rec.has(scale_topic) else ScaleTrack()
        diagnostics = [(log_ns, {kv.key: kv.value for kv in status.values})
                       for log_ns, msg in (rec.read(diag) if rec.has(diag) else [])
                       for status in msg.status]
        samples = _read_samples(rec, samples_topic) if rec.has(samples_topic) else None
        layout = rec.layout
    return Replayed(camera, joints, scale, diagnostics, samples, odometry, layout)


def _read_samples(recording: Recording, topic: str) -> Samples:
    stamps, rows = [], []
    for log_ns, msg in recording.read(topic):
        data = np.asarray(msg.data, dtype=float).reshape(-1, SAMPLE_FIELDS)
        stamps.extend([log_ns] * len(data))
        rows.append(data)
    table = np.vstack(rows) if rows else np.zeros((0, SAMPLE_FIELDS))
    return Samples(np.asarray(stamps, dtype=np.int64), table[:, 0].astype(int), table[:, 1],
                   table[:, 2].astype(int), table[:, 3] > 0.5)
