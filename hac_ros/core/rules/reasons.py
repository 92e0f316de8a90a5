"""Every reason hac_ros gives for not being OK: the one table.

A reason is a key of ``/diagnostics`` (``rejected.<key>``, ``event.<key>``, ``condition.<key>``,
or a name in its ``reasons`` list). Its :class:`Reason` says which kind it is, what it means (the
text logged with its first occurrence), whether it makes the status WARN, and what a user can do
about it. Everything else reads this table: the calibrator's notices
(:mod:`hac_ros.core.frame_loop`), the status's level (:mod:`hac_ros.core.rules.health`), the node's
own findings, the replay's summary, and docs/node.md's reason table (generated from
:func:`markdown_table` and checked by ``test/test_docs.py``: ``make docs`` rewrites it).

To add a reason: one entry here, and a test that makes it happen.
"""
from __future__ import annotations

from dataclasses import dataclass

from hac_ros.core.basics.param_fields import Choice
from hac_ros.core.layouts import counts_text


class ReasonKind(Choice):
    """How a reason shows in /diagnostics."""

    REJECTED = 'rejected'  # an input (or an output) refused and counted: rejected.<key>
    EVENT = 'event'  # something that happened, counted: event.<key>
    CONDITION = 'condition'  # holds while it lasts: condition.<key>
    STATUS = 'status'  # the core's own finding about its estimate
    NODE = 'node'  # a finding only hac_node can make (its clock, its queues, the graph)


REJECTED, EVENT, CONDITION, STATUS, NODE = ReasonKind  # short names for the table below
KINDS = tuple(ReasonKind)


