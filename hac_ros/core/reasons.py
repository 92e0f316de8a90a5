"""Every reason hac_ros gives for not being OK: the one table.

A reason is a key of ``/diagnostics`` (``rejected.<key>``, ``event.<key>``, ``condition.<key>``,
or a name in its ``reasons`` list). Its :class:`Reason` says which kind it is, what it means (the
text logged with its first occurrence), whether it makes the status WARN, and what a user can do
about it. Everything else reads this table: the calibrator's notices
(:mod:`hac_ros.core.frame_loop`), the status's level (:mod:`hac_ros.core.health`), the node's own
findings, the replay's summary, and docs/node.md's reason table (generated from
:func:`markdown_table` and checked by ``test/test_docs.py``: ``make docs`` rewrites it).

To add a reason: one entry here, and a test that makes it happen.
"""
from __future__ import annotations

from dataclasses import dataclass

from hac_ros.core.layouts import counts_text

# kinds: how the reason shows in /diagnostics
REJECTED = 'rejected'  # an input (or an output) refused and counted: rejected.<key>
EVENT = 'event'  # something that happened, counted: event.<key>
CONDITION = 'condition'  # holds while it lasts: condition.<key>
STATUS = 'status'  # the core's own finding about its estimate
NODE = 'node'  # a finding only hac_node can make (its clock, its queues, the graph)
KINDS = (REJECTED, EVENT, CONDITION, STATUS, NODE)


@dataclass(frozen=True)
class Reason:
    """One reason. ``text``: what it means, one line; ``warns``: a counted reason (rejected,
    event) makes the status WARN when it grew since the previous status (conditions and findings
    always do while they hold); ``counted``: a condition whose inputs are also counted under
    ``rejected.<key>``; ``remedy``: what the user can do about it, or ``none``."""

    kind: str
    text: str
    warns: bool = False
    remedy: str = ''
    counted: bool = False

    @property
    def makes_warn(self) -> bool:
        """Whether this reason ever makes a status WARN (or worse)."""
        return self.warns or self.kind in (CONDITION, STATUS, NODE)


