"""NaN joints are joints not seen (docs/inputs.md, "Joints not seen"): the core takes a person
as far as they are seen, takes no contact from an unseen joint, refuses a person only when too
little is seen, and publishes unseen joints as NaN, never a guess."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scenes import walking_scene

from hac_ros.core.basics.outputs import HumanJointsOut, OdometryOut, PoseOut, SampleOut, ScaleOut
from hac_ros.core.bodies.posture import posture_problem
from hac_ros.core.calibrator import Calibrator
from hac_ros.core.layouts import SMPL24
from hac_ros.core.rules.params import HacParams

HANDS = [20, 21, 22, 23]  # SMPL24's wrists and hands
LEFT_LEG = [1, 4, 7, 10]  # hip, knee, ankle, foot
FEET = [7, 8, 10, 11]  # the contact candidates: ankles and feet


def run(unseen: list[int] | None = None, every: int = 1, value: float = math.nan,
        frames: int = 40, **params) -> tuple[Calibrator, list]:
    """The walking scene with ``unseen`` joints set to ``value`` in every ``every``-th frame."""
    scene = walking_scene(frames=frames)
    contacts = scene.to_slam(scene.contact_world())
    cal = Calibrator(HacParams(cone_min_points=1, map_overlap_min=0.0, min_samples=5, **params))
    outs: list = []
    for t, stamp in enumerate(scene.stamps_ns):
        joints = scene.joints_cam[t].copy()
        if unseen and t % every == 0:
            joints[unseen] = value
        outs += cal.add_map(int(stamp), scene.with_backdrop(contacts[t:t + 1]), 'map')
        outs += cal.add_pose(int(stamp), scene.R_wc_slam[t], scene.c_slam[t], 'map')
        outs += cal.add_joints(int(stamp), joints[None], 'cam')
    return cal, outs + cal.flush()


def accepted(outs: list) -> int:
    return sum(1 for o in outs if isinstance(o, SampleOut) and o.accepted)


def final_scale(outs: list) -> float:
    return [o.scale for o in outs if isinstance(o, ScaleOut)][-1]


def test_unseen_hands_keep_the_scale_and_are_nan_in_the_world_joints():
    """contact_mode feet: the hands are no candidate, so they may go unseen."""
    _, seen = run(contact_mode='feet')
    cal, outs = run(HANDS, contact_mode='feet')
    assert accepted(outs) == accepted(seen) and cal.rejected['too_little_seen'] == 0
    assert final_scale(outs) == pytest.approx(final_scale(seen), rel=1e-9)
    humans = [o.joints_metric for o in outs if isinstance(o, HumanJointsOut)]
    assert humans
    for people in humans:
        assert np.isnan(people[:, HANDS]).all()
        others = np.delete(people, HANDS, axis=1)
        assert np.isfinite(others).all()
    for o in outs:  # nothing else carries a NaN
        if isinstance(o, (PoseOut, OdometryOut)):
            assert np.isfinite(o.position_metric).all() and np.isfinite(o.covariance).all()


def test_unseen_feet_give_no_contact_and_no_scale():
    cal, outs = run(FEET)
    assert accepted(outs) == 0 and not [o for o in outs if isinstance(o, ScaleOut)]
    assert cal.rejected['contact_unseen'] == 40


def test_an_unseen_candidate_may_be_the_contact_so_none_is_taken():
    """SMPL24 names no contact candidates (any joint may touch: hands in a handstand): with the
    hands unseen, the lowest seen joint is not known to be the lowest."""
    cal, outs = run(HANDS)
    assert accepted(outs) == 0 and cal.rejected['contact_unseen'] == 40


def test_one_leg_unseen_the_other_measures():
    """contact_mode feet (the two feet, the median of those seen): a frame with the left leg
    unseen measures on the right foot; posture is judged on the right leg."""
    _, seen = run(contact_mode='feet')
    cal, outs = run(LEFT_LEG, every=2, contact_mode='feet')
    assert cal.rejected['not_standing'] == 0 and cal.rejected['contact_unseen'] == 0
    assert accepted(outs) >= 0.7 * accepted(seen)
    assert final_scale(outs) == pytest.approx(2.5, rel=0.03)


def test_a_person_of_whom_too_little_is_seen_is_refused():
    cal, outs = run([i for i in range(24) if i not in (0, 1, 4, 7, 10, 12)])  # 6 of 24 seen
    assert cal.rejected['too_little_seen'] == 40 and accepted(outs) == 0
    cal, outs = run([12])  # the top of the body axis (the neck) unseen
    assert cal.rejected['too_little_seen'] == 40
    cal, outs = run([3], value=math.inf)  # infinite is not "unseen": malformed
    assert cal.rejected['nonfinite_joints'] == 40


def test_posture_is_judged_on_the_legs_seen():
    scene = walking_scene(frames=2)
    joints = scene.joints_cam[0].copy()
    up = SMPL24.up_axis(joints)
    assert posture_problem(SMPL24, joints, up, None) == ''
    one_leg = joints.copy()
    one_leg[LEFT_LEG] = np.nan
    assert posture_problem(SMPL24, one_leg, SMPL24.up_axis(one_leg), None) == ''
    no_legs = joints.copy()
    no_legs[LEFT_LEG + [2, 5, 8, 11]] = np.nan
    down = -up / np.linalg.norm(up)
    assert posture_problem(SMPL24, no_legs, SMPL24.up_axis(no_legs), down) != ''
