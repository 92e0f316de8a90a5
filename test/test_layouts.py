"""joint_layout (every built-in layout, custom) end to end, and the warnings that catch a wrong
input convention (hac_ros.core.bodies.convention_check)."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from scenes import QUICK_CONVERGENCE
from scipy.spatial.transform import Rotation

from hac_ros.bridge.messages import OutputMessages
from hac_ros.cli import main as hac
from hac_ros.core import layouts
from hac_ros.core.basics.errors import ParameterError
from hac_ros.core.basics.outputs import HumanJointsOut, NoticeOut, ScaleOut
from hac_ros.core.bodies.contact import leg_lengths
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.layouts import BUILT_IN, problems
from hac_ros.core.rules.params import HacParams, describe
from hac_ros.recording.reader import Recording
from hac_ros.recording.tracks import read_output
from hac_ros.simulate import make_scenario
from hac_ros.simulate.feed import feed_events, scenario_events
from hac_ros.simulate.motions import STANDING
from hac_ros.simulate.skeletons import simulated_layouts, to_layout

DURATION_S = 15.0
BODY_FRAME_Q = [-0.5, 0.5, -0.5, 0.5]  # the optical frame in an x-forward, z-up camera frame


def events(sc, pose_rotation: np.ndarray | None = None, joints=lambda j: j) -> list:
    """The scenario's inputs, the SLAM poses' rotations right-multiplied by ``pose_rotation`` (as
    a SLAM wrapper that publishes another child frame would), the joints through ``joints``."""
    out = []
    for stamp, kind, payload in scenario_events(sc):
        if kind == 'pose' and pose_rotation is not None:
            payload = (payload[0] @ pose_rotation, *payload[1:])
        elif kind == 'joints':
            payload = (joints(payload[0]), *payload[1:])
        out.append((stamp, kind, payload))
    return out


def run(sc, params: HacParams, pose_rotation: np.ndarray | None = None, camera_info: bool = True,
        joints=lambda j: j) -> list:
    """Every input of ``sc`` (:func:`events`) into a fresh calibrator, flushed: its outputs."""
    cal = Calibrator(params)
    out = list(cal.add_camera_info(sc.K, sc.width, sc.height)) if camera_info else []
    return out + feed_events(cal, events(sc, pose_rotation, joints)) + cal.flush()


def scale_error(sc, outputs: list) -> float:
    scales = [o.scale for o in outputs if isinstance(o, ScaleOut)]
    return abs(float(scales[-1]) / float(sc.true_scale[-1]) - 1.0)


def warnings(outputs: list) -> set[str]:
    return {o.cause for o in outputs if isinstance(o, NoticeOut) and o.cause.startswith('convention')}


# ---------------------------------------------------------------------------- layouts
def test_the_simulated_layouts_place_their_joints_on_the_same_body():
    body = STANDING[None]  # (1, 24, 3): forward x, left y, up z
    coco, h36m = to_layout(body, 'coco17')[0], to_layout(body, 'h36m17')[0]
    assert coco.shape == (17, 3) and h36m.shape == (17, 3)
    np.testing.assert_allclose(coco[15], STANDING[7])  # COCO's left ankle is SMPL's
    np.testing.assert_allclose(h36m[3], STANDING[8])  # H36M's right ankle is SMPL's
    assert coco[0, 0] > STANDING[15, 0]  # the nose is in front of the head
    assert h36m[10, 2] > STANDING[15, 2]  # the top of the head above SMPL's head joint


@pytest.mark.parametrize('name', simulated_layouts())
def test_a_simulated_layout_is_a_standing_body(name):
    """Each layout the simulator writes, on the standing template (forward x, left y, up z): its
    body axis points up, its root is at the pelvis, its legs are 0.7-0.9 m, its joints called left
    are on the left, and its lowest joint is one of its contact candidates."""
    layout = BUILT_IN[name]
    joints = to_layout(STANDING[None], name)[0]
    up = layout.up_axis(joints)
    assert up[2] > 0.8 * np.linalg.norm(up)
    assert np.linalg.norm(layout.root_of(joints) - STANDING[0]) < 0.1
    assert all(0.7 < leg < 0.9 for leg in leg_lengths(layout, joints))
    sides = [(n, joints[i, 1]) for i, n in enumerate(layout.joint_names)
             if n.startswith(('left_', 'right_'))]
    assert sides and all((y > 0) == n.startswith('left_') for n, y in sides), sides
    assert int(np.argmin(joints[:, 2])) in (layout.contact or range(len(joints)))


def test_the_registry_is_the_layout_modules():
    """hac_ros/core/layouts/: one module per built-in layout, each registered under its own name;
    the parameter's choices and the simulator's are the registry's."""
    modules = sorted(p.stem for p in Path(layouts.__file__).parent.glob('*.py')
                     if p.stem not in ('__init__', 'base'))
    assert sorted(BUILT_IN) == modules and next(iter(BUILT_IN)) == 'smpl24'
    assert describe('joint_layout')['choices'] == (*BUILT_IN, 'custom')
    assert set(simulated_layouts()) == {n for n, lay in BUILT_IN.items() if lay.sim_placement}
    assert all(problems(layout) == [] for layout in BUILT_IN.values())