@dataclass(frozen=True)
class Reason:
    """One reason. ``text``: what it means, one line; ``warns``: a counted reason (rejected,
    event) makes the status WARN when it grew since the previous status (conditions and findings
    always do while they hold); ``counted``: a condition whose inputs are also counted under
    ``rejected.<key>``; ``remedy``: what the user can do about it, or ``none``."""

    kind: ReasonKind
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
        REJECTED, 'SLAM pose with NaN/inf, an invalid rotation or an invalid stamp',
        remedy='none when the SLAM publishes NaN while it is lost; otherwise publish unit '
               'quaternions, finite positions and valid stamps'),
    'pose_wrong_frame': Reason(
        REJECTED, 'SLAM pose in another frame than the map\'s, not followed by '
        'reset_confirm_poses more in it (a re-initialisation would be): another publisher on '
        'pose_topic?', warns=True,
        remedy='one SLAM per pose_topic: give each robot its own namespace, or remap the topics'),
    'pose_out_of_order': Reason(
        REJECTED, 'SLAM pose stamp not after the previous one (out of order or repeated)',
        remedy='none for a few; many: one publisher on pose_topic, stamped from one clock'),
    'pose_outlier': Reason(
        REJECTED, 'isolated SLAM pose jump (jump and back, or a glitch among the first poses): '
        'pose ignored',
        remedy='none: the SLAM glitched and the pose was ignored'),
    'pose_stamp_outlier': Reason(
        REJECTED, 'a SLAM pose stamped far ahead of the others (a clock glitch) was refused',
        warns=True,
        remedy='check the clock that stamps the SLAM poses; none if it happened once'),
    # ------------------------------------------------------------ joints
    'frames_dropped': Reason(
        REJECTED, 'joints frames dropped by hac_node, the oldest waiting: input faster than '
        'processing (joints_backlog_max)', warns=True,
        remedy='the processing time per frame (logged with it; latency_p99_ms) must stay below '
               'the input period: fewer map points (index_max_points), a lower joints rate or '
               'fewer people per frame help; a larger joints_backlog_max drops fewer frames '
               'but lets them wait longer (latency)'),
    'poses_coalesced': Reason(
        REJECTED, 'SLAM poses coalesced by hac_node: a pose stream faster than one per '
        'pose_coalesce_s thinned to it (no /hac/odometry for the poses left out)',
        remedy='none: the odometry comes at least every pose_coalesce_s; pose_coalesce_s 0 '
               'processes every pose, and the node then falls behind a stream it cannot keep '
               'up with'),
    'late_frame': Reason(REJECTED, 'joints frame older than the last processed frame: dropped',
        remedy='none for a few (reordered in transport); many: stamp the joints with the clock '
               'of the poses'),
    'joints_malformed': Reason(
        REJECTED, 'joints message is not P blocks of the layout\'s joints',
        remedy='publish a PoseArray of the layout\'s joints per person, with a valid stamp'),
    'joints_wrong_layout': Reason(
        REJECTED, 'the number of joints is not a multiple of the joint layout\'s joints per '
        f'person: set joint_layout ({counts_text()})',
        remedy='set joint_layout (joints_per_person for custom)'),
    'joints_wrong_frame': Reason(REJECTED, 'joints in a frame other than the camera frame',
        remedy='one camera per node: set camera_frame to its optical frame and publish every '
               'joints message in it'),
    'nonfinite_joints': Reason(REJECTED, 'a person with infinite joints (NaN is "not seen")',
        remedy='none: the person is skipped'),
    'too_little_seen': Reason(
        REJECTED, 'a person of whom too little is seen (NaN joints): no joint at one end of the '
        'body axis, or fewer than half the joints',
        remedy='none: the person is skipped'),
    'contact_unseen': Reason(
        REJECTED, 'a person whose contact joints (or the leg that gives their height above the '
        'sole) are not seen (NaN): no contact, no sample',
        remedy='none: people whose feet are out of view or hidden give no scale'),
    'joints_not_metres': Reason(
        REJECTED, 'people refused: joints spread over more than 4 m or less than 0.3 m (HMR '
        'joints must be metres)', warns=True,
        remedy='publish the HMR joints in metres (the log names the likely unit)'),
    'behind_camera': Reason(REJECTED, 'a person entirely behind the camera',
        remedy='none for a few; many: the joints are not in the camera optical frame (z '
               'forward, docs/inputs.md)'),
    'not_standing': Reason(
        REJECTED, 'a person seated, kneeling or lying: only standing people measure the floor '
        '(the body cannot tell planted feet from hanging ones)',
        remedy='none: the scale comes from the people who stand or walk'),
    'no_pose': Reason(REJECTED, 'no SLAM pose at (or around) the joints stamp',
        remedy='publish the SLAM pose of each image with the image\'s stamp, or poses within '
               'interp_max_gap_s around it, from the same clock as the joints'),
    'pending_overflow': Reason(REJECTED, 'joints waited too long for a SLAM pose: dropped',
        remedy='the poses lag the joints by more than pose_buffer frames: check pose_topic and '
               'the stamps, or raise pose_buffer'),
    # ------------------------------------------------------------ samples
    'no_map': Reason(REJECTED, 'no map yet (or none since the last reset) and no ground plane',
        remedy='none while the first map comes; else publish the SLAM map on cloud_topic (a '
               'volatile publisher needs cloud_qos volatile)'),
    'no_reference': Reason(
        REJECTED, 'no map hit and no usable ground plane for the contact joint',
        remedy='none for a few; many: a denser map around the people\'s feet, or a larger '
               'cone_angle_deg'),
    'gated': Reason(REJECTED, 'scale sample far from the current estimate (outlier gate)',
        remedy='none: an outlier sample was refused; after a known change of scale, call '
               '~/reset'),
    'no_down': Reason(
        REJECTED, 'a body without an up axis (its axis joints on one point) while the scene has '
        'not said which way is down (docs/method.md, "Which way is down")',
        remedy='none: such bodies are used once the floor or other bodies say which way is '
               'down; many: check joint_layout'),
    # ------------------------------------------------------------ maps
    'cloud_empty': Reason(REJECTED, 'map cloud with no valid point: previous map kept',
        remedy='none: the previous map is kept; check the map publisher if it lasts'),
    'cloud_malformed': Reason(REJECTED, 'map cloud that could not be decoded',
        remedy='publish PointCloud2 with x, y, z fields of float32 or float64'),
    'cloud_wrong_frame': Reason(REJECTED, 'map cloud in a frame other than the SLAM pose frame',
        remedy='publish the map in the frame_id of the SLAM poses'),
    'cloud_implausible': Reason(
        REJECTED, 'a map cloud of values no SLAM produces (a wrong byte order?) was refused',
        warns=True,
        remedy='check the map\'s byte order and fields (is_bigendian, point_step, offsets)'),
    'map_degenerate': Reason(
        CONDITION, 'a map cloud whose points lie at a point, on a line, or on one plane that '
        'cannot be the floor (tilted from the bodies\' axis, or through the camera) was '
        'refused, and no good map serves since', counted=True,
        remedy='publish the SLAM\'s map points themselves (not a projection, a line or a '
               'single wall); none once a good map comes'),
    'map_superseded': Reason(
        REJECTED, 'a map cloud stamped at or before the map in use: the newer map is kept',
        remedy='none: the newer map is used'),
    'map_old_segment': Reason(
        REJECTED, 'a map cloud stamped before the SLAM re-initialised: the old map\'s, not used',
        remedy='none: the new segment waits for its own map'),
    'camera_info_invalid': Reason(REJECTED, 'CameraInfo with invalid intrinsics',
        remedy='publish CameraInfo with positive focal lengths in K and the image size'),
    # ------------------------------------------------------------ outputs
    'output_implausible': Reason(
        REJECTED, 'outputs with non-finite or absurd values were suppressed', warns=True,
        remedy='check the inputs\' units; raise output_max_m only for a scene that large'),
    # ------------------------------------------------------------ pose_source tf
    'tf_invalid': Reason(
        REJECTED, 'a TF transform that is not finite, not a rotation or has an invalid stamp',
        remedy='check the publisher of the SLAM\'s transform'),
    'tf_unconnected': Reason(
        REJECTED, 'a transform of slam_pose_frame\'s branch while slam_map_frame cannot be '
        'reached in TF (a static transform missing, or a frame misnamed)',
        remedy='publish the static transforms between slam_map_frame and slam_pose_frame, or '
               'correct their names'),
    'tf_chain_dynamic': Reason(
        REJECTED, 'the TF chain from slam_map_frame to slam_pose_frame passes through a second '
        'dynamic transform: no pose taken',
        remedy='set slam_pose_frame to the frame whose transform the SLAM publishes'),
    # ------------------------------------------------------------ transport (hac_node)
    'pose_lost': Reason(REJECTED, 'SLAM pose lost in transport (best-effort input_qos)',
        remedy='none for a few; many: input_qos reliable with a reliable publisher, or '
               'config/fastdds_large_data.xml in every process (docs/node.md, Performance)'),
    'joints_lost': Reason(REJECTED, 'joints message lost in transport (best-effort input_qos)',
        remedy='none for a few; many: input_qos reliable with a reliable publisher, or '
               'config/fastdds_large_data.xml in every process (docs/node.md, Performance)'),
    'camera_info_lost': Reason(REJECTED, 'CameraInfo lost in transport (best-effort input_qos)',
        remedy='none for a few; many: input_qos reliable with a reliable publisher'),
    'cloud_lost': Reason(REJECTED, 'map cloud lost in transport',
        remedy='config/fastdds_large_data.xml in every process that publishes or takes the map'),
    'pose_wrong_type': Reason(
        REJECTED, 'a publisher on the pose topic has another type than pose_type',
        remedy='set pose_type to the publisher\'s type, or pose_topic to the pose topic'),
    'joints_wrong_type': Reason(REJECTED, 'a publisher on the joints topic is not PoseArray',
        remedy='set joints_topic to the topic of the HMR\'s PoseArray'),
    'camera_info_wrong_type': Reason(
        REJECTED, 'a publisher on the CameraInfo topic is not CameraInfo',
        remedy='set camera_info_topic to the CameraInfo topic ("" turns it off)'),
    'cloud_wrong_type': Reason(REJECTED, 'a publisher on the map topic is not PointCloud2',
        remedy='set cloud_topic to the topic of the SLAM\'s PointCloud2 map'),
    'internal_error': Reason(
        REJECTED, 'an unexpected error in a callback (logged once with its traceback): the '
        'message was skipped',
        remedy='report it with the traceback logged with the first one'),
    # ------------------------------------------------------------ events
    'time_jump_back': Reason(EVENT, 'time jumped back: a new stream started', warns=True,
        remedy='none when a recording was played again; otherwise check the inputs\' clock'),
    'time_jump_ahead': Reason(EVENT, 'time jumped ahead: a new segment started', warns=True,
        remedy='none after a pause of the SLAM; otherwise check the inputs\' clock'),
    # ------------------------------------------------------------ conditions
    'slam_frozen': Reason(
        CONDITION, 'the SLAM pose repeats bit for bit while the people move: tracking lost? '
        '(frames not sampled)', counted=True,
        remedy='a camera that does not move (a tripod, a wall): set static_camera true; a SLAM: '
               'check its tracking (relocalise it); none once it moves again'),
    'pose_zigzag': Reason(
        CONDITION, 'the SLAM pose goes back and forth between two places, pose after pose: two '
        'SLAMs on pose_topic in one frame (two robots in one domain without namespaces?)',
        remedy='one SLAM per pose_topic: give each robot its own namespace, or remap the topics'),
    'floor_unknown': Reason(
        CONDITION, 'no floor found in the map: the contacts\' map hits are not checked against '
        'it (a table top or a step could pass for it)',
        remedy='keep some of the floor in the SLAM\'s map; none while it is being mapped'),
    'relocking': Reason(
        CONDITION, 'gated samples in a row say the scale changed (they began after a new map '
        'changed its scale, while the estimate was unverified or lagging, or they last '
        'seconds): re-locking on them once they hold; the ± covers the gap',
        remedy='none: it re-locks by itself (docs/method.md, "The estimator")'),
    'map_rescaled': Reason(
        CONDITION, 'the SLAM\'s last new map has another scale than the one before (a quiet '
        're-initialisation, a scale that slips): the estimate follows it; the ± covers the step '
        'until a map holds still', remedy='none: the estimate follows the map by itself; if it '
        'lasts, the SLAM\'s scale is unstable (relocalise it, or map slower)'),
    'lagging': Reason(
        CONDITION, 'the latest samples disagree with the estimate: the scale changes faster than '
        'the estimate follows; the ± covers the gap',
        remedy='none: it catches up by itself; if it lasts, the SLAM\'s scale is unstable'),
    'unverified': Reason(
        CONDITION, 'no sample has checked the estimate for a while (nobody measuring in view, '
        'empty joints frames, a joints gap): it is carried on and its ± grows with the drift '
        'the estimator allows', remedy='people standing in full view, feet visible; check that '
        'the joints reach the node (joints_topic)'),
    # ------------------------------------------------------------ the core's findings
    'not_converged': Reason(STATUS, 'not converged: fewer than min_samples samples, or the '
                            'estimate\'s own uncertainty above converged_max_rel_sigma',
        remedy='none while samples come (min_samples); if it lasts: people in full view, feet '
               'visible, the floor in the map'),
    'inputs_suspect': Reason(
        STATUS, 'an input convention is suspect (suspect.<check>: pose_convention, '
        'pose_inverted, joint_layout, joints_frame)',
        remedy='check what the warning names: pose_to_optical, the SLAM pose\'s direction '
               '(T_wc, not T_cw), joint_layout, or the joints\' frame (docs/inputs.md)'),
    'alignment_slam': Reason(
        STATUS, 'metric frame: SLAM axes (no usable ground normal)',
        remedy='keep people standing or walking in view, so that the floor\'s normal is found; '
               'or set metric_frame_alignment slam'),
    # ------------------------------------------------------------ hac_node's findings
    'latency': Reason(NODE, 'the frames processed now are behind their arrival',
        remedy='as for frames_dropped: less work per frame (index_max_points, fewer people, a '
               'lower rate), or fewer other processes on the machine'),
    'backlog': Reason(NODE, 'input faster than processing: joints frames waiting',
        remedy='as for frames_dropped'),
    'no_joints': Reason(NODE, 'SLAM poses come but no HMR joints (the scale is held)',
        remedy='check that the HMR model publishes on joints_topic (and its QoS: input_qos)'),
    'no_poses': Reason(NODE, 'HMR joints come but no SLAM poses (the scale is held)',
        remedy='check that the SLAM publishes on pose_topic (tracking lost?)'),
    'no_input': Reason(NODE, 'no input at all (STALE, on the steady clock)',
        remedy='check that the inputs are published in this ROS domain (ROS_DOMAIN_ID) on the '
               'topics named'),
    'duplicate_name': Reason(
        NODE, 'another node with this node\'s name and namespace is in the graph: every '
        'output comes twice',
        remedy='give each node its own name (--ros-args -r __node:=NAME) or namespace, or stop '
               'one of them'),
    'many_publishers': Reason(
        NODE, 'more than one publisher on the pose, joints or map topic: their messages '
        'interleave (two SLAMs, or two robots in one domain without namespaces?)',
        remedy='one publisher per input topic: give each robot its own namespace (-r __ns:=/NAME '
               'for every node of it), or remap the topics'),
    'no_status': Reason(NODE, 'input comes but makes no status (no SLAM pose, or the '
                        'processing far behind)',
        remedy='see no_poses (joints without SLAM poses) and latency (the node far behind)'),
}