REASONS: dict[str, Reason] = {
    # ------------------------------------------------------------ SLAM poses
    'pose_nonfinite': Reason(
        REJECTED, 'SLAM pose with NaN/inf, an invalid rotation or an invalid stamp'),
    'pose_out_of_order': Reason(
        REJECTED, 'SLAM pose stamp not after the previous one (out of order or repeated)'),
    'pose_outlier': Reason(
        REJECTED, 'isolated SLAM pose jump (jump and back, or a glitch among the first poses): '
        'pose ignored'),
    'pose_stamp_outlier': Reason(
        REJECTED, 'a SLAM pose stamped far ahead of the others (a clock glitch) was refused',
        warns=True),
    # ------------------------------------------------------------ joints
    'frames_dropped': Reason(
        REJECTED, 'joints frames dropped by hac_node, the oldest waiting: input faster than '
        'processing (joints_backlog_max)', warns=True),
    'late_frame': Reason(REJECTED, 'joints frame older than the last processed frame: dropped'),
    'joints_malformed': Reason(
        REJECTED, 'joints message is not P blocks of the layout\'s joints'),
    'joints_wrong_layout': Reason(
        REJECTED, 'the number of joints is not a multiple of the joint layout\'s joints per '
        f'person: set joint_layout ({counts_text()})'),
    'joints_wrong_frame': Reason(REJECTED, 'joints in a frame other than the camera frame'),
    'nonfinite_joints': Reason(REJECTED, 'a person with NaN/inf joints'),
    'joints_not_metres': Reason(
        REJECTED, 'people refused: joints spread over more than 4 m or less than 0.3 m (HMR '
        'joints must be metres)', warns=True),
    'behind_camera': Reason(REJECTED, 'a person entirely behind the camera'),
    'not_standing': Reason(
        REJECTED, 'a person seated, kneeling or lying: only standing people measure the floor '
        '(the body cannot tell planted feet from hanging ones)'),
    'no_pose': Reason(REJECTED, 'no SLAM pose at (or around) the joints stamp'),
    'pending_overflow': Reason(REJECTED, 'joints waited too long for a SLAM pose: dropped'),
    # ------------------------------------------------------------ samples
    'no_map': Reason(REJECTED, 'no map yet (or none since the last reset) and no ground plane'),
    'no_reference': Reason(
        REJECTED, 'no map hit and no usable ground plane for the contact joint'),
    'gated': Reason(REJECTED, 'scale sample far from the current estimate (outlier gate)'),
    'no_down': Reason(
        REJECTED, 'a body without an up axis (its axis joints on one point) while the scene has '
        'not said which way is down (docs/method.md, "Which way is down")'),
    # ------------------------------------------------------------ maps
    'cloud_empty': Reason(REJECTED, 'map cloud with no valid point: previous map kept'),
    'cloud_malformed': Reason(REJECTED, 'map cloud that could not be decoded'),
    'cloud_wrong_frame': Reason(REJECTED, 'map cloud in a frame other than the SLAM pose frame'),
    'cloud_implausible': Reason(
        REJECTED, 'a map cloud of values no SLAM produces (a wrong byte order?) was refused',
        warns=True),
    'map_degenerate': Reason(
        CONDITION, 'a map cloud whose points lie at a point, on a line, or on one plane that '
        'cannot be the floor (tilted from the bodies\' axis, or through the camera) was '
        'refused, and no good map serves since', counted=True),
    'map_superseded': Reason(
        REJECTED, 'a map cloud stamped at or before the map in use: the newer map is kept'),
    'map_old_segment': Reason(
        REJECTED, 'a map cloud stamped before the SLAM re-initialised: the old map\'s, not used'),
    'camera_info_invalid': Reason(REJECTED, 'CameraInfo with invalid intrinsics'),
    # ------------------------------------------------------------ outputs
    'output_implausible': Reason(
        REJECTED, 'outputs with non-finite or absurd values were suppressed', warns=True),
    # ------------------------------------------------------------ pose_source tf
    'tf_invalid': Reason(
        REJECTED, 'a TF transform that is not finite, not a rotation or has an invalid stamp'),
    'tf_unconnected': Reason(
        REJECTED, 'a transform of slam_pose_frame\'s branch while slam_map_frame cannot be '
        'reached in TF (a static transform missing, or a frame misnamed)'),
    'tf_chain_dynamic': Reason(
        REJECTED, 'the TF chain from slam_map_frame to slam_pose_frame passes through a second '
        'dynamic transform: no pose taken'),
    # ------------------------------------------------------------ transport (hac_node)
    'pose_lost': Reason(REJECTED, 'SLAM pose lost in transport (best-effort input_qos)'),
    'joints_lost': Reason(REJECTED, 'joints message lost in transport (best-effort input_qos)'),
    'camera_info_lost': Reason(REJECTED, 'CameraInfo lost in transport (best-effort input_qos)'),
    'cloud_lost': Reason(REJECTED, 'map cloud lost in transport'),
    'pose_wrong_type': Reason(
        REJECTED, 'a publisher on the pose topic has another type than pose_type'),
    'joints_wrong_type': Reason(REJECTED, 'a publisher on the joints topic is not PoseArray'),
    'camera_info_wrong_type': Reason(
        REJECTED, 'a publisher on the CameraInfo topic is not CameraInfo'),
    'cloud_wrong_type': Reason(REJECTED, 'a publisher on the map topic is not PointCloud2'),
    'internal_error': Reason(
        REJECTED, 'an unexpected error in a callback (logged once with its traceback): the '
        'message was skipped'),
    # ------------------------------------------------------------ events
    'time_jump_back': Reason(EVENT, 'time jumped back: a new stream started', warns=True),
    'time_jump_ahead': Reason(EVENT, 'time jumped ahead: a new segment started', warns=True),
    # ------------------------------------------------------------ conditions
    'slam_frozen': Reason(
        CONDITION, 'the SLAM pose repeats bit for bit while the people move: tracking lost? '
        '(frames not sampled)', counted=True),
    'floor_unknown': Reason(
        CONDITION, 'no floor found in the map: the contacts\' map hits are not checked against '
        'it (a table top or a step could pass for it)'),
    'relocking': Reason(
        CONDITION, 'gated samples in a row disagree with the estimate, or a new map\'s floor says '
        'it has another scale (a SLAM that re-initialised without a pose jump?): re-locking on '
        'the samples once they hold', remedy='none: it re-locks by itself (docs/method.md, '
        '"The estimator")'),
    # ------------------------------------------------------------ the core's findings
    'not_converged': Reason(STATUS, 'not converged: fewer than min_samples samples, or the '
                            'estimate\'s own uncertainty above converged_max_rel_sigma'),
    'inputs_suspect': Reason(
        STATUS, 'an input convention is suspect (suspect.<check>: pose_convention, '
        'joint_layout, joints_frame)'),
    'alignment_slam': Reason(
        STATUS, 'metric frame: SLAM axes (no usable ground normal)'),
    # ------------------------------------------------------------ hac_node's findings
    'latency': Reason(NODE, 'the frames processed now are behind their arrival'),
    'backlog': Reason(NODE, 'input faster than processing: joints frames waiting'),
    'no_joints': Reason(NODE, 'SLAM poses come but no HMR joints (the scale is held)'),
    'no_poses': Reason(NODE, 'HMR joints come but no SLAM poses (the scale is held)'),
    'no_input': Reason(NODE, 'no input at all (STALE, on the steady clock)'),
    'no_status': Reason(NODE, 'input comes but makes no status (no SLAM pose, or the '
                        'processing far behind)'),
}


def text(key: str) -> str:
    """The reason's text, or the key itself for a reason not in the table."""
    reason = REASONS.get(key)
    return reason.text if reason is not None else key


def warn_when_counted() -> dict[str, str]:
    """Counted reasons that make the status WARN when they grew: key -> text."""
    return {key: r.text for key, r in REASONS.items() if r.warns and r.kind in (REJECTED, EVENT)}


def markdown_table() -> str:
    """docs/node.md's reason table (between its ``reasons`` markers): one row per reason."""
    prefix = {REJECTED: 'rejected.', EVENT: 'event.', CONDITION: 'condition.', STATUS: '',
              NODE: ''}
    rows = ['| reason | kind | WARN | what it means | what to do |', '|---|---|---|---|---|']
    for key, r in REASONS.items():
        names = f'`{prefix[r.kind]}{key}`' + (f', `rejected.{key}`' if r.counted else '')
        warn = 'yes' if r.makes_warn else ''
        rows.append(f'| {names} | {r.kind} | {warn} | {r.text} | {r.remedy} |')
    return '\n'.join(rows) + '\n'