def test_a_wrong_layout_module_is_told_what_is_wrong():
    """problems() (run on every layout module at import) names what does not fit."""
    good = BUILT_IN['coco17']
    assert problems(good) == []
    wrong = dataclasses.replace(good, root=(17,), joint_names=good.joint_names[:-1],
                                sole_height_rel={15: 0.6}, sim_placement=good.sim_placement[:3])
    found = ' '.join(problems(wrong))
    for text in ('root has indices outside 0..16', '16 joint names', 'sole height outside',
                 '3 simulator placements'):
        assert text in found, found


@pytest.mark.parametrize('layout', [n for n in simulated_layouts() if n != 'smpl24'])
def test_each_layout_calibrates_like_smpl24_on_the_same_scene(layout):
    errors = {}
    for name in ('smpl24', layout):
        sc = make_scenario('walk', seed=3, duration=DURATION_S, hmr_bias=0.0, joint_layout=name)
        assert sc.joints_cam[0].shape[1] == BUILT_IN[name].joints_per_person
        out = run(sc, HacParams().replace(joint_layout=name))
        assert not warnings(out)
        errors[name] = scale_error(sc, out)
        humans = [o for o in out if isinstance(o, HumanJointsOut)]
        assert humans and humans[-1].joints_metric.shape[1:] == (sc.joints_cam[0].shape[1], 3)
    assert errors[layout] < 0.02, errors
    assert errors[layout] < errors['smpl24'] + 0.01, errors


def test_a_custom_layout_equals_the_built_in_one_it_describes():
    sc = make_scenario('walk', seed=4, duration=8.0, hmr_bias=0.0, joint_layout='coco17')
    coco = HacParams().replace(joint_layout='coco17', sole_correction=False,
                               converged_max_rel_sigma=QUICK_CONVERGENCE)
    custom = coco.replace(joint_layout='custom', joints_per_person=17, root_joints=[11, 12],
                          body_axis_lower_joints=[11, 12], body_axis_upper_joints=[5, 6],
                          skeleton_edges=[5, 7, 7, 9])
    a, b = run(sc, coco), run(sc, custom)
    scales_a = [o.scale for o in a if isinstance(o, ScaleOut)]
    assert scales_a and scales_a == [o.scale for o in b if isinstance(o, ScaleOut)]
    assert custom.layout().edges == ((5, 7), (7, 9))


@pytest.mark.parametrize('changes, text', [
    (dict(joint_layout='custom'), 'joints_per_person'),
    (dict(joint_layout='custom', joints_per_person=5, root_joints=[5],
          body_axis_lower_joints=[0], body_axis_upper_joints=[1]), 'outside 0..4'),
    (dict(joint_layout='custom', joints_per_person=5, root_joints=[0],
          body_axis_lower_joints=[0], body_axis_upper_joints=[]), 'body_axis_upper_joints'),
    (dict(joint_layout='custom', joints_per_person=5, root_joints=[0],
          body_axis_lower_joints=[0], body_axis_upper_joints=[1], skeleton_edges=[0, 1, 2]),
     'pairs'),
    (dict(root_joints=[-1]), 'integers >= 0'),
])
def test_a_bad_custom_layout_is_refused_with_the_reason(changes, text):
    with pytest.raises(ParameterError, match=text):
        HacParams().replace(**changes)


def test_joints_of_another_layout_are_rejected_naming_joint_layout():
    sc = make_scenario('walk', seed=5, duration=3.0, hmr_bias=0.0, joint_layout='coco17')
    cal = Calibrator(HacParams())  # smpl24: 17 joints per person do not fit
    out = cal.add_joints(int(sc.joints_stamps_ns[0]), sc.joints_cam[0], sc.camera_frame)
    assert cal.rejected['joints_wrong_layout'] == 1
    assert 'joint_layout' in out[0].text


