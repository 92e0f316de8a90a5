"""``from hac_ros import calibrate``: the whole calibration in one call on numpy arrays.

For research code that holds a SLAM trajectory, a map and HMR joints as arrays (the HAC authors'
``masked_droid_slam.npz`` and SMPL joints, a DROID-SLAM or DPVO run, ...): :func:`calibrate` gives
what ``hac import`` + ``hac replay`` give on the same arrays, without recordings on disk. The inputs
are fed to the node's :class:`~hac_ros.core.calibrator.Calibrator` exactly as the replay feeds a
recording written by ``hac import`` (stamps to nanoseconds by round(t × 1e9), the map once at the
first stamp, poses and joints matched within ``sync_slop_s`` or interpolated, an absent person left
out), and resolved as the replay resolves them (offline by default). With ``literal=True`` it is the
authors' method (:mod:`hac_ros.core.estimate.literal`) on the same frames.

Everything is validated first: an :class:`~hac_ros.core.basics.errors.InputError` names the
argument, the shape and the unit it expects. Imports no ROS.
"""
from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hac_ros.core import input_checks as checks
from hac_ros.core.basics.errors import InputError
from hac_ros.core.basics.outputs import HumanJointsOut, Output, PoseOut, SampleOut, ScaleOut
from hac_ros.core.basics.transforms import is_rotation
from hac_ros.core.offline import OfflineScale
from hac_ros.core.rules.params import HacParams

log = logging.getLogger(__name__)

MODES = ('offline', 'online')
MAP_FRAME, CAMERA_FRAME = 'map', 'camera_optical'  # the frames hac import writes
ROTATION_TOL = 1e-6  # max |RᵀR − I| of a rotation (the message adapters' tolerance)


@dataclass
class CalibrationResult:
    """What :func:`calibrate` found. Frames and units in the names; NaN where nothing was
    published (before convergence, frames without a pose, absent people).

    scale: the final scale, metres per SLAM unit (the last one published, as the replay's
    ``/hac/scale``); converged: whether any metric output was published; mode: ``offline``,
    ``online`` or ``literal``.
    Per joints frame t (``joint_stamps``): ``frame_scales`` (T,) the scale published with frame t;
    ``samples`` (T, P) each person's per-frame scale sample (the method's s_t, NaN when refused);
    ``sources`` (T, P) where it came from (``map``, ``ground``, a refusal reason, ``''`` absent);
    ``joints_world`` (T, P, K, 3) metres in the metric frame (``metric_frame_alignment``: z up
    with the floor at z = 0 by default; the SLAM map's axes scaled for ``literal``).
    Per pose i (``pose_stamps``): ``camera_R`` (N, 3, 3) camera optical frame to the metric frame,
    ``camera_position`` (N, 3) metres, the globally consistent pose (``/hac/pose``).
    counts: frames, people, samples, map_hits, ground_fallbacks, resets, and ``rejected`` by
    reason; schedule: the offline scale per segment (offline mode).
    """

    scale: float
    converged: bool
    mode: str
    joint_stamps: np.ndarray
    frame_scales: np.ndarray
    samples: np.ndarray
    sources: np.ndarray
    joints_world: np.ndarray
    pose_stamps: np.ndarray
    camera_R: np.ndarray
    camera_position: np.ndarray
    counts: dict[str, Any] = field(default_factory=dict)
    schedule: OfflineScale | None = None

    def __repr__(self) -> str:
        return (f'CalibrationResult(scale={self.scale:.6g} m/SLAM unit, mode={self.mode}, '
                f'frames={len(self.joint_stamps)}, poses={len(self.pose_stamps)}, '
                f'samples={self.counts.get("samples", 0)}, converged={self.converged})')


@dataclass
class _Inputs:
    """The validated inputs: stamps in int ns, people present per frame."""

    pose_ns: np.ndarray  # (N,) int64
    R_wc: np.ndarray  # (N, 3, 3)
    c_map: np.ndarray  # (N, 3) SLAM units
    points_map: np.ndarray  # (M, 3) SLAM units, finite, no (0, 0, 0)
    joint_ns: np.ndarray  # (T,) int64
    joints_cam: np.ndarray  # (T, P, K, 3) metres
    present: list[np.ndarray]  # per frame: indices of the people present (not all-NaN)
    camera: tuple[np.ndarray, int, int] | None  # K (3, 3) pixels, width, height


