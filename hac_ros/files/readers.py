"""The files ``hac import`` reads, checked: TUM trajectories, joints ``.npz``, camera intrinsics.

Every stamp becomes integer nanoseconds by ``round(t × 1e9)`` of the float seconds (the TUM text
parsed as a float64, the ``.npz`` stamps as stored), the same rule for every file, so that a joints
stamp written from the same float as a trajectory stamp gives the same nanoseconds. Every problem
raises :class:`~hac_ros.core.basics.errors.InputError` naming the file (and the line) and the
problem.
"""
from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from hac_ros.core import input_checks as checks
from hac_ros.core.basics.errors import ArgumentError, InputError
from hac_ros.core.basics.numeric import NS
from hac_ros.files.tum import tum_rows


def seconds_to_ns(t: np.ndarray, where: str = 'stamps', labels: list[str] | None = None
                  ) -> np.ndarray:
    """Float seconds (N,) → int64 nanoseconds by round(t × 1e9) (docs/interface.md, "Conventions").
    :class:`InputError` (``where``: the file, ``labels``: each stamp's place in it) for a stamp
    that is not a ROS time: negative, or past 2^31 s (the check ``calibrate()`` makes:
    :func:`hac_ros.core.input_checks.ros_time_ns`)."""
    return checks.ros_time_ns(t, where, labels)


@dataclass
class Trajectory:
    """A TUM trajectory: stamps_ns (N,) int64 strictly increasing; positions (N, 3) camera centres
    in the file's world/map frame and unit (SLAM units for a SLAM trajectory, metres for ground
    truth); quats_xyzw (N, 4) unit quaternions, camera (optical axes) to that frame."""

    path: Path
    stamps_ns: np.ndarray
    positions: np.ndarray
    quats_xyzw: np.ndarray

    def __len__(self) -> int:
        return len(self.stamps_ns)


@dataclass
class Joints:
    """A joints ``.npz``: stamps_ns (T,) int64 strictly increasing; joints (T, P, K, 3) metres, in
    the camera optical frame (HMR input) or the ground truth's world frame; an all-NaN (P) block =
    that person is absent from that frame."""

    path: Path
    stamps_ns: np.ndarray
    joints: np.ndarray

    @property
    def joints_per_person(self) -> int:
        return int(self.joints.shape[2])

    def people(self, t: int) -> np.ndarray:
        """The people present in frame t: (P_t, K, 3), all-NaN blocks left out."""
        frame = self.joints[t]
        return frame[~np.isnan(frame).all(axis=(1, 2))]


def existing_file(path: str | Path, what: str) -> Path:
    """``path`` as a Path; InputError naming ``what`` when it is missing or not a file."""
    path = Path(path)
    if not path.exists():
        raise InputError(f'{what} {path} does not exist')
    if not path.is_file():
        raise InputError(f'{what} {path} is not a file')
    return path


def _unit_quaternions(path: str | Path, what: str, quats: np.ndarray, labels: list[str]
                      ) -> np.ndarray:
    """(N, 4) quaternions x y z w normalised; InputError naming the line of a zero one."""
    norms = np.linalg.norm(quats, axis=1)
    if (norms < 1e-6).any():
        raise InputError(f'{what} {path}: {labels[int(np.argmax(norms < 1e-6))]}: the quaternion '
                         'is zero')
    return quats / norms[:, None]


def _check_increasing(path: Path, what: str, stamps_ns: np.ndarray, labels: list[str]) -> None:
    checks.increasing(stamps_ns, f'{what} {path}', labels)


