"""``smpl24``: the 24 joints of SMPL's joint regressor, the default layout (4D-Humans, WHAM, TRAM:
docs/inputs.md, "HMR side").

SMPL's foot joints sit about 3 cm above the sole of an 0.83 m leg, its ankles about 7 cm, the
hands about 1.5 cm above the palm (docs/method.md, "The contact is not on the surface"). The
simulator moves SMPL-24 bodies: its placement is the identity.
"""
from __future__ import annotations

from hac_ros.core.layouts.base import JointLayout

NAMES = ('pelvis', 'left_hip', 'right_hip', 'spine1', 'left_knee', 'right_knee', 'spine2',
         'left_ankle', 'right_ankle', 'spine3', 'left_foot', 'right_foot', 'neck', 'left_collar',
         'right_collar', 'head', 'left_shoulder', 'right_shoulder', 'left_elbow', 'right_elbow',
         'left_wrist', 'right_wrist', 'left_hand', 'right_hand')

LAYOUT = JointLayout(
    name='smpl24', joints_per_person=24, root=(0,), axis_lower=(0,), axis_upper=(12,),
    feet=(10, 11), pelvis=(0,), head=(15,), legs=((1, 4, 7), (2, 5, 8)),
    sole_height_rel={10: 0.036, 11: 0.036, 7: 0.085, 8: 0.085, 22: 0.018, 23: 0.018},
    edges=((0, 1), (0, 2), (0, 3), (1, 4), (2, 5), (3, 6), (4, 7), (5, 8), (6, 9), (7, 10),
           (8, 11), (9, 12), (9, 13), (9, 14), (12, 15), (13, 16), (14, 17), (16, 18), (17, 19),
           (18, 20), (19, 21), (20, 22), (21, 23)),
    joint_names=NAMES, written_by='SMPL models (4D-Humans, WHAM, TRAM, SMPLer-X)',
    sim_placement=tuple((j, (0.0, 0.0, 0.0)) for j in range(24)))