def calibrate(pose_stamps: Any, R_wc: Any, c_map: Any, points_map: Any, joints_cam: Any,
              joint_stamps: Any = None, K: Any = None, joint_layout: str = 'smpl24',
              params: HacParams | Mapping[str, Any] | None = None, literal: bool = False, *,
              image_size: tuple[int, int] | None = None, mode: str = 'offline'
              ) -> CalibrationResult:
    """The metric scale of a monocular SLAM run from the people in view, in one call.

    pose_stamps: (N,) seconds, increasing; R_wc: (N, 3, 3) camera-to-map rotations (camera optical
    frame to the SLAM map frame); c_map: (N, 3) camera centres in the map frame, SLAM units;
    points_map: (M, 3) map points, SLAM units (non-finite and (0, 0, 0) rows are dropped, as from a
    PointCloud2); joints_cam: (T, P, K, 3) metres in the camera optical frame, K the layout's
    joints per person, an all-NaN (K, 3) block where person p is absent from frame t;
    joint_stamps: (T,) seconds, increasing (default: ``pose_stamps``, then T = N); K: (3, 3)
    intrinsics in pixels (joints projecting outside the image go to the ground plane), with
    ``image_size`` (width, height) in pixels (default: twice the principal point); joint_layout:
    a built-in layout (:data:`hac_ros.core.layouts.LAYOUTS`) or ``custom`` (its index lists in
    ``params``); params: a
    :class:`HacParams` or a mapping of parameter names (the node's: docs/interface.md), the
    replay's defaults otherwise; literal: the authors' method instead of ours; mode: ``offline``
    (the whole sequence at once, as ``hac replay``) or ``online`` (causal, what ``hac_node``
    publishes).
    """
    params = _params(params, joint_layout)
    if mode not in MODES:
        raise InputError(f'mode: expected one of {", ".join(MODES)}, got {mode!r}')
    inputs = _validate(pose_stamps, R_wc, c_map, points_map, joints_cam, joint_stamps, K,
                       image_size, params)
    if literal:
        return _literal(inputs, params)
    return _ours(inputs, params, mode)


# ================================================================================== validation
def _params(params: HacParams | Mapping[str, Any] | None, joint_layout: str) -> HacParams:
    if params is None:
        base = HacParams()
    elif isinstance(params, HacParams):
        base = params
    elif isinstance(params, Mapping):
        base = HacParams.from_dict(params)
    else:
        raise InputError(f'params: expected HacParams, a mapping of parameter names or None, '
                         f'got {type(params).__name__}')
    return base.replace(joint_layout=joint_layout) if joint_layout != base.joint_layout else base


def _validate(pose_stamps: Any, R_wc: Any, c_map: Any, points_map: Any, joints_cam: Any,
              joint_stamps: Any, K: Any, image_size: tuple[int, int] | None,
              params: HacParams) -> _Inputs:
    """Every argument checked before anything runs, with the checks ``hac import`` makes of the
    same arrays read from files (:mod:`hac_ros.core.input_checks`): shapes, units, stamps, finite
    values, the layout."""
    pose_ns = checks.stamps_ns(pose_stamps, 'pose_stamps')
    n = len(pose_ns)
    R = checks.numbers(R_wc, 'R_wc', '(N, 3, 3)', 'camera-to-map rotations')
    if R.shape != (n, 3, 3):
        raise InputError(f'R_wc: expected (N, 3, 3) camera-to-map rotations with N = '
                         f'len(pose_stamps) = {n}, got shape {R.shape}')
    for i in range(n):
        if not is_rotation(R[i], ROTATION_TOL):
            raise InputError(f'R_wc: [{i}] is not a rotation matrix (finite, RᵀR = I within '
                             f'{ROTATION_TOL:g}, det +1): {R[i].tolist()}')
    c = checks.numbers(c_map, 'c_map', '(N, 3)', 'SLAM units')
    if c.shape != (n, 3) or not np.isfinite(c).all():
        raise InputError(f'c_map: expected (N, 3) finite camera centres in SLAM units with N = '
                         f'len(pose_stamps) = {n}, got shape {c.shape}'
                         + ('' if c.shape != (n, 3) else ' with non-finite values'))
    points = checks.map_points(points_map, 'points_map')
    layout = params.layout()
    joints = checks.joints(joints_cam, 'joints_cam', layout.joints_per_person, params.joint_layout)
    odd = checks.joints_unit(joints, 'joints_cam')
    if odd:
        log.warning('%d people of joints_cam are not the size of a body in metres: the '
                    'calibrator refuses them (joints_not_metres)', odd)
    if joint_stamps is None:
        if len(joints) != n:
            raise InputError(f'joints_cam: {len(joints)} frames but no joint_stamps: give '
                             f'joint_stamps (T,) seconds, or one frame per pose (N = {n})')
        joint_ns = pose_ns
    else:
        joint_ns = checks.stamps_ns(joint_stamps, 'joint_stamps')
        checks.frames_match(joint_ns, joints, 'joint_stamps', 'joints_cam')
    present = [np.flatnonzero(~np.isnan(frame).all(axis=(1, 2))) for frame in joints]
    return _Inputs(pose_ns, R, c, points, joint_ns, joints, present,
                   _camera(K, image_size))


