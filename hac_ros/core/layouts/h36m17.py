"""``h36m17``: the 17 Human3.6M joints that VideoPose3D and MotionBERT write (docs/inputs.md,
"HMR side"): pelvis, right hip, knee, ankle, left hip, knee, ankle, spine, thorax, neck/nose, head,
left shoulder, elbow, wrist, right shoulder, elbow, wrist.

Its feet are the ankles (a shod ankle: :data:`~hac_ros.core.layouts.base.SHOD_ANKLE_REL`). The
simulator places the limbs' joints where SMPL's are, the thorax, nose and top of the head at fixed
offsets.
"""
from __future__ import annotations

from hac_ros.core.layouts.base import SHOD_ANKLE_REL, JointLayout

NAMES = ('pelvis', 'right_hip', 'right_knee', 'right_ankle', 'left_hip', 'left_knee',
         'left_ankle', 'spine', 'thorax', 'neck_nose', 'head', 'left_shoulder', 'left_elbow',
         'left_wrist', 'right_shoulder', 'right_elbow', 'right_wrist')

LAYOUT = JointLayout(
    name='h36m17', joints_per_person=17, root=(0,), axis_lower=(0,), axis_upper=(8,),
    feet=(3, 6), pelvis=(0,), head=(10,), legs=((1, 2, 3), (4, 5, 6)),
    sole_height_rel={3: SHOD_ANKLE_REL, 6: SHOD_ANKLE_REL},
    edges=((0, 1), (1, 2), (2, 3), (0, 4), (4, 5), (5, 6), (0, 7), (7, 8), (8, 9), (9, 10),
           (8, 11), (11, 12), (12, 13), (8, 14), (14, 15), (15, 16)),
    joint_names=NAMES, written_by='Human3.6M lifters (VideoPose3D, MotionBERT)',
    sim_placement=((0, (0, 0, 0)), (2, (0, 0, 0)), (5, (0, 0, 0)), (8, (0, 0, 0)),
                   (1, (0, 0, 0)), (4, (0, 0, 0)), (7, (0, 0, 0)),
                   (6, (0, 0, 0)),  # spine
                   (12, (0.0, 0.0, -0.06)),  # thorax
                   (15, (0.09, 0.0, -0.04)),  # neck/nose
                   (15, (0.0, 0.0, 0.11)),  # top of the head
                   (16, (0, 0, 0)), (18, (0, 0, 0)), (20, (0, 0, 0)),
                   (17, (0, 0, 0)), (19, (0, 0, 0)), (21, (0, 0, 0))))
