"""``coco17``: the 17 COCO keypoints (COCO-17 lifters; docs/inputs.md, "HMR side").

Its root and body axis are the mid-hips and mid-shoulders, its feet the ankles (a shod ankle:
:data:`~hac_ros.core.layouts.base.SHOD_ANKLE_REL`), its head the nose. The simulator places the
limbs' joints where SMPL's are, the face at fixed offsets from SMPL's head, the hips a little wider
and lower than SMPL's.
"""
from __future__ import annotations

from hac_ros.core.layouts.base import SHOD_ANKLE_REL, JointLayout

NAMES = ('nose', 'left_eye', 'right_eye', 'left_ear', 'right_ear', 'left_shoulder',
         'right_shoulder', 'left_elbow', 'right_elbow', 'left_wrist', 'right_wrist', 'left_hip',
         'right_hip', 'left_knee', 'right_knee', 'left_ankle', 'right_ankle')

LAYOUT = JointLayout(
    name='coco17', joints_per_person=17, root=(11, 12), axis_lower=(11, 12), axis_upper=(5, 6),
    feet=(15, 16), pelvis=(11, 12), head=(0,), legs=((11, 13, 15), (12, 14, 16)),
    sole_height_rel={15: SHOD_ANKLE_REL, 16: SHOD_ANKLE_REL},
    edges=((0, 1), (0, 2), (1, 3), (2, 4), (5, 6), (5, 7), (7, 9), (6, 8), (8, 10), (5, 11),
           (6, 12), (11, 12), (11, 13), (13, 15), (12, 14), (14, 16)),
    joint_names=NAMES, written_by='COCO-17 lifters',
    sim_placement=((15, (0.10, 0.0, -0.03)),  # nose
                   (15, (0.08, 0.03, 0.0)), (15, (0.08, -0.03, 0.0)),  # left, right eye
                   (15, (0.0, 0.075, -0.01)), (15, (0.0, -0.075, -0.01)),  # left, right ear
                   (16, (0, 0, 0)), (17, (0, 0, 0)), (18, (0, 0, 0)), (19, (0, 0, 0)),
                   (20, (0, 0, 0)), (21, (0, 0, 0)),
                   (1, (0.0, 0.03, -0.02)), (2, (0.0, -0.03, -0.02)),  # hips: wider and lower
                   (4, (0, 0, 0)), (5, (0, 0, 0)), (7, (0, 0, 0)), (8, (0, 0, 0))))