def _camera(K: Any, image_size: tuple[int, int] | None) -> tuple[np.ndarray, int, int] | None:
    if K is None:
        if image_size is not None:
            raise InputError('image_size: given without K (3, 3) intrinsics, pixels')
        return None
    intrinsics = checks.numbers(K, 'K', '(3, 3)', 'pixels')
    if intrinsics.shape != (3, 3) or not np.isfinite(intrinsics).all() \
            or intrinsics[0, 0] <= 0 or intrinsics[1, 1] <= 0:
        raise InputError(f'K: expected (3, 3) finite intrinsics in pixels with fx, fy > 0, got '
                         f'{intrinsics.tolist() if intrinsics.size <= 9 else intrinsics.shape}')
    if image_size is None:
        width, height = round(2 * intrinsics[0, 2]), round(2 * intrinsics[1, 2])
        log.info('image_size not given: %d x %d pixels, twice the principal point', width, height)
    else:
        try:
            width, height = (int(v) for v in image_size)
        except (TypeError, ValueError) as exc:
            raise InputError(f'image_size: expected (width, height) in pixels, got '
                             f'{image_size!r}') from exc
    if not (0 < width < 2**31 and 0 < height < 2**31):
        raise InputError(f'image_size: expected positive (width, height) in pixels, got '
                         f'({width}, {height})')
    return intrinsics, width, height


# ================================================================================== ours
def _events(inputs: _Inputs) -> list[tuple[int, int, str, Any]]:
    """The calibrator calls, in the order the replay makes them of an imported recording: by
    stamp; at one stamp the map, the pose, the joints (hac_ros.replay.feeder.TIE_ORDER)."""
    from msg_adapters import matrix_to_quat, quat_to_matrix

    first = int(min(inputs.pose_ns[0], inputs.joint_ns[0]))
    events: list[tuple[int, int, str, Any]] = [(first, 1, 'map', inputs.points_map)]
    for stamp, R, c in zip(inputs.pose_ns.tolist(), inputs.R_wc, inputs.c_map):
        # through a quaternion, as a PoseStamped carries it (the same float64 rotation)
        events.append((stamp, 2, 'pose', (quat_to_matrix(*matrix_to_quat(R)), c)))
    for t, stamp in enumerate(inputs.joint_ns.tolist()):
        if len(inputs.present[t]):
            events.append((stamp, 3, 'joints', t))
    events.sort(key=lambda e: (e[0], e[1]))
    return events


def _ours(inputs: _Inputs, params: HacParams, mode: str) -> CalibrationResult:
    from hac_ros.core.calibrator import Calibrator
    from hac_ros.core.offline import resolve_offline

    offline = mode == 'offline'
    calibrator = Calibrator(params, offline=offline)
    outputs: list[Output] = []
    if inputs.camera is not None:
        outputs += calibrator.add_camera_info(*inputs.camera)
    joint_rows: dict[int, int] = {}
    for stamp, _, kind, payload in _events(inputs):
        if kind == 'map':
            outputs += calibrator.add_map(stamp, payload, MAP_FRAME)
        elif kind == 'pose':
            outputs += calibrator.add_pose(stamp, payload[0], payload[1], MAP_FRAME)
        else:
            joint_rows[stamp] = payload
            people = inputs.joints_cam[payload][inputs.present[payload]]
            outputs += calibrator.add_joints(stamp, people, CAMERA_FRAME)
    outputs += calibrator.flush()
    schedule = None
    status = calibrator.status()
    if offline:  # as the offline replay: the run resolved with its own schedule, humans smoothed
        run = resolve_offline(calibrator)
        outputs, schedule, status = run.outputs, run.schedule, run.status
    result = _collect(inputs, outputs, joint_rows, mode)
    result.schedule = schedule
    result.counts = {'frames': status.frames, 'people': status.people,
                     'samples': int(np.isfinite(result.samples).sum()),
                     'accepted': sum(1 for o in outputs if isinstance(o, SampleOut) and o.accepted),
                     'map_hits': status.map_hits, 'ground_fallbacks': status.ground_fallbacks,
                     'resets': status.resets, 'rejected': dict(status.rejected)}
    return result