def read_trajectory(path: str | Path, what: str = 'trajectory',
                    duplicates: list[int] | None = None) -> Trajectory:
    """A TUM file (``stamp tx ty tz qx qy qz qw`` per line, ``#`` comments, blank lines skipped;
    commas allowed between values) with at least one pose, finite values, non-zero quaternions
    (normalised here) and strictly increasing stamps. With a ``duplicates`` list, a pose whose stamp
    equals the one before is dropped and its line number appended there instead (motion-capture
    files have them: TUM fr2_desk's ground truth); a stamp going back is still an error."""
    path = existing_file(path, what)
    rows, labels = [], []
    for number, parts in tum_rows(path, what):
        try:
            row = [float(v) for v in parts]
        except ValueError as exc:
            raise InputError(f'{what} {path}:{number}: not a number ({exc})') from exc
        if not np.isfinite(row).all():
            raise InputError(f'{what} {path}:{number}: a value is not finite (NaN or inf): '
                             f'{" ".join(parts)}')
        rows.append(row)
        labels.append(f'line {number}')
    if not rows:
        raise InputError(f'{what} {path}: no pose in it (TUM: t tx ty tz qx qy qz qw per line)')
    data = np.asarray(rows, dtype=float)
    stamps = seconds_to_ns(data[:, 0], f'{what} {path}', labels)
    if duplicates is not None:
        repeated = np.flatnonzero(np.diff(stamps) == 0) + 1
        duplicates += [int(labels[i].split()[1]) for i in repeated]
        keep = np.setdiff1d(np.arange(len(stamps)), repeated)
        data, stamps, labels = data[keep], stamps[keep], [labels[i] for i in keep]
    _check_increasing(path, what, stamps, labels)
    return Trajectory(path, stamps, data[:, 1:4], _unit_quaternions(path, what, data[:, 4:8],
                                                                    labels))


