"""The checks one person passes before measuring (hac_ros.core.bodies.person_checks): each refuses what it
is for and names its reason from the one table, in order, and a whole standing person passes."""
from __future__ import annotations

import numpy as np
import pytest
from scenes import STANDING

from hac_ros.core.bodies.person_checks import BODY_CHECKS, JOINT_CHECKS, Person, refusal
from hac_ros.core.layouts import SMPL24
from hac_ros.core.rules.reasons import REASONS

# world (z up) to an optical camera (x right, y down, z ahead) at 1.5 m, 3 m before the person
WORLD_TO_CAMERA = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
CAMERA = STANDING @ WORLD_TO_CAMERA + [0.0, 1.5, 3.0]
DOWN = np.array([0.0, 1.0, 0.0])  # the scene's down in the camera frame


def judged(joints: np.ndarray, down: np.ndarray | None = DOWN) -> tuple[str, str] | None:
    """The first refusal of the joint checks, then of the body checks (as hac_node runs them)."""
    person = Person(SMPL24, joints, 'lowest_gravity')
    refused = refusal(JOINT_CHECKS, person)
    if refused:
        return refused
    person.up_cam, person.down_cam = SMPL24.up_axis(joints), down
    return refusal(BODY_CHECKS, person)


def test_a_whole_standing_person_passes_every_check():
    assert judged(CAMERA) is None
    assert judged(CAMERA, down=None) is None  # down not known yet: standing judged by the legs


def test_every_reason_is_in_the_one_table_once():
    reasons = [reason for reason, _ in (*JOINT_CHECKS, *BODY_CHECKS)]
    assert len(set(reasons)) == len(reasons) and set(reasons) <= set(REASONS)


@pytest.mark.parametrize('case, reason', [
    ('inf', 'nonfinite_joints'),
    ('head_only', 'too_little_seen'),
    ('millimetres', 'joints_not_metres'),
    ('behind', 'behind_camera'),
    ('foot_unseen', 'contact_unseen'),
    ('lying', 'not_standing'),
])
def test_each_check_refuses_its_case_under_its_reason(case, reason):
    joints = CAMERA.copy()
    if case == 'inf':
        joints[3] = np.inf
    elif case == 'head_only':
        joints[:12] = np.nan  # the legs and the pelvis: no lower end of the body axis
    elif case == 'millimetres':
        joints = joints * 1000.0
    elif case == 'behind':
        joints[:, 2] -= 10.0
    elif case == 'foot_unseen':
        joints[10] = np.nan  # a contact candidate not seen: it may be the contact
    elif case == 'lying':  # the body along the floor (world x), 30 cm above it
        joints = (STANDING[:, [2, 1, 0]] + [-0.9, 0.0, 0.3]) @ WORLD_TO_CAMERA + [0.0, 1.5, 3.0]
    refused = judged(joints)
    assert refused is not None and refused[0] == reason, refused


def test_the_first_failed_check_decides():
    """Joints in millimetres and behind the camera: refused as not metres, the earlier check."""
    joints = CAMERA * 1000.0
    joints[:, 2] -= 1e5
    assert judged(joints)[0] == 'joints_not_metres'
