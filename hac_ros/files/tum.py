"""TUM trajectory files: ``timestamp tx ty tz qx qy qz qw`` per line (evo reads and writes them).

Poses are of the camera in the world (camera-to-world: position = camera centre). Stamps are int
nanoseconds in memory and seconds with 9 decimals in the file.
"""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from hac_ros.core.basics.errors import InputError
from hac_ros.core.basics.numeric import NS
from hac_ros.recording.reader import GT_CAMERA
from hac_ros.recording.tracks import read_camera


def tum_rows(path: str | Path, what: str = 'TUM file') -> Iterator[tuple[int, list[str]]]:
    """(line number, the 8 fields) of every pose line; '#' lines and blanks skipped, commas allowed
    between values. :class:`~hac_ros.core.basics.errors.InputError` naming the file and line
    otherwise."""
    try:
        lines = Path(path).read_text(encoding='utf-8').splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f'{what} {path}: cannot read it as text ({exc})') from exc
    for number, line in enumerate(lines, 1):
        text = line.strip()
        if not text or text.startswith('#'):
            continue
        parts = text.replace(',', ' ').split()
        if len(parts) != 8:
            raise InputError(f'{what} {path}:{number}: expected 8 values (TUM: t tx ty tz qx qy qz '
                             f'qw), got {len(parts)}')
        yield number, parts


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(stamps_ns (N,) int64, positions (N, 3), quats_xyzw (N, 4)); the stamps' decimals read
    exactly (no float rounding)."""
    stamps, rows = [], []
    for number, parts in tum_rows(path):
        try:
            sec, _, frac = parts[0].partition('.')
            stamps.append(int(sec) * NS + int((frac + '000000000')[:9]))
            rows.append([float(v) for v in parts[1:]])
        except ValueError as exc:
            raise InputError(f'TUM file {path}:{number}: not a number ({exc})') from exc
    data = np.array(rows, dtype=float).reshape(-1, 7)
    return np.array(stamps, dtype=np.int64), data[:, :3], data[:, 3:]


def write_tum(path: str | Path, stamps_ns: np.ndarray, positions: np.ndarray,
              quats_xyzw: np.ndarray) -> None:
    """Write a TUM file (stamps int ns; positions (N, 3); quaternions (N, 4) x, y, z, w)."""
    lines = []
    for stamp, p, q in zip(np.asarray(stamps_ns, dtype=np.int64), positions, quats_xyzw):
        sec, ns = divmod(int(stamp), NS)
        lines.append(f'{sec}.{ns:09d} ' + ' '.join(f'{v:.9f}' for v in (*p, *q)))
    Path(path).write_text('\n'.join(lines) + ('\n' if lines else ''))


def rotations_to_quats(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations → (N, 4) quaternions x, y, z, w."""
    return Rotation.from_matrix(np.asarray(R).reshape(-1, 3, 3)).as_quat()


def quats_to_rotations(q: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions x, y, z, w → (N, 3, 3) rotations."""
    return Rotation.from_quat(np.asarray(q).reshape(-1, 4)).as_matrix()


TUM_FILES = {'metric': 'camera_metric.tum', 'slam': 'camera_slam.tum', 'gt': 'camera_gt.tum'}


def write_tum_exports(directory: Path, metric: list,
                      poses: list[tuple[int, np.ndarray, np.ndarray]],
                      recording: Any) -> dict[str, Path]:
    """A replay's trajectories as TUM files for evo, into ``directory``: camera_metric.tum (the
    metric camera: ``metric``, a list of PoseOut (/hac/pose), metres, metric_frame), camera_slam.tum
    (``poses``, the raw SLAM poses: (stamp ns, R_wc (3, 3), c (3,) SLAM units)) and, when the
    recording has it, camera_gt.tum (/gt/camera_pose, metres). Returns kind -> path of the files
    written."""
    directory.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}

    def export(kind: str, stamps: Any, rotations: Any, positions: Any) -> None:
        if len(stamps):
            path = directory / TUM_FILES[kind]
            write_tum(path, np.asarray(stamps, dtype=np.int64), np.asarray(positions, dtype=float),
                      rotations_to_quats(np.asarray(rotations, dtype=float)))
            written[kind] = path

    try:
        export('metric', [o.stamp_ns for o in metric], [o.rotation_metric for o in metric],
               [o.position_metric for o in metric])
        export('slam', [p[0] for p in poses], [p[1] for p in poses], [p[2] for p in poses])
        if recording.has(*GT_CAMERA):
            gt = read_camera(recording, GT_CAMERA[0])
            export('gt', gt.stamps_ns, gt.rotations, gt.positions)
    except BaseException:  # interrupted, or a full disk: none of the files
        for kind in TUM_FILES:
            (directory / TUM_FILES[kind]).unlink(missing_ok=True)
        raise
    return written