def _load_npz(path: Path, what: str) -> dict[str, np.ndarray]:
    """The named arrays of a ``.npz`` (no pickles); InputError when it cannot be read."""
    try:
        npz = np.load(path, allow_pickle=False)
        if not isinstance(npz, np.lib.npyio.NpzFile):
            raise ValueError('a single array, not an archive of named arrays')
        with npz:
            return {name: npz[name] for name in npz.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise InputError(f'{what} {path}: not a readable .npz ({exc})') from exc


def read_any_trajectory(path: str | Path, what: str = 'trajectory', fps: float | None = None,
                        warnings: list[str] | None = None) -> Trajectory:
    """A TUM file, or a DROID-SLAM-style ``.npz`` (:func:`read_droid_trajectory`) when the name
    ends in ``.npz``; ``fps`` (frames per second) applies to the ``.npz``'s frame indices only."""
    if Path(path).suffix.lower() == '.npz':
        return read_droid_trajectory(path, what, fps, warnings)
    if fps is not None:
        raise ArgumentError(f'{what} {path}: {{fps}} applies to the frame indices of a '
                            'DROID-SLAM-style .npz trajectory, not to a TUM file (whose stamps are '
                            'seconds)', 'fps')
    return read_trajectory(path, what)


def read_droid_trajectory(path: str | Path, what: str = 'trajectory', fps: float | None = None,
                          warnings: list[str] | None = None) -> Trajectory:
    """A DROID-SLAM-style ``.npz`` (as the HAC authors' ``masked_droid_slam.npz``): ``traj``
    (N, 7) camera-to-world poses ``tx ty tz qx qy qz qw`` (SLAM units, optical axes) and
    ``tstamp`` (N,) seconds, or frame indices when ``fps`` is given (seconds = index / fps; without
    ``tstamp`` frame i is at i / fps). Stamps must increase; quaternions are normalised (a zero
    one is an error). Stamps that are all whole numbers without ``fps`` look like frame indices:
    an :class:`ArgumentError` naming ``fps`` (taken as seconds, a replay would keep only the
    joints frames that fall on whole seconds). ``warnings``: where warnings would go (none
    today)."""
    path = existing_file(path, what)
    arrays = _load_npz(path, what)
    if 'traj' not in arrays:
        raise InputError(f'{what} {path}: no \'traj\' array (it holds: '
                         f'{", ".join(sorted(arrays)) or "nothing"}); expected traj (N, 7) '
                         'camera-to-world tx ty tz qx qy qz qw and tstamp (N,)')
    traj = arrays['traj']
    if traj.ndim != 2 or traj.shape[1] != 7 or traj.dtype.kind not in 'iuf' or not len(traj):
        raise InputError(f'{what} {path}: traj must be (N, 7) numbers (tx ty tz qx qy qz qw), '
                         f'got shape {traj.shape} of {traj.dtype}')
    traj = traj.astype(float)
    if fps is not None and not 0.0 < fps < float('inf'):
        raise ArgumentError(f'{what} {path}: {{fps}} must be a number > 0, got {fps!r}', 'fps')
    if 'tstamp' in arrays:
        tstamp = arrays['tstamp']
        if tstamp.shape != (len(traj),) or tstamp.dtype.kind not in 'iuf':
            raise InputError(f'{what} {path}: tstamp must be ({len(traj)},) numbers like traj\'s '
                             f'rows, got shape {tstamp.shape} of {tstamp.dtype}')
        t = tstamp.astype(float)
    elif fps is not None:
        t = np.arange(len(traj), dtype=float)
    else:
        raise ArgumentError(f'{what} {path}: no \'tstamp\' array: give the frame rate ({{fps}}) '
                            'to stamp frame i at i / fps', 'fps')
    labels = [f'row {i}' for i in range(len(traj))]
    bad = ~np.isfinite(traj).all(axis=1) | ~np.isfinite(t)
    if bad.any():
        raise InputError(f'{what} {path}: {labels[int(np.argmax(bad))]}: a value is not finite')
    if fps is None and len(t) > 1 and np.all(t == np.round(t)):
        raise ArgumentError(f'{what} {path}: tstamp holds whole numbers ({t[0]:g}, {t[1]:g}, '
                            '...): frame indices? give the frame rate, {fps} (seconds = index / '
                            'fps); a trajectory at 1 Hz stamped in seconds is {fps} 1', 'fps')
    stamps = seconds_to_ns(t / fps if fps is not None else t, f'{what} {path}', labels)
    _check_increasing(path, what, stamps, labels)
    return Trajectory(path, stamps, traj[:, :3], _unit_quaternions(path, what, traj[:, 3:7],
                                                                   labels))


def read_joints(path: str | Path, what: str = 'joints',
                joints_per_person: int | None = None, layout: str = '') -> Joints:
    """A ``.npz`` with ``stamps`` (T,) float seconds and ``joints`` (T, P, K, 3) metres (NaN blocks
    for absent people); K checked against ``joints_per_person`` (the layout ``layout``'s) when
    given. The arrays pass the checks ``calibrate()`` makes of the same arrays
    (:mod:`hac_ros.core.input_checks`)."""
    path = existing_file(path, what)
    arrays = _load_npz(path, what)
    missing = [name for name in ('stamps', 'joints') if name not in arrays]
    if missing:
        raise InputError(f'{what} {path}: no {" or ".join(repr(m) for m in missing)} array (it '
                         f'holds: {", ".join(sorted(arrays)) or "nothing"}); expected stamps (T,) '
                         'seconds and joints (T, P, K, 3) metres')
    frame = ("the ground truth's world frame" if 'ground-truth' in what
             else 'the camera optical frame')
    joints = checks.joints(arrays['joints'], f'{what} {path}: joints', joints_per_person, layout,
                           frame)
    stamps_ns = checks.stamps_ns(arrays['stamps'], f'{what} {path}: stamps')
    checks.frames_match(stamps_ns, joints, f'{what} {path}: stamps', 'joints')
    return Joints(path, stamps_ns, joints)


def parse_camera(text: str) -> tuple[np.ndarray, int, int]:
    """``fx,fy,cx,cy,width,height`` (pixels) → (K (3, 3) pixels, width, height)."""
    parts = [p for p in text.replace(',', ' ').split()]
    try:
        if len(parts) != 6:
            raise ValueError(f'{len(parts)} values')
        fx, fy, cx, cy = (float(p) for p in parts[:4])
        width, height = (int(p) for p in parts[4:])
    except ValueError as exc:
        raise ArgumentError(f'{{camera}} {text!r}: expected fx,fy,cx,cy,width,height (pixels; '
                            f'width and height integers) ({exc})', 'camera') from exc
    if not (np.isfinite([fx, fy, cx, cy]).all() and fx > 0 and fy > 0 and width > 0 and height > 0):
        raise ArgumentError(f'{{camera}} {text!r}: fx, fy, width and height must be positive, '
                            'all finite', 'camera')
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]), width, height


