"""``blazepose33``: the 33 landmarks of MediaPipe's BlazePose GHUM 3D, what ``hac_people_node``
and ``hac people`` publish (docs/people.md).

Its root is the mid-hips and its body axis mid-hips → mid-shoulders (the model's own origin is the
mid-hips); the contact candidates are the heels, the foot indices (the tips of the feet) and the
ankles, the fixed ``feet`` mode's joints the heels. Their heights above the sole were measured on
BlazePose's landmarks of real people walking (docs/method.md, "People from pixels"). The
simulator places the face, hands and feet at fixed offsets from SMPL's head, hand, ankle and foot
joints.
"""
from __future__ import annotations

from hac_ros.core.layouts.base import JointLayout

NAMES = ('nose', 'left_eye_inner', 'left_eye', 'left_eye_outer', 'right_eye_inner', 'right_eye',
         'right_eye_outer', 'left_ear', 'right_ear', 'mouth_left', 'mouth_right',
         'left_shoulder', 'right_shoulder', 'left_elbow', 'right_elbow', 'left_wrist',
         'right_wrist', 'left_pinky', 'right_pinky', 'left_index', 'right_index', 'left_thumb',
         'right_thumb', 'left_hip', 'right_hip', 'left_knee', 'right_knee', 'left_ankle',
         'right_ankle', 'left_heel', 'right_heel', 'left_foot_index', 'right_foot_index')
HIPS, SHOULDERS = (23, 24), (11, 12)
ANKLES, HEELS, FOOT_INDICES = (27, 28), (29, 30), (31, 32)

# Heights above the sole, fraction of the leg (thigh + shank): measured on real people
# (bench/people_real.py, vtest.avi's stance feet, along the floor's normal) the heel stands 2.0-2.1
# cm and the ankle 6.3-6.4 cm above the same foot's foot index, on a 0.765 m leg; the foot index
# (the tip of the shoe) is taken 1.5 cm above the sole, which images cannot tell (docs/method.md,
# "People from pixels")
FOOT_INDEX_REL = 0.020
HEEL_REL = 0.047
ANKLE_REL = 0.102

LAYOUT = JointLayout(
    name='blazepose33', joints_per_person=33, root=HIPS, axis_lower=HIPS, axis_upper=SHOULDERS,
    feet=HEELS, pelvis=HIPS, head=(0,), contact=(*HEELS, *FOOT_INDICES, *ANKLES),
    legs=((23, 25, 27), (24, 26, 28)),
    sole_height_rel={29: HEEL_REL, 30: HEEL_REL, 31: FOOT_INDEX_REL, 32: FOOT_INDEX_REL,
                     27: ANKLE_REL, 28: ANKLE_REL},
    # MediaPipe's POSE_CONNECTIONS
    edges=((0, 1), (1, 2), (2, 3), (3, 7), (0, 4), (4, 5), (5, 6), (6, 8), (9, 10), (11, 12),
           (11, 13), (13, 15), (15, 17), (15, 19), (15, 21), (17, 19), (12, 14), (14, 16),
           (16, 18), (16, 20), (16, 22), (18, 20), (11, 23), (12, 24), (23, 24), (23, 25),
           (24, 26), (25, 27), (26, 28), (27, 29), (28, 30), (29, 31), (30, 32), (27, 31),
           (28, 32)),
    joint_names=NAMES, written_by='MediaPipe BlazePose GHUM 3D (`hac_people_node`, `hac people`)',
    sim_placement=(
        (15, (0.10, 0.0, -0.03)),  # nose
        (15, (0.085, 0.015, 0.0)), (15, (0.08, 0.03, 0.0)), (15, (0.075, 0.045, 0.0)),  # left eye
        (15, (0.085, -0.015, 0.0)), (15, (0.08, -0.03, 0.0)), (15, (0.075, -0.045, 0.0)),
        (15, (0.0, 0.075, -0.01)), (15, (0.0, -0.075, -0.01)),  # ears
        (15, (0.09, 0.025, -0.07)), (15, (0.09, -0.025, -0.07)),  # mouth
        (16, (0, 0, 0)), (17, (0, 0, 0)), (18, (0, 0, 0)), (19, (0, 0, 0)),
        (20, (0, 0, 0)), (21, (0, 0, 0)),
        (22, (-0.01, 0.01, -0.04)), (23, (-0.01, -0.01, -0.04)),  # pinky knuckles
        (22, (0.02, 0.0, -0.05)), (23, (0.02, 0.0, -0.05)),  # index knuckles
        (22, (0.04, -0.01, 0.0)), (23, (0.04, 0.01, 0.0)),  # thumb tips
        (1, (0.0, 0.03, -0.02)), (2, (0.0, -0.03, -0.02)),  # hips, as COCO's
        (4, (0, 0, 0)), (5, (0, 0, 0)),
        (7, (0, 0, 0)), (8, (0, 0, 0)),  # ankles
        (7, (-0.05, 0.0, -0.045)), (8, (-0.05, 0.0, -0.045)),  # heels: back of the heel
        (10, (0.07, 0.0, -0.012)), (11, (0.07, 0.0, -0.012)),  # foot indices: the toes' tips
    ))
