"""``hac import``: a rosbag2 recording with hac_node's input topics from a SLAM's and an HMR's
files (docs/interface.md, "Topics"; docs/inputs.md).

Inputs (checked by :mod:`hac_ros.files.readers` and :mod:`hac_ros.files.map_files`):

- trajectory T: TUM, or a DROID-SLAM-style ``.npz`` (``traj`` (N, 7), ``tstamp`` seconds or frame
  indices with ``fps``), camera-to-map poses in SLAM units, optical axes → ``/slam/pose``
  (``geometry_msgs/msg/PoseStamped``, ``header.frame_id`` = ``map_frame``, default ``map`` as the
  simulator's), one message per line at its stamp;
- map M (PLY, ``.npy`` or text; SLAM units, map frame) → one ``/slam/cloud`` (``PointCloud2``,
  x y z float64) at the first stamp of T or J, whichever is earlier;
- joints J (``.npz``: ``stamps`` (T,) s, ``joints`` (T, P, K, 3) metres, camera optical frame) →
  ``/hmr/joints`` (``PoseArray``, ``header.frame_id`` = ``camera_frame``, default
  ``camera_optical``): the people of a frame as consecutive blocks of K joints, an all-NaN block
  left out (so block order is the order of the people present); a frame with nobody in it is not
  written (as the simulator writes joints only when someone is in view); partly-NaN people are
  written as they are (the core counts and drops them);
- ``camera`` (``fx,fy,cx,cy,width,height``) → ``/camera/camera_info`` at every pose stamp (as the
  simulator does), ``camera_frame``;
- ground truth G (TUM, metres, any fixed world frame): ``/gt/camera_pose`` (``world_frame``,
  default ``world``) at every stamp of T where G has a pose within 1 ms or between two poses at most
  ``interp_max_gap_s`` apart (interpolated), and ``/gt/scale`` once at the first stamp: the scale s
  of the Sim(3) Umeyama fit of T's positions to G's at those stamps (metres per SLAM unit);
- ground-truth joints GJ (``.npz`` like J, metres, G's world frame) → ``/gt/human_joints``.

Every message is logged at its header stamp (``/gt/scale`` at the first pose stamp); at one stamp
the map comes first, then the pose, the camera info, the joints, the ground truth (the simulator's
order). The recording's rosbag2 ``custom_data`` says its joint layout and K; ``joint_layout``
checks K against the layout (not for ``custom``) and writes ``params.yaml``
(``hac_node: {ros__parameters: {joint_layout: ...}}``) into OUT, the replay's parameters file.
Nothing is written unless every file is good: OUT appears whole or not at all.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hac_ros.core import input_checks as checks
from hac_ros.core.basics.errors import ArgumentText, HacError, InputError
from hac_ros.core.basics.numeric import NS
from hac_ros.core.basics.similarity import umeyama
from hac_ros.core.geometry.plausibility import body_spans
from hac_ros.core.layouts import BUILT_IN, SMPL24, joints_per_person, names_text
from hac_ros.core.rules.params import NODE_NAME, HacParams
from hac_ros.files.map_files import read_map
from hac_ros.files.readers import (
    Joints,
    Trajectory,
    parse_camera,
    poses_at,
    read_any_trajectory,
    read_joints,
    read_trajectory,
    unpaired_joint_stamps,
)
from hac_ros.files.tum import quats_to_rotations
from hac_ros.recording.atomic import staged_output
from hac_ros.recording.reader import (
    GT_CAMERA,
    GT_JOINTS,
    GT_SCALE,
    JOINTS_KEY,
    LAYOUT_KEY,
    layout_data,
)
from hac_ros.recording.writer import OutputWriter
from msg_adapters import (
    intrinsics_to_camera_info,
    joints_to_pose_array,
    rosbags_types,
    rt_to_pose_stamped,
    xyz_to_cloud,
)

TOPICS = {  # topic -> type, in the order messages of one stamp are written
    '/slam/cloud': 'sensor_msgs/msg/PointCloud2',
    '/slam/pose': 'geometry_msgs/msg/PoseStamped',
    '/camera/camera_info': 'sensor_msgs/msg/CameraInfo',
    '/hmr/joints': 'geometry_msgs/msg/PoseArray',
    GT_CAMERA[0]: GT_CAMERA[1],
    GT_JOINTS[0]: GT_JOINTS[1],
    GT_SCALE[0]: GT_SCALE[1],
}
ORDER = {topic: k for k, topic in enumerate(TOPICS)}
PARAMS_FILE = 'params.yaml'
GT_MATCH_NS = 1_000_000  # a ground-truth pose within 1 ms of a SLAM stamp is taken as it is


@dataclass
class ImportResult:
    """What ``hac import`` wrote (counts), the ground-truth fit and the warnings to show."""

    path: Path
    poses: int
    joints_frames: int
    people_max: int
    joints_per_person: int
    map_points: int
    camera_info: bool
    gt_poses: int = 0
    gt_joints_frames: int = 0
    gt_scale: float | None = None
    gt_residual_m: float | None = None
    params_file: Path | None = None
    warnings: list[str] = field(default_factory=list)

    def text(self) -> str:
        lines = [f'hac import: {self.path}: {self.poses} SLAM poses, {self.joints_frames} joints '
                 f'frames (up to {self.people_max} people, {self.joints_per_person} joints each), '
                 f'map of {self.map_points} points'
                 + (', camera info' if self.camera_info else ', no camera info')]
        if self.gt_scale is not None:
            lines.append(f'  ground truth: {self.gt_poses} camera poses, Sim(3) fit of the '
                         f'trajectory: scale {self.gt_scale:.6g} m per SLAM unit, residual '
                         f'{self.gt_residual_m:.4f} m (mean)')
        if self.gt_joints_frames:
            lines.append(f'  ground-truth joints: {self.gt_joints_frames} frames')
        return '\n'.join(lines)


def _fit_scale(traj: Trajectory, gt: Trajectory, max_gap_ns: int
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """(indices into T, G positions (M, 3) m, G rotations (M, 3, 3), scale, mean residual m)."""
    idx, positions, rotations = poses_at(gt, traj.stamps_ns, max_gap_ns, GT_MATCH_NS)
    if len(idx) < 3:
        raise InputError(f'ground-truth trajectory {gt.path}: only {len(idx)} stamps of the '
                         f'trajectory {traj.path} have a ground-truth pose (within 1 ms, or '
                         f'between two poses at most {max_gap_ns / NS} s apart); the Sim(3) fit '
                         'needs 3 (do the two files share a clock?)')
    try:
        s, R, t = umeyama(traj.positions[idx], positions)
    except InputError as exc:
        raise InputError(f'cannot fit the trajectory {traj.path} to the ground truth {gt.path}: '
                         f'{exc}') from exc
    fitted = s * traj.positions[idx] @ R.T + t
    return idx, positions, rotations, s, float(np.linalg.norm(fitted - positions, axis=1).mean())


def check_joints(traj: Trajectory, hmr: Joints, params: HacParams) -> list[str]:
    """The joints as the calibrator will judge them: InputError when they are not metres (the
    median body's spread, hac_ros.core.geometry.plausibility) or share no time with the trajectory;
    warnings for a few such bodies and for stamps the replay will find no pose for."""
    warnings = []
    odd = checks.joints_unit(hmr.joints, f'joints {hmr.path}: joints')  # as calibrate() does
    if odd:
        warnings.append(f'{odd} of {len(body_spans(hmr.joints))} people in {hmr.path} are not the '
                        'size of a body in metres: hac replay refuses them (joints_not_metres)')
    slop_ns = int(round(params.sync_slop_s * NS))
    first, last = int(traj.stamps_ns[0]) - slop_ns, int(traj.stamps_ns[-1]) + slop_ns
    if not ((hmr.stamps_ns >= first) & (hmr.stamps_ns <= last)).any():
        raise InputError(f'the joints {hmr.path} (stamps {hmr.stamps_ns[0] / NS:.3f} to '
                         f'{hmr.stamps_ns[-1] / NS:.3f} s) and the trajectory {traj.path} '
                         f'({traj.stamps_ns[0] / NS:.3f} to {traj.stamps_ns[-1] / NS:.3f} s) share '
                         'no time: do the two files use the same clock?')
    bad, gap = unpaired_joint_stamps(traj.stamps_ns, hmr.stamps_ns, slop_ns,
                                     int(round(params.interp_max_gap_s * NS)))
    if bad and np.isinf(gap):
        warnings.append(f'{bad} of {len(hmr.stamps_ns)} joints stamps of {hmr.path} lie outside '
                        f'the trajectory {traj.path} (or in gaps over interp_max_gap_s = '
                        f'{params.interp_max_gap_s} s): hac replay drops those frames (do the '
                        'files cover the same time?)')
    elif bad:
        warnings.append(f'the trajectory {traj.path} is too sparse for the joints: {bad} of '
                        f'{len(hmr.stamps_ns)} joints stamps have no SLAM pose within sync_slop_s '
                        f'and lie in gaps up to {gap:.2f} s (over interp_max_gap_s = '
                        f'{params.interp_max_gap_s} s): hac replay drops those frames (keyframes '
                        'only? export every frame\'s pose)')
    return warnings


def write_params(path: Path, layout: str, k: int) -> None:
    """``params.yaml``, a parameters file for the replay: the joint layout (and K for
    ``custom``)."""
    lines = [f'{NODE_NAME}:', '  ros__parameters:', f'    joint_layout: {layout}']
    if layout == 'custom':
        lines += [f'    joints_per_person: {k}',
                  '    # joint_layout custom also needs root_joints, body_axis_lower_joints and',
                  '    # body_axis_upper_joints (and optionally contact_joints, skeleton_edges):',
                  '    # index lists into the K joints of a person (docs/node.md, parameters)']
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')


def import_files(output: str | Path, trajectory: str | Path, map_file: str | Path,
                 joints: str | Path, camera: str | None = None,
                 gt_trajectory: str | Path | None = None, gt_joints: str | Path | None = None,
                 joint_layout: str | None = None, storage: str = 'mcap', map_frame: str = 'map',
                 camera_frame: str = 'camera_optical', world_frame: str = 'world',
                 params: HacParams | None = None, fps: float | None = None) -> ImportResult:
    """Write the recording ``output`` from the files (see the module docstring). ``params``: the
    ``interp_max_gap_s`` and ``sync_slop_s`` of the sparse-trajectory warning and the ground-truth
    interpolation (defaults otherwise); ``fps``: the frame rate of a DROID-SLAM-style ``.npz``
    trajectory's frame indices. Raises HacError before anything is written."""
    out = Path(output)
    if out.exists() or out.is_symlink():
        raise HacError(f'output {out} already exists (hac never overwrites a recording: remove it '
                       'or choose another name)')
    params = params or HacParams()
    got = _read_inputs(trajectory, map_file, joints, camera, gt_trajectory, gt_joints,
                       joint_layout, fps, params)
    messages = _Messages(rosbags_types())
    result = messages.inputs(got, out, map_frame, camera_frame)
    if got.gt is not None:
        result.gt_poses, result.gt_scale, result.gt_residual_m = messages.gt_poses(
            got.trajectory, got.gt, int(round(params.interp_max_gap_s * NS)), world_frame)
    if got.gt_hmr is not None:
        result.gt_joints_frames = messages.gt_joints(got.gt_hmr, world_frame)
        unmatched = len(np.setdiff1d(got.gt_hmr.stamps_ns, got.hmr.stamps_ns))
        if unmatched:
            got.warnings.append(
                f'{unmatched} of {len(got.gt_hmr.stamps_ns)} stamps of the ground-truth joints '
                f'{got.gt_hmr.path} are not stamps of the joints {got.hmr.path}: hac eval matches '
                'joints by stamp')
    _write(out, messages.sorted(), storage, joint_layout, got.hmr.joints_per_person, result)
    return result


@dataclass
class _Inputs:
    """The files read and checked: the SLAM trajectory, the map (N, 3) SLAM units, the joints,
    the camera's intrinsics (None without), the ground truth (None without), and the warnings."""

    trajectory: Trajectory
    points: np.ndarray
    hmr: Joints
    intrinsics: tuple[np.ndarray, int, int] | None  # K (3, 3) pixels, width, height
    gt: Trajectory | None
    gt_hmr: Joints | None
    warnings: list[str]


def _read_inputs(trajectory: str | Path, map_file: str | Path, joints: str | Path,
                 camera: str | None, gt_trajectory: str | Path | None,
                 gt_joints: str | Path | None, joint_layout: str | None, fps: float | None,
                 params: HacParams) -> _Inputs:
    """Every input file read and checked (InputError naming the file), with the warnings."""
    k_layout = joints_per_person(joint_layout) if joint_layout else None
    warnings: list[str] = []
    traj = read_any_trajectory(trajectory, 'trajectory', fps, warnings)
    points = read_map(map_file)
    hmr: Joints = read_joints(joints, 'joints', k_layout, joint_layout or '')
    k = hmr.joints_per_person
    intrinsics = parse_camera(camera) if camera is not None else None
    repeated: list[int] = []
    gt = (read_trajectory(gt_trajectory, 'ground-truth trajectory', repeated)
          if gt_trajectory else None)
    gt_hmr = read_joints(gt_joints, 'ground-truth joints', k) if gt_joints else None
    if gt is not None and repeated:
        warnings.append(f'the ground-truth trajectory {gt.path} repeats the stamp of the line '
                        f'before on {len(repeated)} line(s) (first: line {repeated[0]}): the first '
                        'pose of each stamp is used')
    if joint_layout is None and k != SMPL24.joints_per_person:
        warnings.append(ArgumentText(
            f'{hmr.path} has {k} joints per person, not {SMPL24.name}\'s '
            f'{SMPL24.joints_per_person}: give {{joint_layout}} '
            f'({names_text()}) so that OUT gets a params.yaml saying it for the replay',
            'joint_layout'))
    warnings += check_joints(traj, hmr, params)
    return _Inputs(traj, points, hmr, intrinsics, gt, gt_hmr, warnings)


class _Messages:
    """The recording's messages (rosbags objects of ``types``), sorted by stamp, then by topic in
    ORDER when written."""

    def __init__(self, types: Any) -> None:
        self.types = types
        self._messages: list[tuple[int, int, str, Any]] = []

    def add(self, stamp: int, topic: str, msg: Any) -> None:
        self._messages.append((int(stamp), ORDER[topic], topic, msg))

    def sorted(self) -> list[tuple[int, int, str, Any]]:
        return sorted(self._messages, key=lambda m: (m[0], m[1]))

    def inputs(self, got: _Inputs, out: Path, map_frame: str, camera_frame: str
               ) -> ImportResult:
        """The map, the SLAM poses (and CameraInfo at each, with intrinsics), the joints frames
        with people; their counts."""
        traj, hmr, types = got.trajectory, got.hmr, self.types
        first = int(min(traj.stamps_ns[0], hmr.stamps_ns[0]))
        self.add(first, '/slam/cloud',
                 xyz_to_cloud(got.points, first, map_frame, types, dtype=np.float64))
        rotations = quats_to_rotations(traj.quats_xyzw)
        for stamp, R, c in zip(traj.stamps_ns.tolist(), rotations, traj.positions):
            self.add(stamp, '/slam/pose', rt_to_pose_stamped(R, c, stamp, map_frame, types))
            if got.intrinsics is not None:
                self.add(stamp, '/camera/camera_info',
                         intrinsics_to_camera_info(*got.intrinsics, stamp, camera_frame, types))
        frames, people_max = 0, 0
        for t, stamp in enumerate(hmr.stamps_ns.tolist()):
            people = hmr.people(t)
            if len(people):
                self.add(stamp, '/hmr/joints',
                         joints_to_pose_array(people, stamp, camera_frame, types))
                frames, people_max = frames + 1, max(people_max, len(people))
        return ImportResult(out, len(traj), frames, people_max, hmr.joints_per_person,
                            len(got.points), got.intrinsics is not None, warnings=got.warnings)

    def gt_poses(self, traj: Trajectory, gt: Trajectory, max_gap_ns: int, world_frame: str
                 ) -> tuple[int, float, float]:
        """The ground-truth camera at the SLAM stamps and the true scale (_fit_scale): the poses
        written, the scale and the fit's residual (metres)."""
        idx, gt_c, gt_R, s, residual = _fit_scale(traj, gt, max_gap_ns)
        for i, R, c in zip(idx.tolist(), gt_R, gt_c):
            stamp = int(traj.stamps_ns[i])
            self.add(stamp, GT_CAMERA[0], rt_to_pose_stamped(R, c, stamp, world_frame, self.types))
        self.add(int(traj.stamps_ns[0]), GT_SCALE[0],
                 self.types.get('std_msgs/msg/Float64')(data=float(s)))
        return len(idx), s, residual

    def gt_joints(self, gt_hmr: Joints, world_frame: str) -> int:
        """The ground-truth joints frames with people; how many."""
        frames = 0
        for t, stamp in enumerate(gt_hmr.stamps_ns.tolist()):
            people = gt_hmr.people(t)
            if len(people):
                self.add(stamp, GT_JOINTS[0],
                         joints_to_pose_array(people, stamp, world_frame, self.types))
                frames += 1
        return frames


def _write(out: Path, messages: list[tuple[int, int, str, Any]], storage: str,
           joint_layout: str | None, k: int, result: ImportResult) -> None:
    """The recording ``out``, whole or not at all, with the layout in its metadata and, for a
    ``joint_layout`` given, its params.yaml."""
    layout_name = joint_layout or (SMPL24.name if k == SMPL24.joints_per_person else 'custom')
    used = {topic for _, _, topic, _ in messages}
    with staged_output(out) as staged:
        data = (layout_data(BUILT_IN[layout_name]) if layout_name in BUILT_IN
                else {LAYOUT_KEY: layout_name, JOINTS_KEY: str(k)})
        writer = OutputWriter(staged, storage, data)
        try:
            for topic, msgtype in TOPICS.items():
                if topic in used:
                    writer.connection(topic, msgtype, latched=topic == '/slam/cloud')
            for stamp, _, topic, msg in messages:
                msgtype = TOPICS[topic]
                writer.write(topic, msgtype, stamp, writer.typestore.serialize_cdr(msg, msgtype))
        finally:
            writer.close()
        if joint_layout:
            write_params(staged / PARAMS_FILE, joint_layout, k)
            result.params_file = out / PARAMS_FILE