# A frame that waits for an input (no map, no pose) may wait because every one that came was
# refused: the waiting reason -> (the input's name, the reasons that refuse it). The replay's
# "nothing calibrated" line names those refusals, which are the cause the user can act on.
WAITS_FOR: dict[str, tuple[str, tuple[str, ...]]] = {
    'no_map': ('maps', ('cloud_empty', 'cloud_malformed', 'cloud_wrong_frame',
                        'cloud_implausible', 'map_degenerate', 'map_superseded',
                        'map_old_segment', 'cloud_wrong_type', 'cloud_lost')),
    'no_pose': ('SLAM poses', ('pose_nonfinite', 'pose_out_of_order', 'pose_outlier',
                               'pose_stamp_outlier', 'pose_wrong_type', 'pose_lost')),
}
WAITS_FOR['pending_overflow'] = WAITS_FOR['no_pose']


def refusals_behind(key: str, counts: dict[str, int]) -> str:
    """Why the input the reason ``key`` waits for never came (:data:`WAITS_FOR`): ``the maps
    were refused: cloud_wrong_frame 15 (its text; remedy: ...)``, the most counted first, or ''
    when none was refused (or ``key`` waits for nothing)."""
    if key not in WAITS_FOR:
        return ''
    name, refusing = WAITS_FOR[key]
    found = sorted(((counts[r], r) for r in refusing if counts.get(r, 0) > 0), reverse=True)
    if not found:
        return ''
    return f'the {name} were refused: ' + ', '.join(
        f'{r} {n} ({text(r)}; remedy: {REASONS[r].remedy})' for n, r in found)


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