def poses_at(traj: Trajectory, query_ns: np.ndarray, max_gap_ns: int, tol_ns: int = 1_000_000
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``traj`` sampled at ``query_ns``: (index into query (M,), positions (M, 3), rotations
    (M, 3, 3) camera to ``traj``'s frame), in ``traj``'s unit. A query stamp within ``tol_ns`` of a
    pose takes it; otherwise one between two poses at most ``max_gap_ns`` apart is interpolated
    (linear position, slerp rotation); the others are left out."""
    q = np.asarray(query_ns, dtype=np.int64)
    s = traj.stamps_ns
    rot = Rotation.from_quat(traj.quats_xyzw)
    exact, interp, nearest, lo, hi = _bracket(s, q, tol_ns, max_gap_ns)
    keep = exact | interp
    idx = np.flatnonzero(keep)
    lo, hi, nearest = lo[keep], hi[keep], nearest[keep]
    alpha = np.where(interp[keep], (q[keep] - s[lo]) / np.maximum(s[hi] - s[lo], 1), 0.0)
    first = np.where(interp[keep], lo, nearest)
    second = np.where(interp[keep], hi, nearest)
    positions = traj.positions[first] + alpha[:, None] * (traj.positions[second]
                                                          - traj.positions[first])
    if not len(idx):
        return idx, positions, np.zeros((0, 3, 3))
    r0 = rot[first]
    step = (r0.inv() * rot[second]).as_rotvec()
    rotations = (r0 * Rotation.from_rotvec(alpha[:, None] * step)).as_matrix()
    return idx, positions, rotations


def unpaired_joint_stamps(pose_ns: np.ndarray, joints_ns: np.ndarray, slop_ns: int,
                          max_gap_ns: int) -> tuple[int, float]:
    """How many joints stamps have no SLAM pose within ``slop_ns`` and lie outside the trajectory or
    in a gap between two poses longer than ``max_gap_ns`` (the replay cannot interpolate a pose for
    them), and the longest such gap in seconds (inf when outside)."""
    pose_ns, joints_ns = np.asarray(pose_ns, np.int64), np.asarray(joints_ns, np.int64)
    exact, interp, _, lo, hi = _bracket(pose_ns, joints_ns, slop_ns, max_gap_ns)
    bad = ~(exact | interp)
    if not bad.any():
        return 0, 0.0
    outside = (joints_ns < pose_ns[0]) | (joints_ns > pose_ns[-1])
    gap_s = (pose_ns[hi] - pose_ns[lo])[bad].max() / NS
    return int(bad.sum()), float(np.inf) if (bad & outside).any() else float(gap_s)


def _bracket(s: np.ndarray, q: np.ndarray, tol_ns: int, max_gap_ns: int
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Where each query stamp of ``q`` falls among the sorted stamps ``s`` (both int ns): exact
    (within ``tol_ns`` of its nearest stamp), interp (not exact, between two stamps at most
    ``max_gap_ns`` apart), and the indices of the nearest, the previous and the next stamp."""
    near = np.clip(np.searchsorted(s, q), 0, len(s) - 1)
    left = np.clip(near - 1, 0, len(s) - 1)
    nearest = np.where(np.abs(s[left] - q) < np.abs(s[near] - q), left, near)
    exact = np.abs(s[nearest] - q) <= tol_ns
    right = np.searchsorted(s, q, side='right')
    inside = (right > 0) & (right < len(s))
    lo, hi = np.clip(right - 1, 0, len(s) - 1), np.clip(right, 0, len(s) - 1)
    interp = ~exact & inside & (s[hi] - s[lo] <= max_gap_ns)
    return exact, interp, nearest, lo, hi