def _empty(inputs: _Inputs, mode: str) -> CalibrationResult:
    t, p, k = inputs.joints_cam.shape[:3]
    n = len(inputs.pose_ns)
    return CalibrationResult(
        math.nan, False, mode, inputs.joint_ns / 1e9, np.full(t, np.nan), np.full((t, p), np.nan),
        np.full((t, p), '', dtype=object), np.full((t, p, k, 3), np.nan), inputs.pose_ns / 1e9,
        np.full((n, 3, 3), np.nan), np.full((n, 3), np.nan))


def _collect(inputs: _Inputs, outputs: list[Output], joint_rows: dict[int, int],
             mode: str) -> CalibrationResult:
    """The outputs as arrays at the inputs' frames, people at their own indices."""
    result = _empty(inputs, mode)
    pose_row = {int(s): i for i, s in enumerate(inputs.pose_ns)}
    for output in outputs:
        if isinstance(output, PoseOut):
            i = pose_row[output.stamp_ns]
            result.camera_R[i] = output.rotation_metric
            result.camera_position[i] = output.position_metric
        elif isinstance(output, HumanJointsOut):
            t = joint_rows[output.stamp_ns]
            result.joints_world[t, inputs.present[t]] = output.joints_metric
        elif isinstance(output, ScaleOut):
            result.frame_scales[joint_rows[output.stamp_ns]] = output.scale
            result.scale = output.scale
        elif isinstance(output, SampleOut):
            t = joint_rows[output.stamp_ns]
            person = inputs.present[t][output.person]
            result.samples[t, person] = output.scale
            result.sources[t, person] = output.source
    result.converged = math.isfinite(result.scale)
    return result


# ================================================================================== literal
def _literal(inputs: _Inputs, params: HacParams) -> CalibrationResult:
    """The authors' method (hac_ros.core.estimate.literal) on the frames the replay would match."""
    from hac_ros.core.estimate.estimator import sequence_scale
    from hac_ros.core.estimate.literal import max_ratio, world_joints
    from hac_ros.core.stream.pose_stream import Pose, PoseTrack

    track = PoseTrack.from_params(params, buffer=len(inputs.pose_ns) + 1)
    for stamp, R, c in zip(inputs.pose_ns.tolist(), inputs.R_wc, inputs.c_map):
        track.append(Pose(stamp, R, c), None)
    result = _empty(inputs, 'literal')
    rejected: Counter[str] = Counter()
    frames: list[tuple[int, np.ndarray, np.ndarray]] = []
    for t, stamp in enumerate(inputs.joint_ns.tolist()):
        if not len(inputs.present[t]):
            continue
        pose = track.at(stamp)
        if pose is None:
            rejected['no_pose'] += 1
            continue
        frames.append((t, *pose))
        for p in inputs.present[t]:
            sample = max_ratio(inputs.points_map, pose[0], pose[1], inputs.joints_cam[t, p])
            result.samples[t, p] = sample
            result.sources[t, p] = 'map' if math.isfinite(sample) else 'no_reference'
            rejected['no_reference'] += not math.isfinite(sample)
    scale = sequence_scale(result.samples)
    result.scale, result.converged = scale, math.isfinite(scale)
    if result.converged:
        for t, R, c in frames:
            result.frame_scales[t] = scale
            people = inputs.present[t]
            result.joints_world[t, people] = world_joints(inputs.joints_cam[t, people], R, c,
                                                          scale)
        result.camera_R[:] = inputs.R_wc
        result.camera_position[:] = scale * inputs.c_map
    result.counts = {'frames': len(frames), 'people': sum(len(inputs.present[t])
                                                          for t, _, _ in frames),
                     'samples': int(np.isfinite(result.samples).sum()),
                     'rejected': {k: v for k, v in rejected.items() if v}}
    return result