def test_a_recording_says_its_layout_and_replay_eval_plot_follow_it(tmp_path):
    source, out = tmp_path / 'coco', tmp_path / 'out'
    assert hac(['simulate', 'walk', '-o', str(source), '--duration', '10', '--seed', '2',
                '--hmr-bias', '0', '--joint-layout', 'coco17']) == 0
    with Recording(source) as rec:
        assert rec.joints_per_person == 17 and rec.layout.name == 'coco17'
    params = tmp_path / 'params.yaml'
    params.write_text('hac_node:\n  ros__parameters:\n    joint_layout: coco17\n')
    assert hac(['replay', str(source), '-o', str(out), '--params', str(params)]) == 0
    replayed = read_output(out)
    assert replayed.layout.name == 'coco17'
    assert replayed.joints.joints and replayed.joints.joints[-1].shape[1:] == (17, 3)
    # eval's reference runs take the layout from the recording when no --params is given
    assert hac(['eval', str(out), '--gt', str(source), '--json', str(tmp_path / 'eval.json')]) == 0
    rows = json.loads((tmp_path / 'eval.json').read_text())['rows']
    assert rows['hac']['w_mpjpe_mm'] < 200 and rows['hac']['scale_error_frames_pct'] < 3
    assert all(row['scale_error_frames_pct'] < 20 for row in rows.values())
    assert hac(['plot', str(out), '--gt', str(source), '-o', str(tmp_path / 'fig')]) == 0


# ---------------------------------------------------------------------------- wrong conventions
@pytest.fixture(scope='module')
def walk():
    return make_scenario('walk', seed=6, duration=DURATION_S, hmr_bias=0.0)


def test_correct_inputs_raise_no_convention_warning(walk):
    assert not warnings(run(walk, HacParams()))
    assert not warnings(run(walk, HacParams(), camera_info=False))


def test_body_frame_poses_are_caught_and_pose_to_optical_fixes_them(walk):
    R_optical_in_body = Rotation.from_quat(BODY_FRAME_Q).as_matrix()
    body_poses = R_optical_in_body.T  # R_map_body = R_map_optical · R(q)^T
    wrong = run(walk, HacParams(), body_poses)
    assert warnings(wrong) == {'convention_pose_convention'}
    notice = next(o for o in wrong if isinstance(o, NoticeOut)
                  and o.cause == 'convention_pose_convention')
    assert 'pose_to_optical' in notice.text and notice.level == 'warn'
    # what the warning is about: a wrong scale (its samples scatter: it is not even published)
    assert not [o for o in wrong if isinstance(o, ScaleOut)] or scale_error(walk, wrong) > 0.3
    fixed = run(walk, HacParams().replace(pose_to_optical=BODY_FRAME_Q), body_poses)
    assert not warnings(fixed)
    assert scale_error(walk, fixed) < 0.02


@pytest.mark.parametrize('data, read', [('h36m17', 'coco17'), ('coco17', 'h36m17')])
def test_a_layout_read_as_another_of_the_same_size_is_caught(data, read):
    sc = make_scenario('walk', seed=7, duration=DURATION_S, hmr_bias=0.0, joint_layout=data)
    out = run(sc, HacParams().replace(joint_layout=read))
    notice = next(o for o in out if isinstance(o, NoticeOut) and o.cause == 'convention_joint_layout')
    assert 'check joint_layout' in notice.text


def test_people_on_their_hands_are_not_mistaken_for_a_wrong_layout():
    """The body axis points down, but the legs are the layout's: no warning."""
    sc = make_scenario('handstand', seed=1, duration=DURATION_S, hmr_bias=0.0)
    assert not warnings(run(sc, HacParams()))


def test_joints_outside_the_optical_frame_are_caught(walk):
    optical_to_body = Rotation.from_quat(BODY_FRAME_Q).as_matrix()  # joints x forward, z up
    out = run(walk, HacParams(), joints=lambda j: j @ optical_to_body.T)
    assert 'convention_joints_frame' in warnings(out)


def test_the_warning_stays_in_diagnostics(walk):
    R = Rotation.from_quat(BODY_FRAME_Q).as_matrix().T
    cal = Calibrator(HacParams())
    cal.add_camera_info(walk.K, walk.width, walk.height)
    feed_events(cal, events(walk, R))
    status = cal.status()
    assert 'pose_convention' in status.suspects
    messages = OutputMessages(HacParams())
    diag = messages.diagnostics(status)
    assert b'suspect.pose_convention' in diag and b'pose_to_optical' in diag


def test_a_runtime_layout_change_renews_the_skeleton_markers():
    """The node hands OutputMessages the new parameters (node.py, _apply_parameters): the bones
    must follow joint_layout, or a 17-joint frame would index SMPL-24's bones."""
    messages = OutputMessages(HacParams())
    messages.params = HacParams().replace(joint_layout='coco17')
    people = make_scenario('walk', seed=2, duration=2.0, hmr_bias=0.0,
                           joint_layout='coco17').gt_joints_world[0]
    assert messages.markers(HumanJointsOut(0, people))  # no IndexError
    assert len(messages._bone_joints) == 2 * len(BUILT_IN['coco17'].edges)
